# Figures per design variant (pyvista cross-section, heat flux along the tube, ...), the variant's
# summary and the comparison of variants; each PNG is captioned for `snakemake --report`.


rule figures:
    input:
        unpack(lambda w: PLAN.figures_inputs(w.variant)),
    output:
        **{
            name: report_item(run_path(paths.FIGURE, name=name), name, lambda w, name=name: PLAN.variant_report(w.variant, name))
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
        effects=report_item(run_path(paths.EFFECTS), "effects", lambda w: PLAN.variant_report(w.variant, "effects")),
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
        comparison=report_item(run_path(paths.COMPARISON, file=COMPARISON[0]), "compare_variants",
                               lambda w: PLAN.comparison_report(COMPARISON[0])),
        cross_sections=report_item(run_path(paths.COMPARISON, file=COMPARISON[1]), "compare_cross_sections",
                                   lambda w: PLAN.comparison_report(COMPARISON[1])),
    params:
        spec=PLAN.comparison_spec(),
        io=io_json,
    log:
        run_path(paths.COMPARISON, file="compare.log"),
    run:
        run_stage("compare", params, log)
