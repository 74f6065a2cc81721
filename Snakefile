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


rule all:
    input:
        all_targets(),
    default_target: True
