"""The accuracy study (issue 15): its knob registry against the config schema, the jobs it plans
(dry run), and a tiny study end to end on the .test scene (real gmsh, LIGGGHTS, thermal stage)."""

import copy
import csv
import json
import math

import h5py
import numpy as np
import pytest
import yaml
from test_workflow import DEFAULT, TEST_CONFIG, end_to_end, job_counts, snakemake, write_config

from dpht import config
from dpht.accuracy import knobs
from dpht.errors import ConfigError
from dpht.plan import Plan
from dpht.studies import first_scene, watkins

# The .test scene with a shorter record (0.12 s of flow, dumps every 1000/4 steps for the thermal step).
TINY_STUDY = {"accuracy": {"knobs": ["thermal_step", "radiation_cutoff", "record_length"]},
              "dem": {"flow_time": 0.12, "dump_interval": 1000}}


def _schema_node(key: str) -> dict:
    node = config.schema()
    for part in key.split("."):
        node = node["properties"][part]
    return node


@pytest.mark.parametrize("knob", [k for k in knobs.KNOBS if knobs.runnable(k)], ids=lambda k: k.name)
def test_every_knob_key_is_a_config_key_and_its_default_the_config_default(knob):
    default = config.load(DEFAULT)
    cfg = scene = first_scene(default["accuracy"], "accuracy.scene")  # the study's own scene (config/tube.yaml)
    if knob.scene == "short":
        scene = config.merge(copy.deepcopy(cfg), default["accuracy"]["short_scene"])
    elif knob.scene == "slice":
        scene = watkins.scene(default["watkins"])
    elif knob.scene == "bed":  # the radiation study's section
        scene = default
    assert knob.reference in knob.settings and knob.default in knob.settings
    for key in knob.keys:
        assert _schema_node(key)  # KeyError names a key the schema lacks
    if knob.name == "thermal_step":  # the study's stride counts dumps FINEST times finer
        assert knob.default == (knobs.FINEST * cfg["thermal"]["frame_stride"],)
    elif knob.keys:  # record_length has none (the start of the reference run)
        assert knob.value_in(scene) == knob.default
    if knob.write is not None:  # the scene's own setting changes no key: it shares the scene's runs
        assert knob.overrides(knob.default, scene) == {}


def test_the_integrator_knob_tries_every_registered_integrator():
    knob = knobs.BY_NAME["integrator"]
    assert knobs.runnable(knob)
    assert sorted(s[0] for s in knob.settings) == sorted(_schema_node(knob.keys[0])["enum"])
    assert knob.reference == ("explicit",) and knob.default == (_schema_node(knob.keys[0])["default"],)


def test_every_setting_is_a_valid_scene_of_the_plan():
    plan = Plan(config.load(DEFAULT))
    runs = json.loads(plan.study("accuracy").spec_json())["runs"]
    assert len(runs) == sum(len(k.settings) for k in knobs.KNOBS)
    for knob in knobs.KNOBS:
        mine = [r for r in runs if r["knob"] == knob.name]
        assert sum(r["reference"] for r in mine) == (1 if knob.settings else 0)
    tube = {r["keys"]["dem"] for r in runs if r["scene"] == "tube"}
    assert len(tube) == 1, "the tube knobs share one DEM run"
    # a thermal knob never re-runs the DEM; each DEM knob setting has a DEM run of its own
    for name in ("youngs_modulus", "dem_timestep"):
        assert len({r["keys"]["dem"] for r in runs if r["knob"] == name}) == len(knobs.BY_NAME[name].settings)
    # the slice knobs share one DEM run (the longest record) but the other slice lengths', and their defaults one run
    on_slice = [r for r in runs if r["scene"] == "slice"]
    assert len({r["keys"]["dem"] for r in on_slice}) == 3
    assert len({r["keys"]["thermal"] for r in on_slice if r["default"]}) == 1
    assert {r["label"]: r["record"] for r in on_slice if r["knob"] == "slice_record"} == pytest.approx(
        {"0.02": 0.02 / 0.3, "0.1": 0.1 / 0.3, "0.3": 1.0})


