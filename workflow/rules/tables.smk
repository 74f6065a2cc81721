# Heat-transfer-coefficient tables (DPHT paper Eqs. 8-13, 18-20), shared by every run with the
# same particles, gas, resolution and solid fraction (a measured one is read from the DEM run's
# summary, its input).


rule htc_table:
    input:
        unpack(lambda w: PLAN.htc_inputs(w.key)),
    output:
        table=paths.stage_pattern("pfp", ".h5"),
    params:
        spec=spec_json,
        io=io_json,
    log:
        paths.stage_pattern("pfp", ".log"),
    run:
        run_stage("htc_table", params, log)


# Radiation distribution factors for the particle and wall emissivities, by Monte Carlo ray
# tracing through packed beds (DPHT paper, Sections 3.6-3.7); minutes, so shipped tables are kept.


rule rdf_table:
    output:
        table=paths.stage_pattern("rdf", ".h5"),
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        paths.stage_pattern("rdf", ".log"),
    run:
        run_stage("rdf_table", params, log)
