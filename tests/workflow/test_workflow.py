"""The workflow: its plan (dpht.plan), job lists and lint without LIGGGHTS; then end to end, the real
workflow (gmsh, LIGGGHTS, numba thermal stage, pyvista) on the tiny scene of .test/config/config.yaml."""

import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht import config, paths, stages, studies
from dpht.plan import FIGURES, Plan, figure, from_files, path
from dpht.thermal import effects, integrate, model as thermal_model, neighbors
from dpht.verification import reference, scenes
from dpht.dem.dumps import PositionsFile
from dpht.thermal.modes import NAMES as MODES
from dpht.thermal.schedule import Schedule
from dpht.geometry.walls import load_walls
from figure_files import check_figure

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "config" / "config.yaml"
TEST_CONFIG = ROOT / ".test" / "config" / "config.yaml"
QUICK = ROOT / "config" / "quick.yaml"
MY_DESIGN = ROOT / "config" / "examples" / "my_design.yaml"
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"), "--cores", "2"]



def end_to_end(test):
    """A test of the real workflow: slow (LIGGGHTS runs), skipped where LIGGGHTS is not installed."""
    return pytest.mark.slow(pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed")(test))


def tiny_config(overrides=None) -> dict:
    """.test/config/config.yaml with ``overrides`` merged in, its RDF table path made absolute
    (it is relative to .test/, and the tests run in temporary folders)."""
    cfg = yaml.safe_load(TEST_CONFIG.read_text())
    cfg["name"] = "tiny"  # results/tiny/, whatever file it is written to
    cfg["thermal"]["rdf_table"] = str((TEST_CONFIG.parent.parent / cfg["thermal"]["rdf_table"]).resolve())
    return config.merge(cfg, json.loads(json.dumps(overrides or {})))


def write_config(path, overrides=None):
    path.write_text(yaml.safe_dump(tiny_config(overrides)))


TINY = config.validate(tiny_config())
T_WALL, T_INLET = float(TINY["thermal"]["walls"]["heated_wall"]["temperature"]), TINY["thermal"]["inlet_temperature"]


def snakemake(workdir, *args, config="tiny.yaml"):
    """Run the workflow in ``workdir`` with the config file ``workdir/config`` (see write_config)."""
    return subprocess.run(
        [*SNAKEMAKE, "--directory", str(workdir), *args, "--configfile", str(workdir / config)],
        capture_output=True,
        text=True,
        timeout=900,
    )


def job_counts(result) -> dict:
    """Rule -> number of jobs, from the "Job stats" table of a (dry) run."""
    assert result.returncode == 0, result.stderr[-3000:]
    table = (result.stdout + result.stderr).split("Job stats:")[1].split("total")[0]
    return {line.split()[0]: int(line.split()[1]) for line in table.splitlines()[3:] if line.strip()}


# --- the plan, without Snakemake ---------------------------------------------------------------


def plan_of(**variants):
    cfg = config.load(DEFAULT)
    cfg["variants"] = {"base": {}, **variants}
    return Plan(config.validate(cfg))


def screened_as(off=()):
    """A stand-in for the workflow's reader of a screening stage's decisions: every effect it
    decides is on, but those in ``off``."""
    return lambda key: {name: effects.Decision(name, name not in off, "test", by="screening").record()
                        for name in effects.SCREENED}  # fmt: skip


def test_plan_of_the_default_config():
    plan = Plan(config.load(DEFAULT))
    keys = plan.keys["base"]
    asked = ("watkins", "watkins_reduction", "mixers", "radiation", "intraparticle")
    assert plan.name == "default" and plan.asked == asked
    assert plan.targets() == [*(f"results/default/base/figures/{f}.png" for f in FIGURES), "results/default/base/summary.json",
                              *(t for name in asked for t in plan.study_targets(name))]  # fmt: skip
    assert plan.study_targets("mixers") == [f"results/default/studies/mixers/{name}" for name in
                                            ("fig14.png", "fig15.png", "fig16.png", "mixers.csv", "mixers.md", "mixers.json")]  # fmt: skip
    # its own HTC tables: its DEM run measures its solid fractions
    assert plan.studies["watkins_reduction"].scenes["full"]["dem"]["drive"]
    # Every mode is auto: the screening stage decides them on the DEM run's settled bed.
    assert plan.runs[keys["screening"]].upstream == {"geometry": keys["geometry"], "dem": keys["dem"]}
    assert plan.screening_inputs(keys["screening"]) == {
        "positions": f"results/dem/{keys['dem']}/positions.h5",
        "dem_summary": f"results/dem/{keys['dem']}/summary.json",
        "walls": f"results/geometry/{keys['geometry']}/walls.h5",
        "rdf": str(ROOT / "tables" / "rdf" / "shipped" / f"{keys['rdf']}.h5"),  # its own (shipped) table
    }
    with pytest.raises(ValueError, match="needs the decisions of its screening stage"):
        plan.thermal_inputs(keys["thermal"])
    inputs = plan.thermal_inputs(keys["thermal"], screened_as())
    assert inputs == {
        "positions": f"results/dem/{keys['dem']}/positions.h5",
        "dem_summary": f"results/dem/{keys['dem']}/summary.json",
        "walls": f"results/geometry/{keys['geometry']}/walls.h5",
        "screening": f"results/screening/{keys['screening']}/screening.json",
        "pfp": f"tables/htc/{keys['pfp']}.h5",
        "pfw": f"tables/htc/{keys['pfw']}.h5",
        "rdf": str(ROOT / "tables" / "rdf" / "shipped" / f"{keys['rdf']}.h5"),
    }
    assert Path(inputs["rdf"]).is_file()  # the shipped table: the default run traces no rays
    # Tables only for the modes the screening keeps.
    assert set(inputs) - set(plan.thermal_inputs(keys["thermal"], screened_as(("pp_radiation", "pfw")))) == {"pfw"}
    assert set(inputs) - set(plan.thermal_inputs(keys["thermal"], screened_as(effects.RADIATION))) == {"rdf"}
    radiation = json.loads(plan.studies["radiation"].spec_json())["key"]  # the keyed stage run it publishes
    assert plan.keyed_inputs(radiation) == {"rdf": inputs["rdf"]}  # the study shares that table
    assert dict(plan.studies["radiation"].inputs)["figure"] == f"results/radiation_study/{radiation}/fig9.png"
    assert plan.dem_inputs(keys["dem"])["walls"] == inputs["walls"]
    # The default solid fraction is measured: the HTC tables and the thermal run name the DEM run
    # they read it from (so it is in their keys) and take its summary as an input.
    assert plan.runs[keys["thermal"]].spec["thermal"]["solid_fraction"] == {
        region: {"measured": keys["dem"], "region": region} for region in ("bulk", "near_wall")}
    for kind, region in (("pfp", "bulk"), ("pfw", "near_wall")):
        assert plan.runs[keys[kind]].spec["solid_fraction"] == {"measured": keys["dem"], "region": region}
        assert plan.htc_inputs(keys[kind]) == {"dem_summary": inputs["dem_summary"]}
    mixed = plan_of(given={"thermal": {"solid_fraction": {"bulk": 0.6, "near_wall": "measured"}}})
    given = mixed.keys["given"]
    assert mixed.runs[given["pfp"]].spec["solid_fraction"] == 0.6 and mixed.htc_inputs(given["pfp"]) == {}
    assert mixed.htc_inputs(given["pfw"]) == {"dem_summary": inputs["dem_summary"]}
    # The variant's summary is written after its figures, so it names the runs they were drawn from.
    assert set(plan.summary_inputs("base").values()) >= set(plan.targets()[:len(FIGURES)])
    summary = json.loads(plan.summary_spec("base"))["stage_keys"]
    assert summary == keys and len(set(keys.values())) == 7


def test_variants_share_every_stage_they_do_not_change():
    plan = plan_of(hot={"thermal": {"inlet_temperature": 500.0}}, long={"geometry": {"tube": {"length": 0.06}}})
    base, hot, long = (plan.keys[v] for v in ("base", "hot", "long"))
    assert {s: hot[s] == base[s] for s in base} == {"geometry": True, "dem": True, "pfp": True, "pfw": True, "rdf": True,
                                                    "screening": False, "thermal": False}  # fmt: skip
    # Another DEM run measures other solid fractions: its HTC tables are its own.
    assert {s: long[s] == base[s] for s in base} == {"geometry": False, "dem": False, "pfp": False, "pfw": False,
                                                     "rdf": True, "screening": False, "thermal": False}  # fmt: skip
    given = plan_of(long={"geometry": {"tube": {"length": 0.06}}, "thermal": {"solid_fraction": 0.6}},
                    short={"thermal": {"solid_fraction": 0.6}})  # fmt: skip
    assert {s: given.keys["long"][s] == given.keys["short"][s] for s in ("dem", "pfp", "pfw")} == {
        "dem": False, "pfp": True, "pfw": True}  # a given solid fraction: the tables are shared
    targets = plan.targets()
    assert "results/default/comparison/variants.png" in targets and "results/default/long/figures/cross_section.png" in targets
    comparison = plan.comparison_inputs()
    assert comparison["thermal_hot"] == f"results/thermal/{hot['thermal']}/thermal.h5"
    assert len(comparison) == 9 and json.loads(plan.comparison_spec())["variants"] == ["base", "hot", "long"]


def test_run_settings_ride_along_outside_the_dem_key():
    plan = plan_of(checked={"dem": {"ranks": 1, "target_mass_flow": 0.01, "mass_flow_tolerance": 0.05}})
    base, checked = plan.keys["base"]["dem"], plan.keys["checked"]["dem"]
    assert base == checked  # one DEM run; the variant named last sets its ranks and check
    assert plan.threads(checked) == 1
    spec = json.loads(plan.spec_json(checked))
    assert spec["dem"]["target_mass_flow"] == 0.01 and "ranks" not in spec["dem"]
    # How often the thermal stage saves its state rides along too: it never changes the result.
    thermal = plan.keys["base"]["thermal"]
    ridden = json.loads(plan.spec_json(thermal))
    assert {k: ridden["thermal"].pop(k) for k in config.THERMAL_RUN_SETTINGS} == {"checkpoint_frames": 500,
                                                                                "checkpoint_minutes": 10}  # fmt: skip
    assert ridden == plan.runs[thermal].spec
    frequent = plan_of(frequent={"thermal": {"checkpoint_frames": 5, "checkpoint_minutes": 0.5}})
    assert frequent.keys["frequent"] == frequent.keys["base"]
    assert json.loads(frequent.spec_json(frequent.keys["frequent"]["thermal"]))["thermal"]["checkpoint_frames"] == 5


def test_rdf_input_is_the_built_table_a_given_file_or_none():
    plan = plan_of(given={"thermal": {"rdf_table": "my/table.h5"}},
                   dark={"thermal": {"modes": {"pp_radiation": False, "pw_radiation": False}}})  # fmt: skip
    assert plan.keys["given"]["rdf"] is None and plan.keys["dark"]["rdf"] is None
    assert plan.thermal_inputs(plan.keys["given"]["thermal"], screened_as())["rdf"] == "my/table.h5"
    assert plan.screening_inputs(plan.keys["given"]["screening"])["rdf"] == "my/table.h5"  # it screens with it too
    assert "rdf" not in plan.thermal_inputs(plan.keys["dark"]["thermal"], screened_as())
    assert "rdf" not in plan.screening_inputs(plan.keys["dark"]["screening"])


def test_figures_spec_comes_from_the_variant():
    plan = plan_of(hot={"thermal": {"walls": {"orifice": {"temperature": "600"}}}, "particles": {"diameter": 0.8e-3}})
    spec = json.loads(plan.figures_spec("hot"))
    assert spec["heated_zones"] == ["heated_wall", "orifice"]
    assert spec["radial_band"] == [0.004, 0.004 + 1.6e-3] and spec["htc"]["radius"] == 0.4e-3
    assert json.loads(plan.figures_spec("base"))["heated_zones"] == ["heated_wall"]


def test_accuracy_spec_is_the_study_runs_measured_on_its_own_scene():
    """The accuracy study's runs are around its scene (config/tube.yaml), whatever the design's
    variants are; it is planned when asked for by name (a target outside `all`)."""
    cfg = config.load(DEFAULT)
    cfg["variants"] = {"small": {"particles": {"diameter": 0.8e-3}, "thermal": {"inlet_temperature": 500.0}}, "base": {}}
    plan, default = Plan(config.validate(cfg)), Plan(config.load(DEFAULT))
    assert "accuracy" not in plan.studies and not any("/accuracy/" in t for t in plan.targets())
    spec = json.loads(plan.study("accuracy").spec_json())
    assert spec == json.loads(default.study("accuracy").spec_json())  # nothing of the design reaches it
    tube = config.variant(config.load(ROOT / "config" / "tube.yaml"), "base")
    orifice = tube["geometry"]["tube"]["orifice_height"]
    assert {k: v for k, v in spec.items() if k != "runs"} == {
        "window": [0.5, 1.0], "radial_band": [orifice, orifice + 2.0e-3], "inlet_temperature": tube["thermal"]["inlet_temperature"],
        "specific_heat": tube["particles"]["specific_heat"], "tolerance": cfg["accuracy"]["tolerance"]}  # fmt: skip
    # Every run's stage keys are runs of the plan, and the inputs hold what the stage reads of each run.
    inputs = plan.studies["accuracy"].inputs
    for i, run in enumerate(spec["runs"]):
        assert all(key in plan.runs for key in run["keys"].values() if key is not None)
        wanted = ["study"] if "radiation_study" in run["keys"] else ["thermal", "thermal_summary", "positions", "dem_summary"]
        wanted += ["walls"] if run["scene"] == "slice" else []  # the slice's outputs are the Watkins figures'
        assert all(f"{i}_{name}" in inputs for name in wanted), run
    assert plan.study_targets("accuracy")[0] == "results/default/studies/accuracy/accuracy.csv"


def test_calibration_spec_is_the_variants_merged_config():
    plan = plan_of(narrow={"geometry": {"tube": {"orifice_diameter": 5.0e-3}}, "dem": {"ranks": 1}})
    for variant in ("base", "narrow"):
        assert json.loads(plan.calibration_spec(variant)) == json.loads(json.dumps(plan.configs[variant]))
    assert json.loads(plan.calibration_spec("narrow"))["geometry"]["tube"]["orifice_diameter"] == 5.0e-3
    assert plan.calibration_threads("narrow") == 1
    assert plan.calibration_threads("base") == config.load(DEFAULT)["dem"]["ranks"]
    assert plan.calibration_targets() == ["results/default/base/calibration/orifice.json",
                                          "results/default/narrow/calibration/orifice.json"]


def test_watkins_inputs_and_reduction_spec_name_the_runs_of_their_scenes():
    plan = Plan(config.load(DEFAULT))
    watkins, reduction = plan.studies["watkins"], plan.studies["watkins_reduction"]
    scene = plan.register_scenes(dict(watkins.scenes))["watkins"]
    assert dict(watkins.inputs) == {"positions": f"results/dem/{scene['dem']}/positions.h5",
                                    "walls": f"results/geometry/{scene['geometry']}/walls.h5",
                                    "thermal": f"results/thermal/{scene['thermal']}/thermal.h5"}  # fmt: skip
    variants = yaml.safe_load((ROOT / "config" / "watkins_reduction.yaml").read_text())["variants"]
    spec = json.loads(reduction.spec_json())
    assert spec == {"slices": list(variants)[1:], "window": variants["full"]["figures"]["steady_window"]}
    # The inputs hold what the reduction stage reads: the full tube's files and each slice's (its DEM
    # box is the slice's length).
    keys = plan.register_scenes(dict(reduction.scenes))
    inputs = reduction.inputs
    assert {inputs[f"full_{k}"] for k in ("positions", "walls", "thermal")} == {
        f"results/dem/{keys['full']['dem']}/positions.h5", f"results/geometry/{keys['full']['geometry']}/walls.h5",
        f"results/thermal/{keys['full']['thermal']}/thermal.h5"}  # fmt: skip
    for name in spec["slices"]:
        assert inputs[f"{name}_thermal"] == f"results/thermal/{keys[name]['thermal']}/thermal.h5"
        assert inputs[f"{name}_walls"] == f"results/geometry/{keys[name]['geometry']}/walls.h5"
        assert inputs[f"{name}_positions"] == f"results/dem/{keys[name]['dem']}/positions.h5"
    # A study the config does not ask for is not planned; its section set to null cannot be asked for.
    cfg = config.load(DEFAULT)
    cfg.update(studies=["watkins"], watkins_reduction=None)
    bare = Plan(config.validate(cfg))
    assert list(bare.studies) == ["watkins"] and not any("watkins_reduction" in t for t in bare.targets())
    with pytest.raises(config.ConfigError, match="watkins_reduction: the study 'watkins_reduction' is asked for, but the "
                                                 "config sets the section to null"):  # fmt: skip
        bare.study("watkins_reduction")


def test_variant_summary_stage_collects_the_stage_summaries(tmp_path):
    inputs = {name: tmp_path / f"{name}.json" for name in ("geometry", "dem", "thermal")}
    for name, file in inputs.items():
        file.write_text(json.dumps({"from": name}))
    inputs["figure_cross_section"] = tmp_path / "cross_section.png"  # listed, not read
    out = tmp_path / "base" / "summary.json"
    io = json.dumps({"input": {k: str(v) for k, v in inputs.items()}, "output": {"summary": str(out)}, "threads": 1})
    keys = {"geometry": "a" * 12, "dem": "b" * 12}
    assert stages.run("variant_summary", json.dumps({"stage_keys": keys}), io, str(tmp_path / "summary.log")) == 0
    summary = json.loads(out.read_text())
    assert summary == {"stage_keys": keys, "geometry": {"from": "geometry"}, "dem": {"from": "dem"}, "thermal": {"from": "thermal"},
                       "figures": ["cross_section.png"]}
    # With the report's table of the effects the thermal run was decided to have.
    decided = [effects.Decision("pfp", True, "set in the config", True).record(),
               effects.Decision("pp_radiation", False, "0.3% of the pair conductance at T = 420 K", "auto", "screening",
                                0.003, 0.01).record()]  # fmt: skip
    inputs["thermal"].write_text(json.dumps({"effects": decided}))
    io = json.loads(io)
    io["output"]["effects"] = str(tmp_path / "base" / "effects.csv")
    assert stages.run("variant_summary", json.dumps({"stage_keys": keys}), json.dumps(io), str(tmp_path / "summary.log")) == 0
    assert (tmp_path / "base" / "effects.csv").read_text().splitlines() == [
        "effect,on,by,estimate,threshold,reason", "pfp,True,config,,,set in the config",
        "pp_radiation,False,screening,0.003,0.01,0.3% of the pair conductance at T = 420 K"]


# --- Snakemake: job lists and lint --------------------------------------------------------------


@pytest.fixture
def workdir(tmp_path):
    """A working folder that sees config/ (the Snakefile's config/config.yaml) and the shipped RDF
    tables, as a checkout does."""
    (tmp_path / "config").symlink_to(ROOT / "config")
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "rdf").symlink_to(ROOT / "tables" / "rdf")
    return tmp_path


