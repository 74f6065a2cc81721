# Screening (dpht/thermal/screening.py): which effects a scene calls for, decided on its settled
# bed where the config leaves them at auto. A checkpoint: the thermal stage's inputs (which tables)
# follow its decisions, so no table is built for an effect it switched off.


checkpoint screening:
    input:
        unpack(lambda w: PLAN.screening_inputs(w.key)),
    output:
        screening=paths.stage_pattern("screening", "screening.json"),
    params:
        spec=spec_json,
        io=io_json,
    log:
        paths.stage_pattern("screening", "screening.log"),
    run:
        run_stage("screening", params, log)
