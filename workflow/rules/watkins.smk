# The Watkins validation (DPHT paper, Section 5, Figs. 11-13): the travelling-slice scene named by
# config `watkins.scene`, and the check of that reduction against a full tube (`watkins.reduction`).
# Their geometry, DEM, table and thermal runs are the ordinary rules' (dpht.plan registers them).
# `snakemake --cores 2 watkins`; part of `all` when the config has a `watkins` section.


rule watkins:
    input:
        PLAN.watkins_targets(),


rule watkins_figures:
    input:
        **PLAN.watkins_inputs(),
    output:
        **{
            name: report(f"results/watkins/{name}.png", caption=f"../report/watkins_{name}.rst", category="Watkins")
            for name in WATKINS_FIGURES
        },
        summary="results/watkins/watkins.json",
    params:
        spec="{}",
        io=io_json,
    log:
        "results/watkins/figures.log",
    run:
        run_stage("watkins", params, log)


rule watkins_reduction:
    input:
        **PLAN.reduction_inputs(),
    output:
        figure=report("results/watkins/reduction.png", caption="../report/watkins_reduction.rst", category="Watkins"),
        summary="results/watkins/reduction.json",
    params:
        spec=PLAN.reduction_spec(),
        io=io_json,
    log:
        "results/watkins/reduction.log",
    run:
        run_stage("watkins_reduction", params, log)