def dry_run(workdir, *args, configfile=DEFAULT):
    """A dry run of the workflow in ``workdir`` with ``configfile``, every job listed (``--forceall``)."""
    return subprocess.run([*SNAKEMAKE, "--directory", str(workdir), "--dry-run", "--forceall", *args, "--configfile",
                           str(configfile)], capture_output=True, text=True, timeout=300)  # fmt: skip


def planned_files(result) -> set[str]:
    """Every output and log path of the jobs of a dry run."""
    assert result.returncode == 0, result.stderr[-3000:]
    lines = re.findall(r"^ {4}(?:output|log): (.+)$", result.stdout + result.stderr, flags=re.MULTILINE)
    return {path for line in lines for path in line.split(", ")}


def rule_names() -> set[str]:
    """Every rule of the workflow: written in the Snakefile and rules, or made from the studies' registry."""
    files = [ROOT / "workflow" / "Snakefile", *sorted((ROOT / "workflow" / "rules").glob("*.smk"))]
    written = {m for f in files for m in re.findall(r"^(?:rule|checkpoint) (\w+):", f.read_text(), flags=re.M)}
    return written | set(studies.STUDIES) | set(studies.KEYED)


def test_default_and_mixer_configs_plan_the_documented_jobs(workdir):
    default = dry_run(workdir)
    # The Watkins validation adds its slice (geometry, DEM, thermal) and the reduction check's driven
    # full tube (geometry, DEM, thermal) and slices (two geometries, three DEM runs, four thermal runs: one
    # carries the full tube's own DEM run); the mixer study its three
    # variants (geometry, DEM, thermal each) and their figures; every DEM run's measured solid fractions
    # give its scene its own two HTC tables. The radiation and intra-particle studies publish their
    # keyed stage runs in the run's folder.
    # Before the screening stages have run, only the Watkins and mixer scenes (every mode set in their
    # configs) ask for their HTC tables; the other scenes' tables follow their screening (a checkpoint).
    assert job_counts(default) == {"geometry": 8, "htc_table": 8, "radiation_study": 1, "intraparticle_study": 1, "dem": 9,
                                   "screening": 6, "thermal": 10, "figures": 1, "variant_summary": 1, "watkins": 1,
                                   "watkins_reduction": 1, "mixers": 1, "radiation": 1, "intraparticle": 1, "all": 1}  # fmt: skip
    # `snakemake mixers` runs the mixer study alone: config/mixers.yaml's three variants and Figs. 14-16.
    assert job_counts(dry_run(workdir, "mixers")) == {"geometry": 3, "htc_table": 6, "dem": 3, "thermal": 3, "mixers": 1}


