# DPHT workflow: gmsh geometry -> LIGGGHTS DEM -> HTC tables -> numba thermal stage -> figures.
# `snakemake --cores 2` runs every variant in config/config.yaml; see README.md.

configfile: "config/config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/geometry.smk"
include: "workflow/rules/dem.smk"
include: "workflow/rules/tables.smk"
include: "workflow/rules/thermal.smk"
include: "workflow/rules/radiation_study.smk"
include: "workflow/rules/figures.smk"


# Under a cluster executor (profiles/slurm) these run on the submitting host: targets, plotting
# and steps of seconds, which would wait longer in the queue than they run.
localrules:
    all,
    calibrate,
    htc_table,
    figures,
    variant_summary,
    compare_variants,


rule all:
    input:
        all_targets(),
    default_target: True
