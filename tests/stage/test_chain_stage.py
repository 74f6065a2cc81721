"""The thermal stage handed the fields of a segment upstream (dpht.thermal.inflow), on the tiny
scene of test_thermal_stage (a bed sinking through a heated tube, recycled at the top): a uniform
field is today's run bit for bit; a non-uniform one changes it and conserves energy. And what it
records of what leaves it (dpht.chain.outlet)."""

import json

import h5py
import numpy as np
import pytest

from dpht.chain import field as hf, outlet
from dpht.chain.files import save_field
from dpht.closures import heat_capacity
from dpht.dem.dumps import PositionsFile
from dpht.errors import DPHTError
from dpht.thermal import integrate, stage
from test_thermal_stage import R as R_P, T_COLD, T_WALL, failing_after, read_all, result, scene  # noqa: F401 (fixtures)


def tube_radius(folder) -> float:
    with PositionsFile(folder / "positions.h5") as dem:
        return float(dem.attrs["box_hi"][0])


def stage_table(s) -> heat_capacity.EnthalpyTable:
    """The enthalpy table the stage builds for this scene (its temperatures: initial, inlet, wall)."""
    return heat_capacity.build(heat_capacity.specific_heat(s["particles"]["specific_heat"]), T_COLD, T_WALL)


def field_file(scene, name, temperature, rings=6, sectors=3):
    """A hand-over field of ``temperature(xy)`` (K) sampled at 4000 random points of the tube
    where particle centres can be (a radius from the wall)."""
    folder, s, _ = scene
    R = tube_radius(folder)
    rng = np.random.default_rng(5)
    r, theta = (R - R_P) * np.sqrt(rng.uniform(0, 1, 4000)), rng.uniform(0, 2 * np.pi, 4000)
    xy = np.column_stack([r * np.cos(theta), r * np.sin(theta)])
    field = hf.build(hf.Stream(xy, temperature(xy), np.full(4000, 1e-4)), hf.CrossSection(rings, sectors, R), stage_table(s))
    save_field(folder / f"{name}.h5", field)
    return folder / f"{name}.h5", field


def run_with(scene, name, **fields):
    folder, s, tables = scene
    out = folder / f"{name}.h5"
    return out, stage.run(json.loads(json.dumps(s)), folder / "positions.h5", folder / "walls.h5", tables, out,
                          rdf_table=folder / "rdf.h5", **fields)  # fmt: skip


def test_uniform_fields_are_the_single_temperature_bit_for_bit(scene, result):
    """The scene starts and recycles at T_COLD; uniform fields at T_COLD as initial and inlet give
    every dataset of that run bit for bit, and a zero shift."""
    path, _ = field_file(scene, "uniform", lambda xy: np.full(len(xy), T_COLD))
    out, summary = run_with(scene, "uniform_fields", initial_field=path, inlet_field=path)
    (data, _, books), (data0, _, books0) = read_all(out), read_all(result[0])
    assert data.keys() == data0.keys()
    for name, value in data.items():
        assert np.array_equal(value, data0[name], equal_nan=value.dtype.kind == "f"), name
    hand_over = books.pop("hand_over")
    assert books == {k: v for k, v in books0.items()}
    assert hand_over["initial"]["correction_J_kg"] == 0.0 and hand_over["initial"]["residual_J_kg"] == 0.0
    assert hand_over["inlet"]["cup_temperature_K"] == T_COLD


def hot_core(xy, R):
    """A cold wall layer about a hot core (K): 700 K on the axis, T_COLD at the wall."""
    return T_COLD + 400.0 * (1.0 - (np.hypot(xy[:, 0], xy[:, 1]) / R) ** 2)


@pytest.fixture(scope="module")
def profiled(scene):
    R = tube_radius(scene[0])
    path, field = field_file(scene, "profile", lambda xy: hot_core(xy, R))
    out, summary = run_with(scene, "profiled", initial_field=path, inlet_field=path)
    return out, summary, field