def test_a_study_the_config_cannot_make_is_an_error_of_the_study_only(tmp_path):
    (tmp_path / "odd.yaml").write_text("dem: {dump_interval: 1002}\n")
    cfg = config.load(DEFAULT)
    cfg["accuracy"].update(knobs=["thermal_step"], scene=[str(DEFAULT.parent / "tube.yaml"), str(tmp_path / "odd.yaml")])
    plan = Plan(config.validate(cfg))
    assert plan.targets()  # the rest of the workflow is unaffected: the study is not asked for
    with pytest.raises(ConfigError, match="dem.dump_interval: 1002 is not a multiple of 4"):
        plan.study("accuracy")


def _slice_scene(folder) -> str:
    """The tiny Watkins scene of .test/config/watkins.yaml, 16 particle diameters long (the length the
    slice_length knob varies around), its RDF table path made absolute, written into ``folder``."""
    cfg = yaml.safe_load((TEST_CONFIG.parent / "watkins.yaml").read_text())
    cfg["thermal"]["rdf_table"] = str((TEST_CONFIG.parent.parent / cfg["thermal"]["rdf_table"]).resolve())
    cfg["geometry"]["tube"].update(length=0.016, heated=[0.0, 0.016])
    cfg["dem"]["fill_height"] = 0.014
    (folder / "watkins.yaml").write_text(yaml.safe_dump(cfg))
    return str(folder / "watkins.yaml")


def test_dry_run_plans_one_dem_and_a_thermal_run_per_distinct_setting(tmp_path):
    slices = ["slice_thermal_step", "slice_record", "slice_length"]
    write_config(tmp_path / "tiny.yaml", config.merge(copy.deepcopy(TINY_STUDY), {
        "accuracy": {"knobs": TINY_STUDY["accuracy"]["knobs"] + slices, "scene": str(tmp_path / "tiny.yaml")},
        "watkins": {"scene": _slice_scene(tmp_path)}}))
    counts = job_counts(snakemake(tmp_path, "-n", "accuracy"))
    # thermal_step 16, 8, 4, 2, 1 and radiation_cutoff 3, 5, 7 (10 is the shared reference); the
    # thermal steps share their screening (it screens the first frame, whatever the stride), each
    # radiation cutoff has its own (the cutoff changes radiation's share); the HTC tables are
    # planned once the screening (a checkpoint) has decided. The slice (every mode on: no
    # screening, its HTC tables planned now): one DEM run of the longest record shared by strides
    # 4, 2, 1 and records 0.02, 0.1, 0.3 s (stride 2 = record 0.02 s = 16 diameters: the default),
    # and the slice lengths 9 and 24 diameters with a geometry and DEM run each.
    assert counts == {"accuracy": 1, "dem": 1 + 3, "geometry": 1 + 3, "htc_table": 2, "screening": 4,
                      "thermal": 8 + 7}, counts


@end_to_end
def test_tiny_study_end_to_end(tmp_path):
    write_config(tmp_path / "tiny.yaml", config.merge(copy.deepcopy(TINY_STUDY), {"accuracy": {"scene": str(tmp_path / "tiny.yaml")}}))
    result = snakemake(tmp_path, "accuracy")
    assert result.returncode == 0, result.stderr[-4000:]
    out = tmp_path / "results" / "tiny" / "studies" / "accuracy"
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
    """Row k of thermal.h5 holds the state at the start of its own frame: runs at strides 1 and 4
    are compared at their last common time itself (not at each run's previous row, 3 frames apart),
    their times equal to rounding (a slice's are its step times the frame count)."""
    from dpht.accuracy.outputs import common_rows, local_rms

    paths = {}
    for stride in (1, 4):
        frames = np.arange(0, 10, stride)  # the stride-4 run ends at frame 8, the stride-1 run at 9
        paths[stride] = tmp_path / f"stride{stride}.h5"
        with h5py.File(paths[stride], "w") as f:
            f["time"] = (0.0025 * stride) * np.arange(frames.size)
            f["temperature"] = np.repeat(300.0 + frames[:, None], 3, axis=1).astype(np.float32)  # T = 300 K + frame
    assert common_rows(paths[1], paths[4]) == (8, 2)
    assert common_rows(paths[4], paths[1]) == (2, 8)
    assert local_rms(paths[4], paths[1], inlet_temperature=300.0) == 0.0  # the same state at frame 8


