# LIGGGHTS: fill, settle, flow; dumps gathered into one HDF5 file. Restart files in work/ let an
# interrupted run resume (they are not declared outputs, so Snakemake never deletes them).


rule dem:
    input:
        walls=lambda w: f"results/geometry/{UPSTREAM[w.key]['geometry']}/walls.h5",
        geometry=lambda w: f"results/geometry/{UPSTREAM[w.key]['geometry']}/geometry.json",
    output:
        positions="results/dem/{key}/positions.h5",
        summary="results/dem/{key}/summary.json",
    params:
        # the mass-flow check rides along: changing it re-checks the cached run, never re-runs LIGGGHTS
        spec=lambda w: json.dumps(
            {**SPECS[w.key], "dem": {**SPECS[w.key]["dem"], **UPSTREAM[w.key]["checks"]}}, sort_keys=True
        ),
        io=io_json,
    threads: lambda w: UPSTREAM[w.key]["ranks"]
    log:
        "results/dem/{key}/dem.log",
    shell:
        stage("dem")