def test_a_profile_changes_the_run_and_conserves_energy(scene, result, profiled):
    out, summary, field = profiled
    folder, s, _ = scene
    with h5py.File(out) as f, h5py.File(result[0]) as f0:
        E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
        T, T0 = f["temperature"][...], f0["temperature"][...]
        heat, heat0 = f["energy/wall"][-1], f0["energy/wall"][-1]
    assert np.nanmean(T[0]) > T_COLD + 50.0 and heat < heat0  # a hotter bed takes less heat from the wall
    # The stage's books close every frame, with the hand-over's enthalpy in them.
    dE, dW, dR = np.diff(E), np.diff(W), np.diff(Rc)
    assert np.max(np.abs(dE - dW - dR) / (np.abs(dW) + np.abs(dR))) <= 1e-12
    # The hand-over: the bed starts with the field's mixing-cup enthalpy, to round-off, after a shift.
    p = s["particles"]
    mass = p["density"] * 4 / 3 * np.pi * (p["diameter"] / 2) ** 3
    n = T.shape[1]
    cup = field.cup_enthalpy(stage_table(s))
    assert E[0] == pytest.approx(mass * n * cup, rel=1e-13)
    # The shift is what the first frame's particles, placed in the field's cells, miss of the cup
    # (the field here samples the cross-section uniformly, the bed's centres are layered at the wall).
    with PositionsFile(folder / "positions.h5") as dem:
        placed = dem.frame(0).positions[:, :2]
    books = summary["hand_over"]["initial"]
    shift = cup - np.mean(stage_table(s).enthalpy(field.sample(placed)[:, 0]))
    assert books["correction_J_kg"] == pytest.approx(shift, rel=1e-9) and shift != 0.0
    assert abs(books["residual_J_kg"]) <= 1e-12 * cup


def test_reentering_particles_take_the_field_at_their_position(scene, profiled):
    """A particle re-entering at the top in frame k is written in row k at the inlet field's
    temperature where it re-entered (thermal.h5's rows: the state at their frame's start)."""
    out, summary, field = profiled
    folder, s, _ = scene
    entered = []
    with h5py.File(out) as f, PositionsFile(folder / "positions.h5") as dem:
        T = f["temperature"][...]
        lo, hi = np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"])
        checked = 0
        for k in range(1, dem.n_frames):
            previous, current = dem.frame(k - 1), dem.frame(k)
            crossed = integrate.wrapped(previous.image, current.image, previous.positions, current.positions, lo, hi, 2)
            crossed &= np.all(np.isfinite(current.positions), axis=1)
            expected = field.sample(current.positions[crossed, :2])[:, 0]
            np.testing.assert_array_equal(T[k, crossed], expected.astype(np.float32))
            checked += int(crossed.sum())
            entered.append(expected)
    assert checked > 20 and len(set(np.round(T[1:][np.isfinite(T[1:])], 1))) > 3
    # The books: how far what entered was from the field's mixing cup, on average.
    books, table = summary["hand_over"]["inlet"], stage_table(s)
    deviation = np.mean(table.enthalpy(np.concatenate(entered))) - field.cup_enthalpy(table)
    assert books["entered"] == checked and books["entered_deviation_J_kg"] == pytest.approx(deviation, rel=1e-9)


def test_a_field_outside_the_scene_temperatures_is_refused(scene):
    path, _ = field_file(scene, "too_hot", lambda xy: np.full(len(xy), T_WALL + 100.0))
    with pytest.raises(DPHTError, match="initial hand-over field spans .* outside the scene's temperatures"):
        run_with(scene, "too_hot_run", initial_field=path)


def test_resolved_particles_take_the_field_nodes_or_their_mean(scene):
    """With resolved particles: a field without nodes starts every node at the particle's mean, a
    field with the model's 6 nodes gives them; the books close either way."""
    folder, s, _ = scene
    R = tube_radius(folder)
    plain, _ = field_file(scene, "plain", lambda xy: hot_core(xy, R))
    rng = np.random.default_rng(6)
    r, theta = (R - R_P) * np.sqrt(rng.uniform(0, 1, 3000)), rng.uniform(0, 2 * np.pi, 3000)
    xy = np.column_stack([r * np.cos(theta), r * np.sin(theta)])
    mean = hot_core(xy, R)
    nodes = mean[:, None] + np.linspace(3.0, -3.0, 6)[None, :]  # surface colder than the centre
    weight = np.full(6, 1 / 6)
    table = stage_table(s)
    mean = table.temperature(table.enthalpy(nodes) @ weight)
    stream = hf.Stream(xy, mean, np.full(3000, 1e-4), shells=nodes, shell_weight=weight)
    save_field(folder / "nodes.h5", hf.build(stream, hf.CrossSection(6, 1, R), table))
    for name, path in (("plain", plain), ("nodes", folder / "nodes.h5")):
        s_resolved = json.loads(json.dumps(s))
        s_resolved["thermal"].update(intraparticle=True, shells=6)
        out = folder / f"resolved_{name}.h5"
        stage.run(s_resolved, folder / "positions.h5", folder / "walls.h5", scene[2], out, rdf_table=folder / "rdf.h5",
                  initial_field=path, inlet_field=path)  # fmt: skip
        with h5py.File(out) as f:
            E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
        dE, dW, dR = np.diff(E), np.diff(W), np.diff(Rc)
        assert np.max(np.abs(dE - dW - dR) / (np.abs(dW) + np.abs(dR))) <= 1e-12, name


