"""The mixer study (DPHT paper, Section 6): its plan (the scene file's variants, all at one mass flow),
and its figures and table drawn from synthetic stage outputs with known answers (the wall heat of one
variant twice the other's, particles leaving at known temperatures)."""

import copy
import csv
import json
import math

import h5py
import numpy as np
import pytest
from matplotlib.image import imread

from dpht import config, stages
from dpht.errors import ConfigError
from dpht.figures import mixers, outlet
from dpht.plan import Plan
from dpht.geometry.walls import Walls
from test_figures import (LENGTH, PARTICLE_RADIUS, TIME, TUBE_RADIUS, known_element_heat, tube_walls, write_positions,
                          write_thermal, write_walls)
from test_workflow import DEFAULT

CP = 900.0  # J/(kg K), constant: enthalpy differences are CP x temperature differences
INLET = 1073.15  # K
LEAVING = {"base": 900.0, "double": 800.0}  # K, the temperature particles leave at
MASS_FLOW = 1.0e-3  # kg/s


# --- the plan ----------------------------------------------------------------------------------


def test_the_default_config_runs_the_mixer_study_at_one_mass_flow():
    plan = Plan(config.load(DEFAULT))
    study = plan.studies["mixers"]
    configs = study.scenes
    assert list(configs) == ["base", "flat_plate", "radial"]
    tubes = {json.dumps(c["geometry"]["tube"], sort_keys=True) for c in configs.values()}
    drives = {json.dumps(c["dem"]["drive"], sort_keys=True) for c in configs.values()}
    assert len(tubes) == 1 and len(drives) == 1  # one tube, one mass flow: only the inserts differ
    assert [len(c["geometry"].get("mixers") or []) for c in configs.values()] == [0, 1, 1]
    keys = list(plan.register_scenes(dict(configs)).values())
    assert len({k["dem"] for k in keys}) == 3 and len({k["rdf"] for k in keys}) == 1  # the shipped RDF table
    spec = json.loads(study.spec_json())
    assert spec["close_up"] == "radial" and spec["paper"] == {"flat_plate": 0.0, "radial": 0.08}
    assert spec["heated_zones"] == ["heated_wall"] and set(study.inputs) == {
        f"{f}_{v}" for f in ("walls", "positions", "thermal", "dem", "thermal_summary") for v in configs}
    assert plan.study_targets("mixers")[0] == "results/default/studies/mixers/fig14.png"


def test_paper_values_must_name_variants_of_the_scene():
    cfg = config.load(DEFAULT)
    cfg["mixer_study"] = {**cfg["mixer_study"], "paper": {"radial_mixer": 0.08}}
    with pytest.raises(ConfigError, match=r"mixer_study.paper: \['radial_mixer'\] are not variants"):
        Plan(config.validate(cfg))
    cfg["studies"] = []  # not asked for: its section is read when it is
    Plan(config.validate(cfg))


# --- figures and table from synthetic outputs ----------------------------------------------------


def with_mixer(walls: Walls) -> Walls:
    """``walls`` and a horizontal ring of triangles half-way up as a zone "mixer"."""
    theta = np.linspace(0.0, 2 * np.pi, 17)
    z, r0, r1 = 0.5 * LENGTH, 0.3 * TUBE_RADIUS, 0.9 * TUBE_RADIUS
    ring = []
    for a, b in zip(theta[:-1], theta[1:]):
        p = [np.array([r * math.cos(t), r * math.sin(t), z]) for r, t in ((r0, a), (r1, a), (r1, b), (r0, b))]
        ring += [(p[0], p[1], p[2]), (p[0], p[2], p[3])]
    vertices = np.concatenate([walls.vertices, np.array(ring)])
    zone = np.concatenate([walls.zone, np.full(len(ring), len(walls.zone_names))])
    return Walls.from_vertices(vertices, zone, (*walls.zone_names, "mixer"))


