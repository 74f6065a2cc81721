# The DPHT paper's Section 4 (Table 1, Fig. 9): four radiation models on a static bed.


rule radiation_study:
    input:
        unpack(lambda w: PLAN.study_inputs(w.key)),
    output:
        table=report("results/radiation_study/{key}/table.csv", caption="../report/radiation_table.rst", category="Radiation models"),
        markdown="results/radiation_study/{key}/table.md",
        history="results/radiation_study/{key}/history.csv",
        figure=report("results/radiation_study/{key}/fig9.png", caption="../report/radiation_study.rst", category="Radiation models"),
        summary="results/radiation_study/{key}/summary.json",
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        "results/radiation_study/{key}/study.log",
    run:
        run_stage("radiation_study", params, log)
