"""The smoke run (config/quick.yaml, `make quick`): it plans every rule of the default target `all`
with `--configfile config/quick.yaml` alone; every report figure of those rules has its CSV columns
listed (tests/figure_files.py); and the figures of the two studies render from the quick config.
The per-variant, comparison and Watkins figures render from the tiny runs of tests/test_workflow.py
and tests/test_watkins.py (their module fixtures, built once)."""

import os
import subprocess
from pathlib import Path

import pytest

from dpht import config
from dpht.plan import from_workflow
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


def report_figures(workdir) -> dict[str, list[str]]:
    """Rule -> the report-marked PNG outputs (their names) of every rule of the workflow, as
    Snakemake reads the rules (with the quick config)."""
    from snakemake.api import SnakemakeApi
    from snakemake.io import is_flagged
    from snakemake.settings.types import ConfigSettings, OutputSettings, Quietness, ResourceSettings, StorageSettings

    figures = {}
    with SnakemakeApi(OutputSettings(quiet={Quietness.ALL})) as api:
        workflow = api.workflow(resource_settings=ResourceSettings(), storage_settings=StorageSettings(),
                                config_settings=ConfigSettings(configfiles=[workdir / "config" / "quick.yaml"]),
                                workdir=workdir, snakefile=ROOT / "Snakefile")._workflow  # fmt: skip
        for rule in workflow.rules:
            pngs = [Path(str(f)).stem for f in rule.output if is_flagged(f, "report") and str(f).endswith(".png")]
            if pngs:
                figures[rule.name] = pngs
    return figures


def test_every_report_figure_of_all_has_its_csv_columns_listed(workdir, planned, monkeypatch):
    monkeypatch.setenv(processes.WORKFLOW_PID, "0")  # the Snakefile sets it; put back after the test
    cwd = os.getcwd()
    try:
        figures = report_figures(workdir)
    finally:
        os.chdir(cwd)  # Snakemake changes into the working folder
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