def falling_positions(n=600, speed=0.02, seed=3):
    """(F, N, 3) centres falling at ``speed`` m/s through the periodic tube, and their image flags."""
    rng = np.random.default_rng(seed)
    r = (TUBE_RADIUS - PARTICLE_RADIUS) * np.sqrt(rng.random(n))
    phi = 2 * np.pi * rng.random(n)
    z = LENGTH * rng.random(n)[None, :] - speed * TIME[:, None]
    image = np.floor(z / LENGTH).astype(np.int32)
    x = np.stack([np.broadcast_to(r * np.cos(phi), z.shape), np.broadcast_to(r * np.sin(phi), z.shape),
                  z - image * LENGTH], axis=-1)
    return x, image


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("mixer_study")
    x, image = falling_positions()
    ids = np.arange(1, x.shape[1] + 1, dtype=np.int64)
    inputs = {}
    for name, factor, walls in (("base", 1.0, tube_walls()), ("double", 2.0, with_mixer(tube_walls()))):
        folder = root / name
        folder.mkdir()
        inputs[f"walls_{name}"] = write_walls(folder / "walls.h5", walls)
        positions = write_positions(folder / "positions.h5", x)
        with h5py.File(positions, "r+") as f:  # what a gathered DEM run has beyond what the figures read
            f["image"][...] = image[..., None] * np.array([0, 0, 1], np.int32)
            f["step"] = np.arange(len(TIME), dtype=np.int64)
            f["lost"] = np.zeros(x.shape[:2], bool)
            f.attrs.update(timestep=TIME[1], summary="{}")
        inputs[f"positions_{name}"] = positions
        # Every particle at the inlet temperature, except those about to leave: at the temperature they leave at.
        temperature = np.full(x.shape[:2], INLET)
        leaving = np.zeros(x.shape[:2], bool)
        leaving[:-1] = image[1:] < image[:-1]
        temperature[leaving] = LEAVING[name]
        heat, _ = known_element_heat(walls)
        thermal = write_thermal(folder / "thermal.h5", ids=ids, temperature=temperature, element_heat=factor * heat)
        with h5py.File(thermal, "r+") as f:
            f["dem_frame"] = np.arange(len(TIME))
        inputs[f"thermal_{name}"] = thermal
        inputs[f"dem_{name}"] = folder / "dem.json"
        inputs[f"dem_{name}"].write_text(json.dumps({"mass_flow_second_half_kg_s": MASS_FLOW * factor, "particles": 600,
                                                     "drive": {"acceleration_over_gravity": 0.5 * factor},
                                                     "wall_time_s": {"settle": 1.0, "flow": 2.0}}))  # fmt: skip
        inputs[f"thermal_summary_{name}"] = folder / "thermal.json"
        inputs[f"thermal_summary_{name}"].write_text(json.dumps({"seconds": 3.0}))
    out = root / "mixers"
    outputs = {"fig14": out / "fig14.png", "fig15": out / "fig15.png", "fig16": out / "fig16.png",
               "table": out / "mixers.csv", "markdown": out / "mixers.md", "summary": out / "mixers.json"}
    spec = {"variants": ["base", "double"], "paper": {"double": 0.08}, "window": [0.5, 1.0],
            "heated_zones": ["heated_wall"], "specific_heat": CP, "inlet_temperature": INLET, "close_up": "double",
            "spans": {"base": [], "double": [[0.4 * LENGTH, 0.6 * LENGTH]]}}
    io = json.dumps({"input": {k: str(v) for k, v in inputs.items()}, "output": {k: str(v) for k, v in outputs.items()}})
    assert stages.run("mixers", json.dumps(spec), io, None) == 0
    return outputs, inputs, x, image


def test_figures_are_drawn(study):
    outputs = study[0]
    for name in ("fig14", "fig15", "fig16"):
        image = imread(outputs[name])[..., :3]
        assert image.shape[0] >= 400 and image.shape[1] >= 600 and image.std() > 0.05, name
    # Fig. 14: both designs and the close-up of the mixer zone, each panel kept.
    assert {p.name for p in outputs["fig14"].parent.glob("fig14.*.png")} == {
        "fig14.base.png", "fig14.double.png", "fig14.double.close_up.png"}


