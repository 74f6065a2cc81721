"""The registry of studies (dpht.studies): a study added through the registry alone is planned, has
its rule and runs its stage; every registered study's outputs, captions and section are consistent."""

import json
import os
from dataclasses import dataclass
from pathlib import Path

import pytest

from dpht import config, paths, stages, studies
from dpht.plan import Plan, from_files
from dpht.studies import Output, Planned, Study
from dpht.util import processes
from test_workflow import ROOT, write_config

REPORT = ROOT / "workflow" / "report"


@dataclass(frozen=True)
class ToySpec:
    window: tuple[float, float]  # the figures section's steady window


def toy_study(scene_file: Path) -> Study:
    """A study defined here alone: the scene of ``scene_file`` run as a variant is, and a stage that
    writes the window it was given and the files it read."""

    def plan(plan, section: dict) -> Planned:
        scene = config.variant(config.load(scene_file), "base")
        keys = plan.register_scenes({"toy": scene}, study=True)["toy"]
        files = plan.scene_files(keys, {"thermal_summary": ("thermal", "summary.json"), "walls": ("geometry", "walls.h5")})
        return Planned(inputs=files, spec=ToySpec(tuple(section["steady_window"])), scenes={"toy": scene})

    def run(spec, inputs, outputs, threads):
        Path(outputs["summary"]).write_text(json.dumps({"window": ToySpec(**spec).window, "read": sorted(inputs)}))

    return Study(name="toy", section="figures", category="Toy", outputs={"summary": Output("toy.json")}, plan=plan, run=run)


@pytest.fixture
def toy(tmp_path):
    """The toy study registered (and taken out of the registry again after the test)."""
    write_config(tmp_path / "tiny.yaml", {"studies": ["toy"], "figures": {"steady_window": [0.6, 1.0]}})
    study = studies.register(toy_study(tmp_path / "tiny.yaml"))
    yield study, tmp_path
    studies.STUDIES.pop("toy")


def test_a_study_added_through_the_registry_alone_is_planned_run_and_dry_run(toy, monkeypatch):
    study, folder = toy
    plan = from_files([folder / "tiny.yaml"])
    assert plan.asked == ("toy",) and plan.study_targets("toy") == ["results/tiny/studies/toy/toy.json"]
    assert plan.targets()[-1] == "results/tiny/studies/toy/toy.json"
    planned = plan.studies["toy"]
    assert json.loads(planned.spec_json()) == {"window": [0.6, 1.0]}
    keys = plan.keys["base"]  # the toy's scene is the design's own: the same stage runs
    assert dict(planned.inputs) == {"thermal_summary": f"results/thermal/{keys['thermal']}/summary.json",
                                    "walls": f"results/geometry/{keys['geometry']}/walls.h5"}  # fmt: skip
    # `python -m dpht stage toy` finds its stage in the registry.
    out = folder / "out" / "toy.json"
    io = json.dumps({"input": dict(planned.inputs), "output": {"summary": str(out)}, "threads": 1})
    assert stages.run("toy", planned.spec_json(), io, str(folder / "toy.log")) == 0
    assert json.loads(out.read_text()) == {"window": [0.6, 1.0], "read": ["thermal_summary", "walls"]}
    # Snakemake makes its rule from the registry: a dry run of `snakemake toy` plans it and its scene's stages.
    from snakemake.api import SnakemakeApi
    from snakemake.settings.types import ConfigSettings, DAGSettings, OutputSettings, Quietness, ResourceSettings, StorageSettings

    monkeypatch.setenv(processes.WORKFLOW_PID, "0")  # the Snakefile sets it; put back after the test
    cwd = os.getcwd()
    try:
        with SnakemakeApi(OutputSettings(quiet={Quietness.ALL})) as api:
            workflow = api.workflow(resource_settings=ResourceSettings(cores=1), storage_settings=StorageSettings(),
                                    config_settings=ConfigSettings(configfiles=[folder / "tiny.yaml"]), workdir=folder,
                                    snakefile=ROOT / "Snakefile")  # fmt: skip
            workflow.dag(dag_settings=DAGSettings(targets={"toy"})).execute_workflow(executor="dryrun")
            jobs = workflow._workflow.dag.jobs
            assert {job.rule.name for job in jobs} == {"geometry", "dem", "screening", "thermal", "toy"}
            assert [str(f) for job in jobs if job.rule.name == "toy" for f in job.output] == plan.study_targets("toy")
    finally:
        os.chdir(cwd)  # Snakemake changes into the working folder


def test_an_unknown_study_is_refused_with_the_registered_names():
    cfg = config.load(ROOT / "config" / "config.yaml")
    cfg["studies"] = ["watkins", "mixer"]
    with pytest.raises(config.ConfigError, match="studies: unknown study 'mixer'; studies: watkins, watkins_reduction, mixers"):
        Plan(config.validate(cfg))


@pytest.mark.parametrize("study", list(studies.STUDIES.values()), ids=lambda s: s.name)
def test_every_study_has_its_section_captions_and_folder(study):
    """Its section is a key of the schema (which may be null: not asked for), its report outputs
    have their captions, its outputs are distinct files, and its keyed stages' folders are reserved."""
    schema = config.schema()["properties"][study.section]
    assert "object" in (schema["type"] if isinstance(schema["type"], list) else [schema["type"]])
    for output in study.outputs.values():
        assert output.caption is None or (REPORT / f"{output.caption}.rst").is_file(), output
    files = list(study.files("run").values())
    assert len(set(files)) == len(files) and all(f.startswith("results/run/studies/") for f in files)
    assert {stage.name for stage in study.stages} <= paths.reserved_run_names()