def test_a_run_with_fields_resumes_bitwise_from_a_checkpoint(scene, profiled, monkeypatch):
    """The initial field is given once, to the first frame: a run that fails after 7 frames resumes
    from its checkpoint after frame 6 and writes the file of the uninterrupted run."""
    folder = scene[0]
    path = folder / "profile.h5"
    real = stage.step
    monkeypatch.setattr(stage, "step", failing_after(7))
    with pytest.raises(RuntimeError, match="injected failure"):
        run_with(scene, "fields_resumed", initial_field=path, inlet_field=path, checkpoints=stage.Checkpoints(frames=3))
    monkeypatch.setattr(stage, "step", real)
    out, _ = run_with(scene, "fields_resumed", initial_field=path, inlet_field=path, checkpoints=stage.Checkpoints(frames=3))
    (data, _, books), (data0, _, books0) = read_all(out), read_all(profiled[0])
    assert books == books0 and data.keys() == data0.keys()
    for name, value in data.items():
        assert np.array_equal(value, data0[name], equal_nan=value.dtype.kind == "f"), name


def test_the_outlet_record_holds_every_crossing_in_float64_and_survives_a_resumed_run(scene, monkeypatch):
    """A run asked for its outlet records each particle crossing the plane downwards, with the
    enthalpy the run held then (thermal.h5's float32 row of that frame, in float64); a run that
    fails after 7 frames resumes from its checkpoint (the crossings before it journalled) and writes
    the same record bit for bit."""
    folder = scene[0]
    with PositionsFile(folder / "positions.h5") as dem:
        lo, hi = float(dem.attrs["box_lo"][2]), float(dem.attrs["box_hi"][2])
    plane = outlet.Outlet(lo + 0.4 * (hi - lo))
    out, _ = run_with(scene, "outlet", outlet=plane)
    record = outlet.read(out)
    assert record.kind == outlet.CROSSINGS and record.plane == plane.plane and record.temperature.dtype == np.float64
    assert record.temperature.size > 20 and np.all(np.diff(record.frame) >= 0)
    with h5py.File(out) as f:
        rows = f["temperature"][...]
    assert np.allclose(record.temperature, rows[record.frame, record.particle], rtol=1e-6, atol=0)
    assert np.any(record.temperature != rows[record.frame, record.particle].astype(np.float64))  # not the float32 rows
    real = stage.step
    monkeypatch.setattr(stage, "step", failing_after(7))
    with pytest.raises(RuntimeError, match="injected failure"):
        run_with(scene, "outlet_resumed", outlet=plane, checkpoints=stage.Checkpoints(frames=3))
    monkeypatch.setattr(stage, "step", real)
    resumed, _ = run_with(scene, "outlet_resumed", outlet=plane, checkpoints=stage.Checkpoints(frames=3))
    again = outlet.read(resumed)
    for name in ("frame", "time", "particle", "xy", "temperature", "shells"):
        assert np.array_equal(getattr(again, name), getattr(record, name)), name
    assert not (folder / "outlet_resumed.work.outlet").exists()  # the journal, once in thermal.h5


def test_a_bed_outlet_is_every_particle_at_the_end_of_the_run(scene):
    """Without a plane the record is the bed at the end of the run: every particle with a position
    in the last frame (the scene loses some), at the run's last temperatures, in float64."""
    folder = scene[0]
    out, _ = run_with(scene, "bed_outlet", outlet=outlet.Outlet())
    record = outlet.read(out)
    with h5py.File(out) as f:
        last = f["temperature"][-1]  # float32, at the start of the last frame, whose interval is empty
        frame = int(f["dem_frame"][-1])
    with PositionsFile(folder / "positions.h5") as dem:
        placed = np.flatnonzero(np.all(np.isfinite(dem.frame(frame).positions[:, :2]), axis=1))
    assert record.kind == outlet.BED and record.particle.tolist() == placed.tolist()
    assert np.allclose(record.temperature, last[placed], rtol=1e-6, atol=0) and record.temperature.dtype == np.float64
