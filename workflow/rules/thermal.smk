# The numba thermal stage: particle temperatures and wall heat per frame (HDF5 + XDMF).


def thermal_inputs(wildcards):
    up = UPSTREAM[wildcards.key]
    inputs = {
        "positions": f"results/dem/{up['dem']}/positions.h5",
        "walls": f"results/geometry/{up['geometry']}/walls.h5",
        "pfp": f"tables/htc/{up['pfp']}.h5",
        "pfw": f"tables/htc/{up['pfw']}.h5",
    }
    if up["rdf"] is not None:
        inputs["rdf"] = f"tables/rdf/{up['rdf']}.h5"
    elif "rdf_table" in SPECS[wildcards.key]["thermal"]:
        inputs["rdf"] = SPECS[wildcards.key]["thermal"]["rdf_table"]  # a file or a list of files
    return inputs


rule thermal:
    input:
        unpack(thermal_inputs),
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
    shell:
        stage("thermal")