# --- the Watkins slice's outputs on synthetic runs whose answers are known ---------------------------

SLICE_VELOCITY, SLICE_PATH, SLICE_STEP = 0.5, 0.66, 0.01  # m/s, m, s: 1.32 s of travel
INLET = 303.15  # K


def _slice_run(folder, name, *, heat, rate, stride=1, particles=6):
    """A synthetic slice run (thermal.h5 as the thermal stage writes it): wall heat ``heat`` (W per
    PW mode) at every frame, every particle heating at ``rate`` K/s from its own offset about the
    inlet temperature; ``stride`` times the step of 0.01 s."""
    from dpht.thermal.modes import PW_MODES
    from dpht.thermal.output import FORMAT

    step = SLICE_STEP * stride
    time = step * np.arange(round(SLICE_PATH / SLICE_VELOCITY / step) + 1)
    offsets = np.linspace(-1.0, 1.0, particles)  # K, zero mean
    spec = {"particles": {"density": 3800.0, "diameter": 1.0e-3},
            "thermal": {"inlet_temperature": INLET, "walls": {"heated_wall": {"temperature": "1000.0"},
                                                              "adiabatic_wall": "adiabatic", "orifice": "adiabatic"},
                        "slice": {"inlet_height": 0.66, "distance": SLICE_PATH, "velocity": SLICE_VELOCITY, "frames": "mirror"}}}  # fmt: skip
    path = folder / f"{name}.h5"
    with h5py.File(path, "w") as f:
        f.attrs.update(format=FORMAT, modes=json.dumps(list(PW_MODES)), wall_modes=list(PW_MODES), spec=json.dumps(spec))
        f["ids"] = np.arange(particles)
        f["time"] = time
        f["temperature"] = (INLET + rate * time[:, None] + offsets).astype(np.float32)
        f["wall_heat"] = np.tile(np.asarray(heat, float), (time.size, 1))
        f["element_heat"] = np.zeros((time.size, 1, len(PW_MODES)), np.float32)
        for group in ("particles", "wall", "recycled"):
            f[f"energy/{group}"] = np.zeros(time.size)
    return path


@pytest.fixture
def slice_runs(tmp_path):
    """Walls of a tube heated over 0.036 m, a reference slice run and one at twice its step with
    10% faster heating and 4 points of the wall heat moved from PW contact and radiation to PFW."""
    from dpht.thermal.modes import PW_MODES
    from test_figures import HEATED, TIME, tube_walls, write_positions, write_walls

    assert PW_MODES == ("pw_contact", "pfw", "pw_radiation")
    walls = write_walls(tmp_path / "walls.h5", tube_walls())
    # The slice's DEM box spans the heated length (its length per metre of tube).
    positions = write_positions(tmp_path / "positions.h5", np.zeros((len(TIME), 6, 3)))
    with h5py.File(positions, "r+") as f:
        f.attrs["box_lo"], f.attrs["box_hi"] = [-0.005, -0.005, HEATED[0]], [0.005, 0.005, HEATED[1]]
    reference = _slice_run(tmp_path, "reference", heat=(30.0, 60.0, 10.0), rate=400.0)
    run = _slice_run(tmp_path, "run", heat=(27.0, 64.0, 9.0), rate=440.0, stride=2)
    return walls, positions, reference, run, HEATED[1] - HEATED[0]