def test_table_has_every_column_and_the_known_numbers(study):
    outputs, _, x, image = study
    with open(outputs["table"]) as stream:
        rows = list(csv.DictReader(stream))
    assert tuple(rows[0]) == mixers.COLUMNS and [r["variant"] for r in rows] == ["base", "double"]
    base, double = ({k: float(v) if k != "variant" and v != "" else v for k, v in r.items()} for r in rows)
    assert all(math.isfinite(v) for r in (base, double) for v in r.values() if isinstance(v, float))
    assert double["wall_heat_relative"] == pytest.approx(1.0, rel=1e-6)  # twice the heat
    assert double["mass_flow_relative"] == pytest.approx(1.0, rel=1e-12)
    assert base["wall_heat_relative"] == 0.0 and double["paper_wall_heat_relative"] == 0.08
    # The wall above, alongside and below the mixer: the whole heated wall, split by the mixer's span.
    for row in (base, double):
        parts = row["wall_heat_above_W"] + row["wall_heat_alongside_W"] + row["wall_heat_below_W"]
        assert parts == pytest.approx(row["wall_heat_W"], rel=1e-5)
        assert min(row["wall_heat_above_W"], row["wall_heat_alongside_W"], row["wall_heat_below_W"]) != 0.0
        assert row["wall_heat_drift"] == pytest.approx(0.0, abs=1e-9)  # the same rate in every window frame
    assert double["wall_heat_below_relative"] == pytest.approx(1.0, rel=1e-5)
    assert double["wall_heat_above_relative"] == pytest.approx(1.0, rel=1e-5)
    for row in (base, double):
        assert row["outlet_temperature_K"] == pytest.approx(LEAVING[row["variant"]], abs=0.01)  # a uniform cup
        expected = row["mass_flow_kg_s"] * CP * (row["outlet_temperature_K"] - INLET) / row["wall_heat_W"]
        assert row["energy_balance"] == pytest.approx(expected, rel=1e-3)
    # Particles leave once per passage: as many as the image flags count in the window.
    frames = np.flatnonzero(TIME >= 0.5 - 1e-12)
    assert base["outlet_particles"] == np.count_nonzero(np.diff(image[frames], axis=0) < 0)
    assert double["outlet_change_relative"] == pytest.approx((800.0 - INLET) / (900.0 - INLET) - 1.0, abs=1e-4)
    markdown = outputs["markdown"].read_text()
    assert "| double |" in markdown and "+100.0%" in markdown and "+8.0%" in markdown
    assert json.loads(outputs["summary"].read_text())["variants"] == ["base", "double"]


def test_mixing_cup_weighs_enthalpy_not_temperature():
    # c_p rising with T: the cup lies above the mean temperature of a 500 K / 1000 K pair.
    cup = outlet.mixing_cup(np.array([500.0, 1000.0]), "271.5 * T_C**0.1719")
    assert 750.0 < cup < 800.0
    assert outlet.enthalpy_difference(1000.0, 500.0, 900.0) == pytest.approx(900.0 * 500.0)


def test_study_refuses_a_single_variant(study, tmp_path):
    _, inputs, _, _ = study
    spec = {"variants": ["base"], "window": [0.5, 1.0], "heated_zones": ["heated_wall"], "specific_heat": CP,
            "inlet_temperature": INLET}
    with pytest.raises(Exception, match="at least two variants"):
        mixers.study(copy.deepcopy(spec), inputs, {})


def test_drift_is_the_change_across_the_window_over_its_mean():
    time = np.linspace(0.0, 1.0, 11)
    k = np.arange(5, 10)  # the window (0.5, 1)
    rate = 10.0 + 20.0 * (time[k] + 0.05)  # a rate rising linearly from 20 to 30 across the window
    assert mixers._drift(time, rate, k, np.diff(time)[k]) == pytest.approx(10.0 / 25.0, rel=1e-12)
    assert math.isnan(mixers._drift(time, rate[:1], k[:1], np.diff(time)[k[:1]]))
