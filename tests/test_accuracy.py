"""The accuracy study (issue 15): its knob registry against the config schema, the jobs it plans
(dry run), and a tiny study end to end on the .test scene (real gmsh, LIGGGHTS, thermal stage)."""

import csv
import json

import pytest
from test_workflow import DEFAULT, end_to_end, job_counts, snakemake, write_config

from dpht import config
from dpht.accuracy import knobs
from dpht.plan import Plan

# The .test scene with a shorter record (0.12 s of flow, dumps every 1000/4 steps for the thermal step).
TINY_STUDY = {"accuracy": {"knobs": ["thermal_step", "radiation_cutoff", "record_length"]},
              "dem": {"flow_time": 0.12, "dump_interval": 1000}}


def _schema_node(key: str) -> dict:
    node = config.schema()
    for part in key.split("."):
        node = node["properties"][part]
    return node


def _get(cfg: dict, key: str):
    for part in key.split("."):
        cfg = cfg[part]
    return cfg


@pytest.mark.parametrize("knob", [k for k in knobs.KNOBS if knobs.runnable(k)], ids=lambda k: k.name)
def test_every_knob_key_is_a_config_key_and_its_default_the_config_default(knob):
    cfg = config.load(DEFAULT)
    scene = config.merge(cfg, cfg["accuracy"]["short_scene"]) if knob.scene == "short" else cfg
    assert knob.reference in knob.settings and knob.default in knob.settings
    for key, default in zip(knob.keys, knob.default):
        assert _schema_node(key)  # KeyError names a key the schema lacks
        if knob.name != "thermal_step":  # the study's stride counts dumps FINEST times finer
            assert _get(scene, key) == default, key
    if knob.name == "thermal_step":
        assert knob.default == (knobs.FINEST * cfg["thermal"]["frame_stride"],)


def test_the_integrator_knob_tries_every_registered_integrator():
    knob = knobs.BY_NAME["integrator"]
    assert knobs.runnable(knob)
    assert sorted(s[0] for s in knob.settings) == sorted(_schema_node(knob.keys[0])["enum"])
    assert knob.reference == ("explicit",) and knob.default == (_schema_node(knob.keys[0])["default"],)


def test_every_setting_is_a_valid_scene_of_the_plan():
    plan = Plan(config.load(DEFAULT))
    assert plan.accuracy_error is None
    assert len(plan.accuracy) == sum(len(k.settings) for k in knobs.KNOBS)
    for knob in knobs.KNOBS:
        mine = [r for r in plan.accuracy if r["knob"] == knob.name]
        assert sum(r["reference"] for r in mine) == (1 if knob.settings else 0)
    tube = {r["keys"]["dem"] for r in plan.accuracy if r["scene"] == "tube"}
    assert len(tube) == 1, "the tube knobs share one DEM run"
    # a thermal knob never re-runs the DEM; each DEM knob setting has a DEM run of its own
    for name in ("youngs_modulus", "dem_timestep"):
        assert len({r["keys"]["dem"] for r in plan.accuracy if r["knob"] == name}) == len(knobs.BY_NAME[name].settings)


def test_a_study_the_config_cannot_make_is_an_error_of_the_study_only():
    cfg = config.load(DEFAULT)
    cfg["dem"]["dump_interval"] = 1002
    cfg["accuracy"]["knobs"] = ["thermal_step"]
    plan = Plan(config.validate(cfg))
    assert plan.accuracy == [] and "dem.dump_interval" in str(plan.accuracy_error)
    with pytest.raises(config.ConfigError, match="multiple of 4"):
        plan.accuracy_inputs()
    assert plan.targets()  # the rest of the workflow is unaffected


def test_dry_run_plans_one_dem_and_a_thermal_run_per_distinct_setting(tmp_path):
    write_config(tmp_path / "tiny.yaml", TINY_STUDY)
    counts = job_counts(snakemake(tmp_path, "-n", "accuracy_cost"))
    # thermal_step 16, 8, 4, 2, 1 and radiation_cutoff 3, 5, 7 (10 is the shared reference); the
    # thermal steps share their screening (it screens the first frame, whatever the stride), each
    # radiation cutoff has its own (the cutoff changes radiation's share); the HTC tables are
    # planned once the screening (a checkpoint) has decided
    assert counts == {"accuracy_cost": 1, "dem": 1, "geometry": 1, "screening": 4, "thermal": 8}, counts


@end_to_end
def test_tiny_study_end_to_end(tmp_path):
    write_config(tmp_path / "tiny.yaml", TINY_STUDY)
    result = snakemake(tmp_path, "accuracy_cost")
    assert result.returncode == 0, result.stderr[-4000:]
    out = tmp_path / "results" / "accuracy"
    with open(out / "accuracy.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 5 + 4 + 4
    for row in rows:
        assert float(row["cost_s"]) > 0
        if row["reference"] == "True":
            assert float(row["error_wall_heat"]) == 0.0 and float(row["error_outlet_temperature"]) == 0.0
    step = {int(r["label"]): abs(float(r["error_wall_heat"])) for r in rows if r["knob"] == "thermal_step"}
    assert step[16] > step[2] > 0, step  # a coarser thermal step is further from the reference
    record = {float(r["label"]): float(r["cost_s"]) for r in rows if r["knob"] == "record_length"}
    assert record[0.25] < record[1.0]
    with open(out / "recommended.csv") as f:
        recommended = {r["knob"]: r for r in csv.DictReader(f)}
    assert set(recommended) == {"thermal_step", "radiation_cutoff", "record_length"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["study_cost_s"] > 0
    for name in ("knobs.png", "pareto.png", "convergence.png"):
        assert (out / name).stat().st_size > 10_000


def test_local_temperatures_of_two_strides_are_compared_at_the_same_time(tmp_path):
    """Row k of thermal.h5 holds the state at the start of its own DEM frame: runs at strides 1 and 4
    are compared at their last common frame itself (not at each run's previous row, 3 frames apart)."""
    import h5py
    import numpy as np

    from dpht.accuracy.outputs import common_frame, state_at

    paths = {}
    for stride in (1, 4):
        frames = np.arange(0, 9, stride)
        paths[stride] = tmp_path / f"stride{stride}.h5"
        with h5py.File(paths[stride], "w") as f:
            f["dem_frame"] = frames
            f["temperature"] = np.repeat(300.0 + frames[:, None], 3, axis=1).astype(np.float32)  # T = 300 K + frame
    assert common_frame(paths[1], paths[4]) == 8
    for stride, path in paths.items():
        np.testing.assert_array_equal(state_at(path, 8), [308.0] * 3)
        np.testing.assert_array_equal(state_at(path, 4), [304.0] * 3)
    assert state_at(paths[4], 5) is None
