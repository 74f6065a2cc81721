# Heat-transfer-coefficient tables (DPHT paper Eqs. 8-13, 18-20), shared by every run with the
# same particles, gas and resolution.


rule htc_table:
    output:
        table="tables/htc/{key}.h5",
    params:
        spec=spec_json,
        io=io_json,
    log:
        "tables/htc/{key}.log",
    shell:
        stage("htc_table")
