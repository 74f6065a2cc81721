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


# The numba thermal stage: particle temperatures and wall heat per frame (HDF5 + XDMF).


rule thermal:
    input:
        unpack(lambda w: PLAN.thermal_inputs(w.key, screened)),
    output:
        thermal="results/thermal/{key}/thermal.h5",
        xdmf="results/thermal/{key}/thermal.xdmf",
        summary="results/thermal/{key}/summary.json",
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        "results/thermal/{key}/thermal.log",
    run:
        run_stage("thermal", params, log)
