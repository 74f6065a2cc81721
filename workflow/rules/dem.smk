# LIGGGHTS: fill, settle, flow; dumps gathered into one HDF5 file. Restart files in work/ let an
# interrupted run resume (they are not declared outputs, so Snakemake never deletes them).

# MPI: dem.ranks ranks (the rule's threads, capped by --cores) started by resources.mpi; profiles
# set another launcher (profiles/slurm: srun) or rank count (--set-resources dem:tasks=64).
MPI_RESOURCES = {"mpi": "mpirun", "tasks": lambda wildcards, threads: threads}


rule dem:
    input:
        unpack(lambda w: PLAN.dem_inputs(w.key)),
    output:
        positions=paths.stage_pattern("dem", "positions.h5"),
        summary=paths.stage_pattern("dem", "summary.json"),
    params:
        # the mass-flow check rides along: changing it re-checks the cached run, never re-runs LIGGGHTS
        spec=spec_json,
        io=io_json,
    threads: lambda w: PLAN.threads(w.key)
    resources:
        **MPI_RESOURCES,
    log:
        paths.stage_pattern("dem", "dem.log"),
    run:
        run_stage("dem", params, log)


# Not part of `all`: `snakemake --cores 2 calibrate` searches the orifice diameter that gives
# dem.target_mass_flow for every variant (a few short DEM runs each; the paper did it by hand).


rule calibrate:
    input:
        PLAN.calibration_targets(),


rule calibrate_orifice:
    output:
        result=run_path(paths.CALIBRATION),
    params:
        spec=lambda w: PLAN.calibration_spec(w.variant),
        io=io_json,
    threads: lambda w: PLAN.calibration_threads(w.variant)
    resources:
        **MPI_RESOURCES,
    log:
        run_path(paths.CALIBRATION_LOG),
    run:
        run_stage("calibrate_orifice", params, log)
