# DPHT workflow: gmsh geometry -> LIGGGHTS DEM -> HTC/RDF tables -> numba thermal stage -> figures.
# `snakemake --cores 2` runs every variant in config/config.yaml and the paper's studies it lists
# (`studies`); `snakemake --cores 2 --configfile my_design.yaml` runs that design alone (merged over
# config/config.yaml, whose `studies` and `name` it does not inherit: dpht/config.py). See README.md.

from snakemake.utils import min_version

from dpht.config import check_yaml

min_version("9.0")


# Snakemake's own message for a YAML syntax error names neither the file nor the line.
check_yaml("config/config.yaml")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/geometry.smk"
include: "workflow/rules/dem.smk"
include: "workflow/rules/tables.smk"
include: "workflow/rules/screening.smk"
include: "workflow/rules/thermal.smk"
include: "workflow/rules/figures.smk"
include: "workflow/rules/studies.smk"


# Under a cluster executor (profiles/slurm) these run on the submitting host: targets, plotting
# and steps of seconds, which would wait longer in the queue than they run (and every study's own
# rule: workflow/rules/studies.smk).
localrules:
    all,
    calibrate,
    htc_table,
    screening,
    figures,
    variant_summary,
    compare_variants,


rule all:
    input:
        PLAN.targets() + list(REMADE),
    default_target: True
