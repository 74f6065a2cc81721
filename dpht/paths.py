"""Where the workflow writes: every output path pattern, defined once for the rules and the plan.

Two kinds of folders:

* **Stage caches**, shared by every run: ``results/<stage>/<key>/<file>`` and the tables
  ``tables/<kind>/<key>.h5``, named by a stage run's key (a digest of what it computes from), so a
  run of any config reuses every stage run it shares with an earlier one.
* **Run folders**, one per config (its ``name``, :func:`dpht.config.run_name`):
  ``results/<run>/<variant>/`` for each design variant (figures, summary, orifice calibration),
  ``results/<run>/comparison/`` for the comparison of its variants and
  ``results/<run>/studies/<study>/`` for each study it asks for (:mod:`dpht.studies`). Two configs
  never write into each other's folders.

The reserved names follow from these tables: a run may not be named like a stage cache folder
(:data:`CACHE_FOLDERS`), a variant not like a folder beside the variants (:data:`RUN_FOLDERS`).
Keyed stages of studies add their folders when they register (:func:`add_cache_folder`).
"""

from __future__ import annotations

from pathlib import Path

RESULTS = "results"
TABLES = "tables"

# Stage caches: stage -> folder. The table stages write one file per key, <folder>/<key>.h5.
CACHE_FOLDERS = {"geometry": f"{RESULTS}/geometry", "dem": f"{RESULTS}/dem", "screening": f"{RESULTS}/screening",
                 "thermal": f"{RESULTS}/thermal", "segment": f"{RESULTS}/segment"}  # fmt: skip
TABLE_FOLDERS = {"pfp": f"{TABLES}/htc", "pfw": f"{TABLES}/htc", "rdf": f"{TABLES}/rdf"}

# Tables shipped with the project (tables/<kind>/shipped/<key>.h5, e.g. the RDF table of the default
# emissivities, minutes to trace) are read from there: sources, not outputs of a rule, so Snakemake
# has no metadata to miss and never rebuilds them.
PROJECT = Path(__file__).resolve().parent.parent
SHIPPED = PROJECT / TABLES

# A run's folder and what it holds beside its variants' folders.
RUN = RESULTS + "/{run}"
VARIANT = RUN + "/{variant}"
FIGURE = VARIANT + "/figures/{name}.png"
FIGURES_LOG = VARIANT + "/figures/figures.log"
SUMMARY = VARIANT + "/summary.json"
EFFECTS = VARIANT + "/effects.csv"
HEADLINE_MD = VARIANT + "/headline.md"
HEADLINE_CSV = VARIANT + "/headline.csv"
SUMMARY_LOG = VARIANT + "/summary.log"
CHAIN = VARIANT + "/chain.json"  # a variant run as a chain of segments (docs/theory/chain.md): its summary
CHAIN_LOG = VARIANT + "/chain.log"
CALIBRATION = VARIANT + "/calibration/orifice.json"
CALIBRATION_LOG = VARIANT + "/calibration/calibrate.log"
COMPARISON = RUN + "/comparison/{file}"
STUDY = RUN + "/studies/{study}/{file}"
RUN_FOLDERS = ("comparison", "studies")  # results/<run>/<folder>/ beside the variants


def add_cache_folder(stage: str) -> None:
    """Register the cache folder ``results/<stage>/`` of a keyed study stage (:mod:`dpht.studies`)."""
    CACHE_FOLDERS.setdefault(stage, f"{RESULTS}/{stage}")


def stage_file(stage: str, key: str, file: str = "") -> str:
    """Where run ``key`` of ``stage`` writes ``file`` (the table stages write one file, ``file``
    unused; a shipped table is read where it is shipped)."""
    if stage in TABLE_FOLDERS:
        folder = TABLE_FOLDERS[stage]
        shipped = SHIPPED / Path(folder).name / "shipped" / f"{key}.h5"
        return str(shipped) if shipped.is_file() else f"{folder}/{key}.h5"
    return f"{CACHE_FOLDERS[stage]}/{key}/{file}"


def stage_pattern(stage: str, file: str) -> str:
    """The rule's output pattern of ``file`` of ``stage`` (``{key}`` a wildcard)."""
    if stage in TABLE_FOLDERS:
        return f"{TABLE_FOLDERS[stage]}/{{key}}{file}"
    return f"{CACHE_FOLDERS[stage]}/{{key}}/{file}"


def reserved_run_names() -> set[str]:
    """Names a run may not have: the folders under results/ that stage caches use."""
    return {Path(folder).name for folder in CACHE_FOLDERS.values()}


def reserved_variant_names() -> set[str]:
    """Names a variant may not have: the folders beside the variants in a run's folder."""
    return set(RUN_FOLDERS)
