"""A chain planned as stage runs (dpht.plan.Plan.register_chain, dpht.chain.scenes), the record of
what leaves a segment (dpht.thermal.outlet's journal, dpht.chain.outlet) and the hand-over built
from it (dpht.chain.handover), without Snakemake or LIGGGHTS."""

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht import config
from dpht.chain import handover, outlet
from dpht.chain.segments import RESOLVED, SLICE
from dpht.closures import heat_capacity
from dpht.plan import Plan
from dpht.thermal import outlet as journal
from dpht.util.expr import parse

ROOT = Path(__file__).resolve().parents[2]
TINY, CHAIN = ROOT / ".test" / "config" / "config.yaml", ROOT / ".test" / "config" / "chain.yaml"
PLATE = {"type": "flat_plate", "thickness": 1.0e-3, "opening": 0.6, "orientation": 0.0}


def plan_of(variants):
    cfg = config.merge(yaml.safe_load(TINY.read_text()), yaml.safe_load(CHAIN.read_text()))
    cfg["thermal"].pop("rdf_table")
    cfg["variants"] = variants
    return Plan(config.validate(cfg))


def test_identical_inserts_share_one_resolved_dem_run_and_every_slice_one():
    plan = plan_of({"plates": {"geometry": {"mixers": [{**PLATE, "height": 0.03}, {**PLATE, "height": 0.015}]}},
                    "plate": {"geometry": {"mixers": [{**PLATE, "height": 0.03}]}}})  # fmt: skip
    plates, plate = plan.chains["plates"], plan.chains["plate"]
    kinds = [s["kind"] for s in plates.spec["segments"]]
    assert kinds == [SLICE, RESOLVED, SLICE, RESOLVED, SLICE]
    assert len(plates.dem) == 2  # the slices' and one for both plates, wherever they sit
    dem = [s["dem"] for s in plates.spec["segments"]]
    assert dem[1] == dem[3] and dem[0] == dem[2] == dem[4] and set(plate.dem) == set(plates.dem)
    assert len(set(plates.segments)) == 5  # a thermal run per segment: its position, its field
    # the upper plate's segment and the slice above it are the same runs in both chains (same inputs)
    assert plates.segments[:2] == plate.segments[:2] and plates.segments[2] != plate.segments[2]
    # in flow order, each started from the hand-over of the one above; resolved also fed by it
    for k, key in enumerate(plates.segments):
        run = plan.runs[key]
        assert run.stage == "segment" and run.upstream["segment"] == (plates.segments[k - 1] if k else None)
        inputs = plan.thermal_inputs(key)
        above = f"results/segment/{plates.segments[k - 1]}/handover.h5" if k else None
        assert inputs.get("initial_field") == above
        assert inputs.get("inlet_field") == (above if kinds[k] == RESOLVED else None)
    assert plan.targets() == ["results/design/plates/chain.json", "results/design/plate/chain.json"]
    assert plan.chain_inputs("plate") == {f"{name}_{k}": f"results/segment/{key}/{file}" for k, key in enumerate(plate.segments)
                                          for name, file in (("summary", "summary.json"), ("handover", "handover.h5"))}


def test_a_resolved_segment_sees_the_wall_where_it_sits():
    """Its DEM covers z from 0 up; its thermal run's wall temperature is the scene's at the scene's z."""
    plan = plan_of({"plate": {"geometry": {"mixers": [{**PLATE, "height": 0.03}]}}})
    chain = plan.chains["plate"]
    segment = chain.spec["segments"][1]
    run = plan.runs[segment["key"]]
    plane = run.spec["outlet"]["plane"]  # the segment's bottom in its DEM
    here = parse(run.spec["thermal"]["walls"]["heated_wall"]["temperature"], ("x", "y", "z"), "here")
    scene = parse("600 + 10000*z", ("x", "y", "z"), "scene")
    z = np.linspace(plane, plane + segment["top"] - segment["bottom"], 7)
    assert np.allclose(here(x=0.0, y=0.0, z=z), scene(x=0.0, y=0.0, z=z - plane + segment["bottom"]), rtol=1e-14)
    dem = plan.runs[run.upstream["dem"]].spec["geometry"]
    assert dem["mixers"][0]["height"] == pytest.approx(0.03 - segment["bottom"] + plane, abs=1e-9)
    assert dem["tube"]["heated"] == [plane, pytest.approx(plane + 0.009, abs=1e-9)]
    # the slices: the scene's expression at the height reached, from the top of their stretch
    first = plan.runs[chain.segments[0]].spec["thermal"]
    assert first["walls"]["heated_wall"]["temperature"] == "600 + 10000*z" and first["slice"]["inlet_height"] == 0.05
    assert first["initial_temperature"] == first["inlet_temperature"] == 300.0
    assert plan.runs[chain.segments[2]].spec["thermal"]["initial_temperature"] == pytest.approx(1100.0, abs=1.0)  # the bound