def test_a_design_config_runs_its_design_alone(workdir, tmp_path):
    """An engineer's own design (config/examples/my_design.yaml: 0.6 mm particles, a wall temperature
    rising along z, a variant with two flat plates), given with --configfile over config/config.yaml:
    its geometry, DEM, screening, thermal runs, figures and comparison, and no study; its results in
    results/my_design/; its stage keys those of the file read alone (config/config.yaml's base scene
    does not reach them). A study is still run when named."""
    counts = job_counts(dry_run(workdir, configfile=MY_DESIGN))
    assert counts == {"geometry": 2, "dem": 2, "screening": 2, "thermal": 2, "figures": 2, "variant_summary": 2,
                      "compare_variants": 1, "all": 1}  # fmt: skip
    merged, alone = from_files([DEFAULT, MY_DESIGN]), from_files([MY_DESIGN])
    assert merged.name == "my_design" and merged.asked == () and merged.studies == {}
    assert merged.keys == alone.keys and merged.variants == ["plain", "two_plates"]
    assert merged.runs[merged.keys["plain"]["dem"]].spec["particles"]["diameter"] == 0.6e-3
    assert all(t.startswith("results/my_design/") for t in merged.targets())
    assert set(job_counts(dry_run(workdir, "watkins", configfile=MY_DESIGN))) == {"geometry", "htc_table", "dem", "thermal", "watkins"}
    # A bad DEM step in it is reported once, for both variants (no study repeats it).
    bad = tmp_path / "my_design.yaml"
    bad.write_text(MY_DESIGN.read_text().replace("timestep: 5.0e-6 ", "timestep: 5.0e-4 "))
    result = dry_run(workdir, configfile=bad)
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert result.stderr.count("dem.timestep = 0.0005 s") == 1, result.stderr
    line = next(k + 1 for k, text in enumerate(bad.read_text().splitlines()) if "timestep:" in text)
    assert f"{bad}:{line}: dem.timestep = 0.0005 s" in result.stderr and "(variants plain, two_plates)" in result.stderr


