"""The smoke run (config/quick.yaml, `make quick`): it plans every rule of the default target `all`
with `--configfile config/quick.yaml` alone; every report figure of those rules has its CSV columns
listed (tests/figure_files.py); the figures of the two studies render from the quick config; and
every report item of every rule has its place in the report (category, subcategory, labels), read
with the quick and the default config's plans. The per-variant, comparison and Watkins figures render from the tiny runs of tests/workflow/test_workflow.py
and tests/workflow/test_watkins.py (their module fixtures, built once)."""

import contextlib
import os
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest

from dpht import config, studies
from dpht.plan import DESIGN, from_files, from_workflow
from dpht.util import processes
from figure_files import FIGURE_CSVS, check_figure, missing
from test_workflow import ROOT, SNAKEMAKE, job_counts, rule_names

QUICK = ROOT / "config" / "quick.yaml"
FILES = [ROOT / "config" / "config.yaml", QUICK]
# Rules of the workflow that the smoke run does not run, and why.
NOT_IN_ALL = {
    "calibrate": "a target of its own (the orifice calibration)",
    "calibrate_orifice": "run by `calibrate` only",
    "accuracy": "a study config/quick.yaml does not ask for (README, What accuracy costs)",
    "screening_check": "a study config/quick.yaml does not ask for",
    "rdf_table": "the RDF table of the default emissivities is shipped (tables/rdf/shipped/); a smoke build "
                 "cannot be fast (config/quick.yaml)",
    "segment": "a chain's (a scene with a chain section); the tiny chain runs end to end in tests/workflow/test_chain.py",
    "chain_summary": "a chain's, as segment",
}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A working folder laid out as a checkout: config/ and the shipped RDF tables."""
    folder = tmp_path_factory.mktemp("quick")
    (folder / "config").symlink_to(ROOT / "config")
    (folder / "tables").mkdir()
    (folder / "tables" / "rdf").symlink_to(ROOT / "tables" / "rdf")
    return folder


@pytest.fixture(scope="module")
def planned(workdir):
    """Rule -> jobs of a dry run of `snakemake --configfile config/quick.yaml` (nothing else given)."""
    result = subprocess.run([*SNAKEMAKE, "--directory", str(workdir), "--dry-run", "--configfile", str(workdir / "config" / "quick.yaml")],
                            capture_output=True, text=True, timeout=300)  # fmt: skip
    return job_counts(result)


def test_quick_config_and_its_scenes_validate_and_plan_every_rule_of_all(planned):
    plan = from_workflow(config.Sources(FILES).merged(), FILES)  # validates quick.yaml and its scene files
    assert plan.name == "quick" and plan.variants == ["base", "flat_plate"]
    assert plan.asked == ("watkins", "watkins_reduction", "mixers", "radiation", "intraparticle")
    assert all(t.startswith("results/quick/") for t in plan.targets())  # never the default run's folder
    reduction = plan.studies["watkins_reduction"].scenes
    assert list(reduction) == ["full", "slice"]
    # the reduction's full tube (config/quick_tube.yaml, the quick design's tube) shares the design's DEM run
    assert plan.register_scenes({"full": reduction["full"]})["full"]["dem"] == plan.keys["base"]["dem"]
    expected = rule_names() - set(NOT_IN_ALL)
    assert set(planned) == expected, f"planned {sorted(planned)}, expected {sorted(expected)}"
    # The command line's file is merged last, so its variants run (two figures jobs, a comparison).
    assert planned["figures"] == 2 and planned["compare_variants"] == 1


@pytest.fixture(scope="module")
def workflow(workdir):
    """The workflow as Snakemake reads it with `--configfile config/quick.yaml` alone: its rules, and
    its plan (``workflow.globals["PLAN"]``)."""
    from snakemake.api import SnakemakeApi
    from snakemake.settings.types import ConfigSettings, OutputSettings, Quietness, ResourceSettings, StorageSettings

    with pytest.MonkeyPatch.context() as patch, contextlib.chdir(os.getcwd()):  # Snakemake changes into the working folder
        patch.setenv(processes.WORKFLOW_PID, "0")  # the Snakefile sets it; put back after reading it
        with SnakemakeApi(OutputSettings(quiet={Quietness.ALL})) as api:
            return api.workflow(resource_settings=ResourceSettings(), storage_settings=StorageSettings(),
                                config_settings=ConfigSettings(configfiles=[workdir / "config" / "quick.yaml"]),
                                workdir=workdir, snakefile=ROOT / "Snakefile")._workflow  # fmt: skip


def report_outputs(rule):
    """The report-marked outputs of ``rule`` with their report flags."""
    from snakemake.io import get_flag_value, is_flagged

    return [(str(f), get_flag_value(f, "report")) for f in rule.output if is_flagged(f, "report")]


def test_every_report_figure_of_all_has_its_csv_columns_listed(workflow, planned):
    figures = {rule.name: [Path(f).stem for f, _ in report_outputs(rule) if f.endswith(".png")] for rule in workflow.rules}
    drawn = {name for rule, names in figures.items() if rule in planned for name in names}
    assert {"cross_section", "fig9", "biot_sweep", "variants", "fig11", "reduction"} <= drawn  # what the rules are
    for name in sorted(drawn):
        assert name in FIGURE_CSVS, missing(name)
    assert set(FIGURE_CSVS) <= drawn, f"FIGURE_CSVS lists figures no rule of `all` draws: {sorted(set(FIGURE_CSVS) - drawn)}"


def test_study_figures_render_from_the_quick_config(workdir):
    """The radiation-model and intra-particle studies of config/quick.yaml, run by Snakemake (no
    LIGGGHTS): every PNG they write, with its CSVs."""
    plan = from_workflow(config.Sources(FILES).merged(), FILES)
    targets = [t for name in ("radiation", "intraparticle") for t in plan.study_targets(name) if t.endswith(".png")]
    assert len(targets) == 1 + 3  # Fig. 9; the Biot sweep and the cooled sphere's two
    result = subprocess.run([*SNAKEMAKE, "--directory", str(workdir), *targets, "--configfile", str(workdir / "config" / "quick.yaml")],
                            capture_output=True, text=True, timeout=600)  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    keyed = [f for name in ("radiation", "intraparticle") for f in plan.studies[name].inputs.values()]
    pngs = sorted(p for t in targets + keyed for p in (workdir / t).parent.glob("*.png"))
    assert {p.stem for p in pngs} >= {"fig9", "biot_sweep", "cooled_sphere", "cooled_sphere_convergence"}
    for png in pngs:
        check_figure(png)


# The plans the report items are read from: the quick config with every study it can plan (the
# accuracy study's knobs vary around the default Watkins slice), and the default config with every study.
REPORT_PLANS = {"quick": (FILES, [s for s in studies.STUDIES if s != "accuracy"]), "default": (FILES[:1], list(studies.STUDIES))}


def report_places(workflow, plan) -> dict[tuple, str]:
    """(category, subcategory, labels) -> the rule, file and wildcards of each report item of every
    job ``plan`` makes of every rule: per variant, per run of a keyed rule (every geometry), the
    studies it planned."""
    places = {}
    for rule in workflow.rules:
        if "variant" in rule.wildcard_names:
            jobs = [{"variant": v} for v in plan.variants]
        elif "key" in rule.wildcard_names:
            jobs = [{"key": k} for k, run in plan.runs.items() if run.stage == rule.name]
        else:
            jobs = [{}] if rule.name in plan.studies or rule.name not in studies.STUDIES else []
        for file, flag in report_outputs(rule):
            for wildcards in jobs:
                w = SimpleNamespace(**wildcards)
                category, subcategory, labels = (v(w) if callable(v) else v for v in (flag.category, flag.subcategory, flag.labels))
                where = f"{rule.name} {file} {wildcards}"
                assert category and subcategory and set(labels) == {"figure", "variant", "study"} and all(labels.values()), where
                place = (category, subcategory, tuple(labels.items()))
                assert place not in places, f"{where} and {places[place]} in one place of the report: {place}"
                places[place] = where
    return places


@pytest.mark.parametrize("name", REPORT_PLANS)
def test_every_report_item_has_its_category_subcategory_and_labels(workflow, workdir, name):
    """Every report-marked output of every rule, for every job of the plan: its place in `snakemake
    --report` (workflow/rules/common.smk, report_item) is a category (the design or the study), a
    subcategory (the variant, Comparison, Geometry, Figures or Tables) and labels naming the figure,
    the variant and the study; no two items alike (the report's table shows one item per labels).
    The rules read the plan from the Snakefile's global PLAN when the report is built, so each plan
    is put there in turn."""
    files, asked = REPORT_PLANS[name]
    read = workflow.globals["PLAN"]
    try:
        with contextlib.chdir(workdir):
            plan = workflow.globals["PLAN"] = from_files(files, asked)
            places = report_places(workflow, plan)
    finally:
        workflow.globals["PLAN"] = read
    rows = [(where.split()[0], category, subcategory, dict(labels)) for (category, subcategory, labels), where in places.items()]
    design = f"Design: {plan.name}"
    for v in plan.variants:
        assert ("figures", design, v, {"figure": "cross section", "variant": v, "study": f"{DESIGN}: {plan.name}"}) in rows
        assert ("variant_summary", design, v, {"figure": "effects", "variant": v, "study": f"{DESIGN}: {plan.name}"}) in rows
    assert {(c, s) for rule, c, s, _ in rows if rule in ("figures", "variant_summary")} == {(design, v) for v in plan.variants}
    assert {(c, s, labels["variant"]) for rule, c, s, labels in rows if rule == "compare_variants"} == {
        (design, "Comparison", ", ".join(plan.variants))}
    for study in map(studies.STUDIES.get, asked):
        items = [(c, s, labels) for rule, c, s, labels in rows if rule == study.name]
        assert items and {(c, s) for c, s, _ in items} <= {(study.category, "Figures"), (study.category, "Tables")}, study.name
        assert {labels["study"] for _, _, labels in items} == {study.name}
    # Every geometry run in the category of the first scene using it, labelled with every scene using it.
    geometry = {labels["variant"]: (c, s, labels["study"]) for rule, c, s, labels in rows if rule == "geometry"}
    assert len(geometry) == len([k for k, run in plan.runs.items() if run.stage == "geometry"])
    if name == "quick":  # the reduction check's full tube is the quick design's; the radial mixer the mixers' own
        assert geometry["base, full"] == (design, "Geometry", f"{DESIGN}: quick, watkins_reduction, mixers")
        assert geometry["radial"] == ("Mixers", "Geometry", "mixers")
