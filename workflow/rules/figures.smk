# Figures per design variant (pyvista cross-section, heat flux along the tube, ...), the variant's
# summary and the comparison of variants; each PNG is captioned for `snakemake --report`.


rule figures:
    input:
        unpack(lambda w: PLAN.figures_inputs(w.variant)),
    output:
        **{
            name: report(
                f"results/{{variant}}/figures/{name}.png",
                caption=f"../report/{name}.rst",
                category="{variant}",
            )
            for name in FIGURES
        },
    params:
        spec=lambda w: PLAN.figures_spec(w.variant),
        io=io_json,
    log:
        "results/{variant}/figures/figures.log",
    run:
        run_stage("figures", params, log)


rule variant_summary:
    input:
        unpack(lambda w: PLAN.summary_inputs(w.variant)),
    output:
        summary="results/{variant}/summary.json",
        effects=report("results/{variant}/effects.csv", caption="../report/effects.rst", category="{variant}"),
        headline_md="results/{variant}/headline.md",
        headline_csv="results/{variant}/headline.csv",
    params:
        spec=lambda w: PLAN.summary_spec(w.variant),
        io=io_json,
    log:
        "results/{variant}/summary.log",
    run:
        run_stage("variant_summary", params, log)


rule compare_variants:
    input:
        **PLAN.comparison_inputs(),
    output:
        comparison=report("results/comparison/variants.png", caption="../report/compare_variants.rst", category="Comparison"),
        cross_sections=report(
            "results/comparison/cross_sections.png", caption="../report/compare_cross_sections.rst", category="Comparison"
        ),
    params:
        spec=PLAN.comparison_spec(),
        io=io_json,
    log:
        "results/comparison/compare.log",
    run:
        run_stage("compare", params, log)
