# The mixer study (DPHT paper, Section 6, Figs. 14-16): every variant of the scene file named by config
# `mixer_study.scene` (config/mixers.yaml) against its first, the plain tube. Their geometry, DEM, table
# and thermal runs are the ordinary rules' (dpht.plan registers them). `snakemake --cores 2 mixers`;
# part of `all` when the config has a `mixer_study` section.


rule mixers:
    input:
        PLAN.mixer_targets(),


rule mixers_figures:
    input:
        **PLAN.mixer_inputs(),
    output:
        **{
            name: report(f"results/mixers/{name}.png", caption=f"../report/mixers_{name}.rst", category="Mixers")
            for name in MIXER_FIGURES
        },
        table=report("results/mixers/mixers.csv", caption="../report/mixers_table.rst", category="Mixers"),
        markdown="results/mixers/mixers.md",
        summary="results/mixers/mixers.json",
    params:
        spec=PLAN.mixer_spec(),
        io=io_json,
    log:
        "results/mixers/figures.log",
    run:
        run_stage("mixers", params, log)
