# LIGGGHTS: fill, settle, flow; dumps gathered into one HDF5 file. Restart files in work/ let an
# interrupted run resume (they are not declared outputs, so Snakemake never deletes them).

# MPI: dem.ranks ranks (the rule's threads, capped by --cores) started by resources.mpi; profiles
# set another launcher (profiles/slurm: srun) or rank count (--set-resources dem:tasks=64).
MPI_RESOURCES = {"mpi": "mpirun", "tasks": lambda wildcards, threads: threads}


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
    resources:
        **MPI_RESOURCES,
    log:
        "results/dem/{key}/dem.log",
    shell:
        stage("dem")


# Not part of `all`: `snakemake --cores 2 calibrate` searches the orifice diameter that gives
# dem.target_mass_flow for every variant (a few short DEM runs each; the paper did it by hand).


rule calibrate:
    input:
        [f"results/calibration/{v}/orifice.json" for v in VARIANTS],


rule calibrate_orifice:
    output:
        result="results/calibration/{variant}/orifice.json",
    params:
        spec=lambda w: json.dumps(KEYS[w.variant]["config"], sort_keys=True),
        io=io_json,
    threads: lambda w: KEYS[w.variant]["config"]["dem"]["ranks"]
    resources:
        **MPI_RESOURCES,
    log:
        "results/calibration/{variant}/calibrate.log",
    shell:
        stage("calibrate_orifice")
