# LIGGGHTS: fill, settle, flow; dumps gathered into one HDF5 file. Restart files in work/ let an
# interrupted run resume (they are not declared outputs, so Snakemake never deletes them).


rule dem:
    input:
        walls=lambda w: f"results/geometry/{UPSTREAM[w.key]['geometry']}/walls.h5",
    output:
        positions="results/dem/{key}/positions.h5",
        summary="results/dem/{key}/summary.json",
    params:
        spec=spec_json,
        io=io_json,
    threads: lambda w: UPSTREAM[w.key]["ranks"]
    log:
        "results/dem/{key}/dem.log",
    shell:
        stage("dem")