def test_the_quick_run_writes_apart_from_the_default_run(workdir):
    """config/quick.yaml's jobs write into results/quick/ and the shared stage caches; the default
    run's into results/default/ and the caches: no file of one run's folder is the other's."""
    quick, default = planned_files(dry_run(workdir, configfile=QUICK)), planned_files(dry_run(workdir))
    caches = tuple(f"{folder}/" for folder in [*paths.CACHE_FOLDERS.values(), *paths.TABLE_FOLDERS.values()])
    assert all(f.startswith(("results/quick/", *caches)) for f in quick), sorted(quick)
    assert all(f.startswith(("results/default/", *caches)) for f in default), sorted(default)
    assert {f for f in quick & default if not f.startswith(caches)} == set()
    assert "results/quick/studies/watkins/fig11.png" in quick and "results/default/studies/watkins/fig11.png" in default


def test_reserved_names_are_the_folders_the_rules_write(workdir):
    """The table of reserved names (dpht.paths) equals the folders the rules write: under results/
    the stage caches beside the runs' folders, and in a run's folder the folders beside its variants."""
    chain = tiny_config(yaml.safe_load((TEST_CONFIG.parent / "chain.yaml").read_text()))  # a variant as a chain of segments
    chain["variants"] = {"plain": {}}
    (workdir / "chain.yaml").write_text(yaml.safe_dump(chain))
    files = (planned_files(dry_run(workdir)) | planned_files(dry_run(workdir, configfile=QUICK))
             | planned_files(dry_run(workdir, configfile=workdir / "chain.yaml")))
    runs = {"default": ["base"], "quick": ["base", "flat_plate"], "tiny": ["plain"]}
    under_results = {f.split("/")[1] for f in files if f.startswith("results/")}
    assert under_results - set(runs) == paths.reserved_run_names()
    beside_variants = {f.split("/")[2] for f in files if f.split("/")[1] in runs and f.split("/")[2] not in runs[f.split("/")[1]]}
    assert beside_variants == paths.reserved_variant_names()