def test_the_journal_keeps_the_crossings_before_a_checkpoint(tmp_path):
    path = tmp_path / "work.outlet"
    log = journal.Journal(path, plane=0.01, length=0.05, shells=0, start=0)
    h = np.array([1.0, 2.0, 3.0])
    previous = np.array([[0.0, 0.0, 0.012], [1e-3, 2e-3, 0.02], [0.0, 0.0, 0.005]])
    now = np.array([[2e-3, 0.0, 0.008], [1e-3, 2e-3, 0.011], [0.0, 0.0, 0.049]])  # down, above, re-entered
    log.observe(4, previous, now, h, None)
    log.observe(5, now, np.array([[2e-3, 0.0, 0.012], [1e-3, 2e-3, 0.009], [0.0, 0.0, 0.04]]), h + 10, None)  # up, down
    rows = log.rows()
    log.close()
    record = journal.crossings(rows, 0.01, np.arange(8) * 0.1, lambda v: 2 * np.asarray(v), 5e-4, np.zeros(0))
    assert record.particle.tolist() == [0, 1] and record.upward == 1 and record.frame.tolist() == [4, 5]
    assert record.xy[0] == pytest.approx([1e-3, 0.0])  # where it crossed, linear between the frames
    assert record.temperature.tolist() == [2.0, 24.0] and record.time.tolist() == [0.4, 0.5]
    with open(path, "ab") as f:
        f.write(b"\0" * 12)  # a row cut short by a kill
    resumed = journal.Journal(path, plane=0.01, length=0.05, shells=0, start=5)  # the checkpoint after frame 4
    assert resumed.rows()[:, 0].tolist() == [4.0]
    resumed.close(remove=True)
    assert not path.exists()


TABLE = heat_capacity.build(heat_capacity.specific_heat("271.5 * T_C**0.1719"), 280.0, 1200.0)
SPEC = handover.Spec(rings=4, sectors=1, radius=4e-3, window=(0.5, 1.0), mass_flow=4e-3, mass=1.86e-6, bin=1e-3)


def record_of(kind, n, times, temperature):
    rng = np.random.default_rng(3)
    r, theta = 3.5e-3 * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    return outlet.Record(kind, np.zeros(n, dtype=np.int64), times, np.arange(n), np.column_stack([r * np.cos(theta), r * np.sin(theta)]),
                         temperature, np.zeros((n, 0)), np.zeros(0), 5e-4)  # fmt: skip


def test_a_slice_hands_over_its_bed_and_its_wall_heat_per_kilogram_of_flow():
    n = 400
    record = record_of(outlet.BED, n, np.full(n, 1.0), np.linspace(500.0, 900.0, n))
    heat = np.zeros((11, 3))
    heat[:-1, 0] = 2.0  # 2 W for 1 s: 2 J from the wall
    rows = handover.Rows(np.linspace(0.0, 1.0, 11), heat, np.linspace(0.0, 2.0, 11))
    place = handover.Place(0.02, 0.029, velocity=0.01)  # 10 mm travelled: the last 1 mm past its bottom
    result = handover.hand_over(record, rows, SPEC, TABLE, place)
    assert result.wall_heat == pytest.approx(4e-3 * 2.0 / (n * 1.86e-6))
    # its profile: 1 mm bins, top first, the heat where it was taken, what went past the bottom in the lowest
    assert result.edges[0] == 0.029 and result.edges[-1] == 0.02 and result.edges.size == 10
    assert math.fsum(result.profile) == pytest.approx(result.wall_heat, rel=1e-12)
    assert result.profile[:-1] == pytest.approx(np.full(8, result.wall_heat / 10))
    assert result.profile[-1] == pytest.approx(result.wall_heat / 5)
    h = TABLE.enthalpy(record.temperature)
    assert TABLE.enthalpy(result.field.cup_temperature) == pytest.approx(h.mean(), rel=1e-13)
    assert result.steady is None and result.summary()["samples"] == n


