# DPHT workflow: gmsh geometry -> LIGGGHTS DEM -> HTC/RDF tables -> numba thermal stage -> figures.
# `snakemake --cores 2` runs every variant in config/config.yaml; see README.md.

from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/geometry.smk"
include: "workflow/rules/dem.smk"
include: "workflow/rules/tables.smk"
include: "workflow/rules/thermal.smk"
include: "workflow/rules/radiation_study.smk"
include: "workflow/rules/figures.smk"


rule all:
    input:
        PLAN.targets() + list(REMADE),
    default_target: True