def test_nothing_is_planned_that_a_scene_does_not_need(tmp_path):
    """Scenes whose config alone decides their effects (``thermal.effects: all``): no RDF table
    without radiation, no particle-wall table without a wall with a temperature, no HTC table in a
    vacuum, and a static bed (a frozen bed of the settled bed) has a DEM run without a flow phase
    (one dry run, variants)."""
    overrides = {"thermal": {"effects": "all"}, "variants": {
        "base": {},
        "dark": {"thermal": {"modes": {"pp_radiation": False, "pw_radiation": False}}},
        "adiabatic": {"thermal": {"walls": {"heated_wall": "adiabatic"}, "modes": {"pp_radiation": False}}},
        "static": {"thermal": {"frozen_bed": {"frame": 0, "duration": 1.0, "step": 0.1}}},
        "vacuum": {"thermal": {"gas_pressure": 0.0}}}}  # fmt: skip
    cfg = tiny_config(overrides)
    del cfg["thermal"]["rdf_table"]  # the workflow's own table then: shipped for these emissivities
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(cfg))
    plan = Plan(config.validate(cfg))
    keys = plan.keys
    assert all(k["screening"] is None for k in keys.values())  # the config decides everything
    assert keys["dark"]["rdf"] is None and keys["base"]["rdf"] is not None
    assert keys["adiabatic"]["pfw"] is None and keys["adiabatic"]["pfp"] == keys["base"]["pfp"]
    assert keys["adiabatic"]["rdf"] is None  # its one radiation mode left is particle-wall: off, no wall to see
    assert keys["vacuum"]["pfp"] is None and keys["vacuum"]["pfw"] is None  # no gas: no HTC tables
    assert set(plan.thermal_inputs(keys["vacuum"]["thermal"])) == {"positions", "dem_summary", "walls", "rdf"}
    assert plan.runs[keys["static"]["dem"]].spec["dem"]["flow_time"] == 0 != plan.runs[keys["base"]["dem"]].spec["dem"]["flow_time"]
    for name in ("dark", "adiabatic"):
        assert "rdf" not in plan.thermal_inputs(keys[name]["thermal"]), name
    assert set(plan.thermal_inputs(keys["adiabatic"]["thermal"])) >= {"pfp"} and "pfw" not in plan.thermal_inputs(
        keys["adiabatic"]["thermal"])  # fmt: skip
    assert plan.thermal_inputs(keys["base"]["thermal"])["rdf"] == plan.thermal_inputs(keys["static"]["thermal"])["rdf"]
    counts = job_counts(snakemake(tmp_path, "--dry-run"))
    # One geometry; the flowing DEM run and the static bed's; the PFP table (at the config's bulk
    # solid fraction) shared, a PFW table per DEM run (its measured near-wall solid fraction) but
    # none for the adiabatic scene; no RDF job (the shipped table).
    assert counts == {"geometry": 1, "dem": 2, "htc_table": 3, "thermal": 5, "figures": 5, "variant_summary": 5,
                      "compare_variants": 1, "all": 1}, counts  # fmt: skip


def test_misspelt_key_stops_with_the_key_named(tmp_path):
    write_config(tmp_path / "tiny.yaml", {"thermal": {"inlet_temperatur": 300.0}})
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode != 0
    assert "thermal.inlet_temperatur: unknown key (did you mean 'inlet_temperature'?)" in result.stderr
    assert "Traceback" not in result.stderr


def test_report_front_page_and_manual_describe_every_rule():
    rules = rule_names()
    assert {"all", "geometry", "dem", "screening", "thermal", "accuracy", "screening_check", "calibrate_orifice"} <= rules
    page = (ROOT / "workflow" / "report" / "workflow.rst").read_text()
    stages = (ROOT / "docs" / "guide" / "workflow.md").read_text().split("\n## Stages\n")[1].split("\n## ")[0]
    assert [r for r in sorted(rules) if f"**{r}**" not in page] == []
    assert [r for r in sorted(rules) if f"`{r}`" not in stages] == []


@pytest.mark.parametrize("snakefile, configfile", [("Snakefile", DEFAULT), ("Snakefile", QUICK), ("workflow/Snakefile", DEFAULT)],
                         ids=["default", "quick", "workflow-snakefile"])  # fmt: skip
def test_snakemake_lint_finds_nothing(workdir, snakefile, configfile):
    """The rules run their stage from a run: block (workflow/rules/common.smk, run_stage), so lint
    does not even advise a conda environment per rule; the project installs with apt and a venv.
    The catalog's entry point, workflow/Snakefile, given alone too (the top-level Snakefile includes it)."""
    result = subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / snakefile), "--directory", str(workdir),
                             "--lint", "--configfile", str(configfile)], capture_output=True, text=True, timeout=300)  # fmt: skip
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    assert re.findall(r"^ {4}\* (.+?):$", text, flags=re.MULTILINE) == [], text
    assert "Congratulations, your workflow is in a good condition!" in text


