# DPHT workflow: gmsh geometry -> LIGGGHTS DEM -> HTC/RDF tables -> numba thermal stage -> figures.
# `snakemake --cores 2` runs every variant in config/config.yaml; see README.md.

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
include: "workflow/rules/radiation_study.smk"
include: "workflow/rules/intraparticle_study.smk"
include: "workflow/rules/figures.smk"
include: "workflow/rules/watkins.smk"
include: "workflow/rules/mixers.smk"
include: "workflow/rules/accuracy.smk"


# Under a cluster executor (profiles/slurm) these run on the submitting host: targets, plotting
# and steps of seconds, which would wait longer in the queue than they run.
localrules:
    all,
    calibrate,
    htc_table,
    screening,
    figures,
    variant_summary,
    compare_variants,
    watkins,
    watkins_figures,
    watkins_reduction,
    mixers,
    mixers_figures,
    accuracy_cost,
    screening_check,


rule all:
    input:
        PLAN.targets() + list(REMADE),
    default_target: True
