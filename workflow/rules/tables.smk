# Heat-transfer-coefficient tables (DPHT paper Eqs. 8-13, 18-20), shared by every run with the
# same particles, gas, resolution and solid fraction (a measured one is read from the DEM run's
# summary, its input).


rule htc_table:
    input:
        unpack(lambda w: PLAN.htc_inputs(w.key)),
    output:
        table="tables/htc/{key}.h5",
    params:
        spec=spec_json,
        io=io_json,
    log:
        "tables/htc/{key}.log",
    run:
        run_stage("htc_table", params, log)


# Radiation distribution factors for the particle and wall emissivities, by Monte Carlo ray
# tracing through packed beds (DPHT paper, Sections 3.6-3.7); minutes, so shipped tables are kept.


rule rdf_table:
    output:
        table="tables/rdf/{key}.h5",
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        "tables/rdf/{key}.log",
    run:
        run_stage("rdf_table", params, log)