# --- end to end on the tiny scene (real LIGGGHTS) ------------------------------------------------


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The tiny workflow run once; beside it ``check.txt``, `dpht check`'s preview before it ran, and
    ``snakemake.err``, what snakemake printed on standard error."""
    import contextlib
    import io

    from dpht.__main__ import main

    workdir = tmp_path_factory.mktemp("workflow")
    write_config(workdir / "tiny.yaml")
    with contextlib.redirect_stdout(io.StringIO()) as preview:
        assert main(["check", str(workdir / "tiny.yaml"), "-d", str(workdir), "--cores", "2"]) == 0
    (workdir / "check.txt").write_text(preview.getvalue())
    result = snakemake(workdir)
    assert result.returncode == 0, result.stderr[-4000:]
    (workdir / "snakemake.err").write_text(result.stderr)
    return workdir


@end_to_end
def test_one_overall_progress_line_with_the_previews_total_and_an_eta(run):
    """`snakemake --cores 2` prints an overall line at its start, at each stage job's start and end
    and at its end: its total is `dpht check`'s estimate of the same jobs, the runs done count up
    to all of them, and the ETA comes down to 0 s at the end."""
    total = re.search(r"about (.+?) of wall time for these on the cores given", (run / "check.txt").read_text()).group(1)
    err = (run / "snakemake.err").read_text()
    assert f"overall: estimated {total} of wall time for 1 DEM and 1 thermal run(s)" in err
    lines = re.findall(r"^overall: (.+) of (.+) estimated done \((\d)/2 DEM and thermal runs\), .+ elapsed, ETA (.+) \[(.+)\]$",
                       err, re.MULTILINE)  # fmt: skip
    assert {line[1] for line in lines} == {total}
    assert lines[0][4] == "start" and lines[-1][4] == "end" and lines[0][3] == total and lines[-1][3] == "0 s"
    assert {"dem started", "dem done", "thermal started", "thermal done", "figures done"} <= {line[4] for line in lines}
    done = [int(line[2]) for line in lines]
    assert done == sorted(done) and done[0] == 0 and done[-1] == 2


@end_to_end
def test_outputs_exist(run):
    summary = json.loads((run / "results" / "tiny" / "base" / "summary.json").read_text())
    for name in FIGURES:
        assert (run / "results" / "tiny" / "base" / "figures" / f"{name}.png").stat().st_size > 10_000
    assert summary["dem"]["particles"] > 300
    assert summary["dem"]["orifice_crossings"] > 0, "particles never flowed through the orifice"
    keys = summary["stage_keys"]
    assert (run / "results" / "thermal" / keys["thermal"] / "thermal.xdmf").is_file()


@end_to_end
def test_headline_and_the_preview_of_the_finished_run(run, capsys):
    """The headline beside the variant's summary gives the engineering figure's and the DEM run's
    numbers; `dpht check` of the finished run gives the particles the DEM set out to insert and
    nothing left to run."""
    from dpht.__main__ import main

    base = run / "results" / "tiny" / "base"
    summary = json.loads((base / "summary.json").read_text())
    balance = json.loads((base / "figures" / "engineering.json").read_text())
    with open(base / "headline.csv") as stream:
        (row,) = csv.DictReader(stream)
    assert float(row["outlet_temperature_K"]) == balance["outlet_temperature_K"]
    assert float(row["wall_heat_W"]) == pytest.approx(balance["duty_W"], rel=1e-6)
    assert float(row["mass_flow_kg_s"]) == summary["dem"]["mass_flow_second_half_kg_s"]
    assert float(row["htc_W_m2K"]) == summary["headline"]["htc_W_m2K"] > 0
    assert float(row["thermal_seconds"]) == summary["thermal"]["seconds"]
    assert "h_w = Q / (A_w <T_w - T_b>)" in (base / "headline.md").read_text()
    assert main(["check", str(run / "tiny.yaml"), "-d", str(run), "--cores", "2"]) == 0
    out = capsys.readouterr().out
    assert f"DEM: {summary['dem']['particles_target']:,} particles (fill estimate)" in out
    assert "jobs to run (snakemake --dry-run): 0 (all done)" in out


def thermal_file(run):
    keys = json.loads((run / "results" / "tiny" / "base" / "summary.json").read_text())["stage_keys"]
    return run / "results" / "thermal" / keys["thermal"] / "thermal.h5", run / "results" / "dem" / keys["dem"] / "positions.h5"


@end_to_end
def test_particles_heat_towards_the_wall_and_never_beyond(run):
    thermal, positions = thermal_file(run)
    with h5py.File(thermal) as f:
        T = f["temperature"][...]
        assert np.nanmin(T) >= T_INLET - 1e-3
        assert np.nanmax(T) <= T_WALL + 1e-3
        assert np.nanmean(T[-1]) > np.nanmean(T[0]) + 1.0
        last = T[-1]
    with PositionsFile(positions) as dem:
        pos = dem.frame(dem.n_frames - 1).positions
    tube, d = TINY["geometry"]["tube"], TINY["particles"]["diameter"]
    r, R = np.hypot(pos[:, 0], pos[:, 1]), tube["inner_diameter"] / 2
    heated = (pos[:, 2] > tube["heated"][0] + 2 * d) & (pos[:, 2] < tube["heated"][1])
    near_wall = heated & (r > R - 1.2 * d)
    centre = heated & (r < R / 2)
    assert np.nanmean(last[near_wall]) > np.nanmean(last[centre]) + 5.0


@end_to_end
def test_energy_balance_closes_every_frame(run):
    thermal, _ = thermal_file(run)
    with h5py.File(thermal) as f:
        e = f["energy/particles"][...]
        wall = f["energy/wall"][...]
        recycled = f["energy/recycled"][...]
    change = np.diff(e)
    sources = np.diff(wall) + np.diff(recycled)
    assert np.max(np.abs(change - sources)) <= 1e-9 * max(np.max(np.abs(wall)), 1e-12)
    assert wall[-1] > 0


@end_to_end
def test_second_run_does_nothing_and_thermal_change_skips_dem(run):
    again = snakemake(run, "--dry-run")
    assert again.returncode == 0
    assert "Nothing to be done" in again.stdout + again.stderr
    write_config(run / "changed.yaml", {"particles": {"conductivity": 3.0}})
    dry = snakemake(run, "--dry-run", config="changed.yaml")
    # The HTC tables it will need are planned once the screening stage (a checkpoint) has decided.
    assert set(job_counts(dry)) == {"screening", "thermal", "figures", "variant_summary", "all"}


@end_to_end
def test_no_rdf_table_is_built_for_radiation_the_screening_switched_off(run):
    """A cold and a hot scene on the tiny scene's DEM run, of dark particles (emissivity 0.05, no
    RDF table shipped for it): once each one's screening stage has run, the hot one plans the RDF
    table job and the cold one does not (radiation below the 1% threshold at 300-310 K)."""
    plans = {}
    for name, thermal in (("cold", {"initial_temperature": 300.0, "inlet_temperature": 300.0,
                                    "walls": {"heated_wall": {"temperature": "310"}}}),
                          ("hot", {"walls": {"heated_wall": {"temperature": "1300"}}})):  # fmt: skip
        overrides = {"particles": {"emissivity": 0.05}, "thermal": thermal}
        cfg = tiny_config(overrides)
        del cfg["thermal"]["rdf_table"]
        (run / f"{name}.yaml").write_text(yaml.safe_dump(cfg))
        plan = Plan(config.validate(cfg))
        assert plan.keys["base"]["dem"] == json.loads((run / "results" / "tiny" / "base" / "summary.json").read_text())["stage_keys"]["dem"]
        screening = path("screening", plan.keys["base"]["screening"], "screening.json")
        assert snakemake(run, screening, config=f"{name}.yaml").returncode == 0
        plans[name] = (json.loads((run / screening).read_text())["decisions"], job_counts(snakemake(run, "--dry-run", config=f"{name}.yaml")))
    (cold, cold_jobs), (hot, hot_jobs) = plans["cold"], plans["hot"]
    assert not cold["pp_radiation"]["on"] and not cold["pw_radiation"]["on"] and "rdf_table" not in cold_jobs
    assert hot["pp_radiation"]["on"] and hot_jobs["rdf_table"] == 1
    # Nothing else to make: the DEM run and the HTC tables are the tiny scene's.
    assert set(cold_jobs) == {"thermal", "figures", "variant_summary", "all"} and cold["pfp"]["on"]


@end_to_end
def test_screening_check_switches_the_screened_out_effects_back_on(run):
    """The tiny scene as configured (nothing screened out) and a cold scene screened coarsely (a 10%
    threshold: radiation, about 7% there, and contact conduction are switched off; the shipped RDF
    table serves both runs): with them back on, wall heat and outlet temperature change by less than
    that threshold (measured: 7.5% and 7.6%)."""
    cold = {"thermal": {"initial_temperature": 300.0, "inlet_temperature": 300.0, "screening_threshold": 0.1,
                        "walls": {"heated_wall": {"temperature": "310"}}}}  # fmt: skip
    # the check's scene: the tiny scene itself (its file, as the section names its scene's)
    write_config(run / "check.yaml", {"screening_check": {"scene": str(run / "check.yaml"), "scenes": {"cold": cold}}})
    result = snakemake(run, "screening_check", config="check.yaml")
    assert result.returncode == 0, result.stderr[-3000:]
    with open(run / "results" / "tiny" / "studies" / "screening_check" / "check.csv") as f:
        rows = {row["scene"]: row for row in csv.DictReader(f)}
    assert set(rows) == {"default", "cold"}
    assert rows["default"]["off"] == "none" and float(rows["default"]["change_wall_heat"]) == 0.0
    off = rows["cold"]["off"].split(";")  # radiation (about 7% there) and contact conduction
    assert {"pp_radiation", "pw_radiation"} <= set(off) and rows["cold"]["by"].split(";") == ["screening"] * len(off)
    change = abs(float(rows["cold"]["change_wall_heat"]))
    assert 0 < change < 0.1 and abs(float(rows["cold"]["change_outlet"])) < 0.1 and rows["cold"]["holds"] == "True"
    assert f"| cold | 300-310 | {', '.join(off)} |" in (run / "results" / "tiny" / "studies" / "screening_check" / "check.md").read_text()


def real_frame(run):
    keys = json.loads((run / "results" / "tiny" / "base" / "summary.json").read_text())["stage_keys"]
    with PositionsFile(run / "results" / "dem" / keys["dem"] / "positions.h5") as dem:
        frame = dem.frame(dem.n_frames // 2)
        box = (np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"]), np.asarray(dem.attrs["periodic"], bool))
    return frame.positions[~frame.lost].astype(np.float64), box, run / "results" / "geometry" / keys["geometry"] / "walls.h5"


@pytest.mark.parametrize("caption", sorted((ROOT / "workflow" / "report").glob("*.rst")), ids=lambda p: p.name)
def test_every_report_caption_is_valid_restructuredtext(caption):
    """snakemake --report renders captions with docutils, which shows markup errors inside the report."""
    import docutils.core

    docutils.core.publish_string(caption.read_text(), writer="html",
                                 settings_overrides={"report_level": 2, "halt_level": 2})


@end_to_end
def test_report_has_the_workflow_page_and_every_figure(run):
    report = run / "report.html"
    result = snakemake(run, "--report", str(report))
    assert result.returncode == 0, result.stderr[-3000:]
    html = report.read_text(errors="replace")
    assert "How to read this report" in html  # workflow/report/workflow.rst
    assert all(f"{name}.png" in html for name in FIGURES)
    # Where each item sits (the report's own tables of its results and categories): the design's
    # category, the variant's subcategory and the geometry's, labelled by figure, variant and study.
    results = json.loads(re.search(r"^\s*var results = (\{.*\});$", html, flags=re.M).group(1))
    categories = json.loads(re.search(r"^\s*var categories = (\{.*\});$", html, flags=re.M).group(1))
    places = {path: (category, sub) for category, subs in categories.items() for sub, paths in subs.items() for path in paths}
    assert set(places) == set(results)
    assert set(places.values()) == {("Design: tiny", "base"), ("Design: tiny", "Geometry")}
    assert sorted(r["labels"]["figure"] for r in results.values()) == sorted([*(n.replace("_", " ") for n in FIGURES), "effects", "geometry"])
    assert all(r["labels"]["variant"] == "base" and r["labels"]["study"] == "design: tiny" for r in results.values())


@end_to_end
def test_every_figure_of_a_variant_and_the_comparison_render_with_their_numbers(run):
    """Each figure of dpht.plan.FIGURES, the geometry picture and, with the variant run again under
    a second name (same stage keys, so only compare_variants runs), the comparison figures: PNG size
    and the CSVs beside them (tests/figure_files.py)."""
    write_config(run / "two.yaml", {"variants": {"base": {}, "again": {}}})
    plan = Plan(config.validate(tiny_config({"variants": {"base": {}, "again": {}}})))
    compared = plan.comparison_files()
    assert set(compared) <= set(plan.targets()) and compared[0] == "results/tiny/comparison/variants.png"
    result = snakemake(run, *compared, config="two.yaml")
    assert result.returncode == 0, result.stderr[-3000:]
    assert job_counts(result) == {"compare_variants": 1}
    pngs = [*(run / figure("base", name, plan.name) for name in FIGURES), run / plan.variant_file("base", "geometry", "geometry.png"),
            *(run / t for t in compared)]  # fmt: skip
    for png in pngs:
        check_figure(png)


@end_to_end
def test_cell_list_equals_brute_force_on_a_real_frame(run):
    positions, (lo, hi, periodic), _ = real_frame(run)
    assert periodic.tolist() == [False, False, True]
    for cutoff in (1.5e-3, 3.5e-3):
        cells = neighbors.build(positions, cutoff, box_lo=lo, box_hi=hi, periodic=periodic)
        found = {tuple(sorted(p)) for p in zip(*neighbors.pairs(cells, cutoff))}
        reference_pairs = set(zip(*neighbors.brute_force_pairs(positions, cutoff, box_lo=lo, box_hi=hi, periodic=periodic)))
        assert found == reference_pairs and len(found) > len(positions)


@end_to_end
def test_all_modes_on_a_real_frame_match_the_brute_force_reference(run):
    """As the thermal stage sees the frame: the walls the DEM used (the exact cylinder, the plate's
    STL), z open for heat (the DEM only recycles particles across it)."""
    positions, (lo, hi, periodic), walls_h5 = real_frame(run)
    walls = load_walls(walls_h5)
    keys = json.loads((run / "results" / "tiny" / "base" / "summary.json").read_text())["stage_keys"]
    with PositionsFile(run / "results" / "dem" / keys["dem"] / "positions.h5") as dem:
        kinds, schedule = dem.summary["walls"], Schedule.of(dem, 1)
    assert kinds["heated_wall"] == "primitive" and schedule.periodic.tolist() == [False, False, False]
    s = scenes.spec(list(MODES), walls={"heated_wall": {"temperature": 900.0}, "adiabatic_wall": "adiabatic", "orifice": "adiabatic"})
    model = thermal_model.build(s, walls, scenes.htc_tables(s), scenes.synthetic_rdf(), kinds)
    T = model.enthalpy.temperature(model.enthalpy.enthalpy(np.random.default_rng(0).uniform(300, 800, len(positions))))
    frame = integrate.prepare_frame(model, positions, lo, hi, schedule.periodic)
    rates = integrate.Rates.for_frame(model, frame)
    integrate.evaluate(model, frame, T[frame.particles], rates)
    q = np.zeros(len(positions))
    q[frame.particles] = rates.q
    q_ref, heat_ref = reference.heat_rates(model, positions, T, walls)  # no periodic images either
    assert np.max(np.abs(q - q_ref)) <= 1e-10 * np.max(np.abs(q_ref))
    # Wall heat involves no particle pairs, so it matches for every particle.
    np.testing.assert_allclose(rates.element_heat.sum(axis=0), heat_ref, rtol=1e-10)


@end_to_end
def test_xdmf_opens_as_a_time_series_in_vtk(run):
    """ParaView reads XDMF with VTK's reader: every frame, every particle, the temperatures."""
    vtk = pytest.importorskip("vtkmodules.vtkIOXdmf2")
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

    thermal, _ = thermal_file(run)
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(thermal.with_suffix(".xdmf")))
    reader.UpdateInformation()
    steps = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    with h5py.File(thermal) as f:
        times = f["time"][...]
        last = f["temperature"][-1]
    np.testing.assert_allclose(steps, times)
    reader.UpdateTimeStep(steps[-1])
    grid = reader.GetOutputDataObject(0)
    assert grid.GetNumberOfPoints() == last.size
    low, high = grid.GetPointData().GetArray("temperature").GetRange()
    assert low == pytest.approx(np.nanmin(last)) and high == pytest.approx(np.nanmax(last))