def test_a_resolved_segment_hands_over_the_crossings_of_its_window_and_says_whether_it_is_steady(tmp_path):
    n = 600
    times = np.linspace(0.0, 1.0, n)
    record = record_of(outlet.CROSSINGS, n, times, np.where(times < 0.5, 400.0, 800.0))  # cold until steady
    path = tmp_path / "thermal.h5"
    with h5py.File(path, "w") as f:  # 3 wall elements, 1 W each in each of 3 modes
        f["element_heat"] = np.ones((101, 3, 3), dtype=np.float32)
    rows = handover.Rows(np.linspace(0.0, 1.0, 101), np.full((101, 3), 3.0), np.zeros(101), str(path))
    place = handover.Place(0.024, 0.033, plane=0.005)
    centroids = np.array([0.004, 0.0095, 0.0139])  # in the run-out, in the stretch's middle and its top bin
    result = handover.hand_over(record, rows, SPEC, TABLE, place, centroids)
    assert result.field.cup_temperature == pytest.approx(800.0, abs=1e-9) and result.samples == np.count_nonzero(times >= 0.5)
    assert result.wall_heat == pytest.approx(9.0) and result.steady
    assert result.profile.tolist() == [3.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 3.0]  # top first; the run-out's in the lowest
    drifting = handover.Rows(rows.time, np.linspace(1.0, 2.0, 101)[:, None] * np.ones(3), rows.wall_energy, str(path))
    assert handover.hand_over(record, drifting, SPEC, TABLE, place, centroids).steady is False
    with pytest.raises(Exception, match="no particle left the segment.*jammed"):
        handover.hand_over(record_of(outlet.CROSSINGS, n, times - 2.0, record.temperature), rows, SPEC, TABLE, place, centroids)


def test_the_chain_summary_adds_up_its_segments(tmp_path):
    from dpht.chain.field import CrossSection, Field
    from dpht.chain.summary import summarize

    def field(T):
        return Field(CrossSection(4, 1, 4e-3), np.full((4, 1), T), np.full(4, 0.25), np.full(4, 9), T, np.zeros(0))

    spec = {"segments": [{"kind": k, "bottom": b, "top": t, "key": f"k{i}", "dem": d, "inserts": [], "outlet": False}
                         for i, (k, b, t, d) in enumerate([(SLICE, 0.03, 0.05, "s"), (RESOLVED, 0.02, 0.03, "r"),
                                                           (SLICE, 0.0, 0.02, "s")])],
            "mass_flow": 4e-3, "inlet_temperature": 300.0, "specific_heat": "271.5 * T_C**0.1719", "shapes": 1}  # fmt: skip
    books = {"initial": {"correction_J_kg": 1.0, "correction_K": 1e-3, "residual_J_kg": 0.0, "relative_residual": 0.0,
                         "filled_cells": 0}}  # fmt: skip
    outs = [{"wall_heat_W": q, "samples": 10, "steady": None, "wall_heat_halves_W": None, "cup_temperature_halves_K": None,
             "upward_crossings": 0, "filled_cells": 0, "profile_edges_m": [t, b], "profile_W": [q]}
            for q, (t, b) in zip((1.0, 2.0, 3.0), ((0.05, 0.03), (0.03, 0.02), (0.02, 0.0)))]  # fmt: skip
    summaries = [{"outlet": o, **({"hand_over": books} if k else {})} for k, o in enumerate(outs)]
    result = summarize(spec, summaries, [field(T) for T in (400.0, 500.0, 650.0)])
    assert result["wall_heat_W"] == 6.0 and result["outlet_cup_temperature_K"] == 650.0 and result["dem_runs"] == 2
    assert [j["cup_temperature_K"] for j in result["joints"]] == [400.0, 500.0] and result["joints"][0]["delta_J_kg"] == 1.0
    h = TABLE.enthalpy
    assert result["enthalpy_rise_W"] == pytest.approx(4e-3 * float(h(650.0) - h(300.0)), rel=1e-9)
    assert math.fsum(s["enthalpy_rise_W"] for s in result["segments"]) == pytest.approx(result["enthalpy_rise_W"], rel=1e-12)
    assert [(p["z_top_m"], p["wall_heat_W"]) for p in result["profile"]] == [(0.05, 1.0), (0.03, 2.0), (0.02, 3.0)]
