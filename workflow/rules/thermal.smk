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