@end_to_end
def test_a_damaged_result_is_made_again_and_valid_ones_are_kept(run):
    """positions.h5 replaced by a copy cut short (an interrupted rsync, a full disk): the workflow
    sets it aside at start, the DEM stage publishes its intact work copy again (no LIGGGHTS), the
    thermal result stands (or its stage publishes its complete work copy of those very frames: no
    recomputing), and the cheap figures are drawn again."""
    keys = json.loads((run / "results" / "tiny" / "base" / "summary.json").read_text())["stage_keys"]
    positions = run / "results" / "dem" / keys["dem"] / "positions.h5"
    thermal = run / "results" / "thermal" / keys["thermal"] / "thermal.h5"
    before = thermal.read_bytes()
    damaged = positions.with_name("copy.h5")
    damaged.write_bytes(positions.read_bytes()[: positions.stat().st_size // 3])
    damaged.replace(positions)
    result = snakemake(run)
    assert result.returncode == 0, result.stderr[-3000:]
    assert f"{positions.relative_to(run)} is damaged" in result.stderr and positions.with_name("positions.h5.damaged").is_file()
    assert "earlier run of this stage" in (positions.parent / "dem.log").read_text()
    log = (thermal.parent / "thermal.log").read_text()
    # Not run again (Snakemake found it up to date once the screening checkpoint had run), or run
    # and published its complete work copy.
    assert log.count("=== stage thermal") == 1 or "earlier run of these inputs" in log.split("=== stage thermal")[-1]
    assert thermal.read_bytes() == before  # the very result, published again, never recomputed
    with PositionsFile(positions) as dem:
        assert dem.n_frames > 10
    assert "Nothing to be done" in (lambda r: r.stdout + r.stderr)(snakemake(run, "--dry-run"))
    positions.with_name("positions.h5.damaged").unlink()


def test_damaged_outputs_without_a_manifest_are_set_aside_before_the_workflow_plans(tmp_path):
    """Results of runs that wrote no manifest are opened instead (dpht.integrity.damage)."""
    from dpht.integrity import check, damage

    plan = Plan(TINY)
    keys = plan.keys["base"]
    good, cut, json_file = (tmp_path / p for p in (plan.variant_file("base", "geometry", "walls.h5"),
                            plan.variant_file("base", "dem", "positions.h5"), plan.variant_file("base", "dem", "summary.json")))  # fmt: skip
    for path in (good, cut, json_file):
        path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(good, "w") as f:
        f["x"] = np.arange(100000.0)
    cut.write_bytes(good.read_bytes()[:5000])
    json_file.write_text('{"cut": ')
    incomplete = tmp_path / plan.variant_file("base", "thermal", "thermal.h5")
    incomplete.parent.mkdir(parents=True)
    with h5py.File(incomplete, "w") as f:
        f.attrs["complete"] = False
    assert damage(good) is None and "truncated" in damage(cut) and damage(json_file) and damage(incomplete)
    targets, warnings = check(plan, tmp_path)
    assert set(targets) == {str(p.relative_to(tmp_path)) for p in (cut, json_file, incomplete)} and len(warnings) == 3
    assert good.is_file() and not cut.exists() and not json_file.exists()
    assert all(p.with_name(p.name + ".damaged").is_file() for p in (cut, json_file, incomplete))
    assert any(keys["dem"] in w and "positions.h5 is damaged" in w for w in warnings)


def _dem_processes(folder):
    """PIDs of processes (LIGGGHTS, mpirun) whose working directory lies inside ``folder``."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and str(Path(proc / "cwd").resolve()).startswith(str(folder)):
                found.append(int(proc.name))
        except OSError:
            continue
    return found


@end_to_end
def test_workflow_killed_mid_flow_resumes_the_dem_run(tmp_path):
    """SIGKILL the whole workflow during the flow (a lost machine), unlock, re-run: the DEM
    continues from its last restart file and the frames have no gap and no duplicate. Its DEM job
    only (what comes after it is tested on the run fixture's workflow and in test_faults.py)."""
    overrides = {"dem": {"flow_time": 0.6, "restart_interval": 2000}}
    write_config(tmp_path / "tiny.yaml", overrides)
    positions = path("dem", Plan(config.validate(tiny_config(overrides))).keys["base"]["dem"], "positions.h5")
    command = [*SNAKEMAKE, "--directory", str(tmp_path), positions, "--configfile", str(tmp_path / "tiny.yaml")]
    child = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    restarts = []
    while time.monotonic() < deadline and child.poll() is None and len(restarts) < 2:
        restarts = list(tmp_path.glob("results/dem/*/work/flow/restart/flow.*.restart"))
        time.sleep(0.2)
    assert child.poll() is None and len(restarts) >= 2, "the flow ended before it could be killed"
    os.killpg(child.pid, signal.SIGKILL)
    child.wait()
    for pid in _dem_processes(tmp_path.resolve()):  # MPI ranks live in their own process group
        os.kill(pid, signal.SIGKILL)
    assert subprocess.run([*command[:-2], "--unlock", *command[-2:]], capture_output=True).returncode == 0
    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "resuming from" in (tmp_path / positions).with_name("dem.log").read_text()
    with PositionsFile(tmp_path / positions) as dem:
        steps = dem.steps
        assert dem.n_frames == 121  # 0.6 s of flow, a frame every 500 steps of 1e-5 s, both ends
    np.testing.assert_array_equal(np.diff(steps), 500)
