# The numba thermal stage: particle temperatures and wall heat per frame (HDF5 + XDMF).


rule thermal:
    input:
        unpack(lambda w: PLAN.thermal_inputs(w.key, screened)),
    output:
        thermal=paths.stage_pattern("thermal", "thermal.h5"),
        xdmf=paths.stage_pattern("thermal", "thermal.xdmf"),
        summary=paths.stage_pattern("thermal", "summary.json"),
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        paths.stage_pattern("thermal", "thermal.log"),
    run:
        run_stage("thermal", params, log)
