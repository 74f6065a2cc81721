# Figures per design variant (pyvista cross-section, heat flux along the tube, ...), the variant's
# summary and the comparison of variants; each PNG is captioned for `snakemake --report`.


rule figures:
    input:
        unpack(lambda w: PLAN.figures_inputs(w.variant)),
    output:
        **{
            name: report(
                run_path(paths.FIGURE, name=name),
                caption=f"../report/{name}.rst",
                category="{variant}",
            )
            for name in FIGURES
        },
    params:
        spec=lambda w: PLAN.figures_spec(w.variant),
        io=io_json,
    log:
        run_path(paths.FIGURES_LOG),
    run:
        run_stage("figures", params, log)


rule variant_summary:
    input:
        unpack(lambda w: PLAN.summary_inputs(w.variant)),
    output:
        summary=run_path(paths.SUMMARY),
        effects=report(run_path(paths.EFFECTS), caption="../report/effects.rst", category="{variant}"),
        headline_md=run_path(paths.HEADLINE_MD),
        headline_csv=run_path(paths.HEADLINE_CSV),
    params:
        spec=lambda w: PLAN.summary_spec(w.variant),
        io=io_json,
    log:
        run_path(paths.SUMMARY_LOG),
    run:
        run_stage("variant_summary", params, log)


rule compare_variants:
    input:
        **PLAN.comparison_inputs(),
    output:
        comparison=report(run_path(paths.COMPARISON, file=COMPARISON[0]), caption="../report/compare_variants.rst",
                          category="Comparison"),
        cross_sections=report(run_path(paths.COMPARISON, file=COMPARISON[1]), caption="../report/compare_cross_sections.rst",
                              category="Comparison"),
    params:
        spec=PLAN.comparison_spec(),
        io=io_json,
    log:
        run_path(paths.COMPARISON, file="compare.log"),
    run:
        run_stage("compare", params, log)
