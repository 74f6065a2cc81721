# Screening (dpht/thermal/screening.py): which effects a scene calls for, decided on its settled
# bed where the config leaves them at auto. A checkpoint: the thermal stage's inputs (which tables)
# follow its decisions, so no table is built for an effect it switched off.


checkpoint screening:
    input:
        unpack(lambda w: PLAN.screening_inputs(w.key)),
    output:
        screening="results/screening/{key}/screening.json",
    params:
        spec=spec_json,
        io=io_json,
    log:
        "results/screening/{key}/screening.log",
    run:
        run_stage("screening", params, log)


# Not part of `all`: `snakemake --cores 2 screening_check` runs each check scene (config section
# screening_check) as configured and with every auto switch on, and tabulates what the effects the
# screening switched off would have changed (dpht/accuracy/screening_check.py).


rule screening_check:
    input:
        unpack(lambda w: PLAN.screening_check_inputs()),
    output:
        table=report("results/screening_check/check.csv", caption="../report/screening_check.rst", category="Screening"),
        markdown="results/screening_check/check.md",
        summary="results/screening_check/summary.json",
    params:
        spec=lambda w: PLAN.screening_check_spec(),
        io=io_json,
    log:
        "results/screening_check/check.log",
    run:
        run_stage("screening_check", params, log)