def test_slice_outputs_and_errors_of_known_runs(slice_runs):
    from dpht.accuracy.outputs import local_rms, slice_errors, slice_headline

    walls, positions, reference, run, heated_length = slice_runs
    ref, out = slice_headline(positions, reference, walls), slice_headline(positions, run, walls)
    # rise at 0.645 m = 1.29 s of travel; the tube's wall heat = the slice's energy per metre of slice times v
    assert ref["rise_K"] == pytest.approx(400.0 * 0.645 / SLICE_VELOCITY, rel=1e-5)
    assert ref["wall_heat_W"] == pytest.approx(100.0 * 1.32 * SLICE_VELOCITY / heated_length, rel=1e-9)
    assert ref["wall_heat_J"] == pytest.approx(100.0 * 1.32, rel=1e-9)
    assert ref["split_overall_percent"] == pytest.approx({"pw_contact": 30.0, "pfw": 60.0, "pw_radiation": 10.0})
    assert out["split_at_measurement_percent"] == pytest.approx({"pw_contact": 27.0, "pfw": 64.0, "pw_radiation": 9.0})
    local = local_rms(run, reference, INLET)  # at 1.32 s both: 52.8 K apart, the reference 528 K +- 1 K above the inlet
    offsets = np.linspace(-1.0, 1.0, 6)
    assert local == pytest.approx(0.1 * 528.0 / math.sqrt(528.0**2 + np.mean(offsets**2)), rel=1e-5)
    e = slice_errors(out, ref, local)
    assert e["rise"] == pytest.approx(0.1, rel=1e-5)
    assert e["wall_heat"] == pytest.approx(0.0, abs=1e-12)
    assert e["wall_heat_by_mode"] == pytest.approx(0.04) and e["wall_heat_pw_contact"] == pytest.approx(-0.03)
    assert e["split_overall"] == pytest.approx(0.04) and e["split_at_measurement"] == pytest.approx(0.04)  # 4 points
    assert all(v == pytest.approx(0.0, abs=1e-12) for v in slice_errors(ref, ref, 0.0).values())


def test_slice_knobs_in_the_study_costs_and_local_temperatures(slice_runs, tmp_path):
    """evaluate: a stride and a slice length against their references; the stride shares the DEM
    run (local temperatures compared), the slice length does not; costs by the study's rules."""
    from dpht.accuracy import study

    walls, positions, reference, run, _ = slice_runs
    (tmp_path / "thermal.json").write_text(json.dumps({"seconds": 10.0}))
    (tmp_path / "dem.json").write_text(json.dumps({"wall_time_s": {"settle": 5.0, "flow": 30.0}}))
    runs, inputs = [], {}
    for i, (knob, label, reference_, dem, record, thermal) in enumerate([
            ("slice_thermal_step", "2", False, "D16", 1 / 15, run), ("slice_thermal_step", "1", True, "D16", 1 / 15, reference),
            ("slice_length", "9", False, "D9", 1.0, run), ("slice_length", "24", True, "D24", 1.0, reference)]):  # fmt: skip
        runs.append({"knob": knob, "label": label, "scene": "slice", "default": False, "reference": reference_,
                     "record": record, "keys": {"dem": dem}})  # fmt: skip
        inputs.update({f"{i}_thermal": thermal, f"{i}_walls": walls, f"{i}_positions": positions,
                       f"{i}_thermal_summary": tmp_path / "thermal.json",
                       f"{i}_dem_summary": tmp_path / "dem.json"})  # fmt: skip
    rows = study.evaluate({"runs": runs}, inputs, progress=lambda _: None)
    assert [r["cost_s"] for r in rows] == pytest.approx([10.0, 10.0, 45.0, 45.0])  # thermal; settle + flow + thermal
    assert rows[0]["errors"]["rise"] == pytest.approx(0.1, rel=1e-5) and rows[1]["errors"]["rise"] == 0.0
    assert rows[0]["errors"]["local_rms"] > 0.09 and math.isnan(rows[2]["errors"]["local_rms"])
    assert study.judged(rows[0]) == pytest.approx(0.1, rel=1e-5)  # the rise, the largest headline error
    assert study.recommend(rows, 0.005)[0]["recommended"] == "1"
