"""The thermal stage end to end on a synthetic positions file (no LIGGGHTS): a dense bed sinking
through a periodic tube with a heated wall, so particles are recycled at the inlet every frame."""

import json
import math
import xml.etree.ElementTree as ET

import h5py
import numba
import numpy as np
import pytest

from dpht.closures import htc, rdf
from dpht.dem.dumps import FORMAT as POSITIONS_FORMAT, DumpFrame, write_positions
from dpht.thermal import modes, stage
from dpht.thermal.output import FORMAT
from dpht.verification import scenes
from geometry.walls import save_walls

R = scenes.RADIUS
T_COLD, T_WALL = 300.0, 900.0
DEM_STEP, DUMP_INTERVAL = 1e-5, 1000  # frames 0.01 s apart, the paper's thermal step
SPEED = 0.1  # m/s downwards: a diameter per frame, so several particles re-enter each frame
LOST = 7  # a particle the "DEM" loses from frame 5 on


def sinking_bed(n_frames: int, n: int = 500, seed: int = 3) -> list[DumpFrame]:
    """Frames of a bed moving down the periodic tube axis at SPEED, each particle also oscillating
    by up to 2% of a diameter per axis (so contacts change between frames), wrapped into the box
    with LIGGGHTS-style image flags."""
    base, tube_radius, length = scenes.dense_tube_bed(n, solid_fraction=0.6)
    rng = np.random.default_rng(seed)
    amplitude = 0.02 * 2 * R * rng.uniform(0.5, 1.0, base.shape)
    phase = rng.uniform(0, 2 * np.pi, base.shape)
    box_lo, box_hi = np.array([-tube_radius, -tube_radius, 0.0]), np.array([tube_radius, tube_radius, length])
    ids = np.arange(1, len(base) + 1, dtype=np.int64)
    frames = []
    for k in range(n_frames):
        t = k * DEM_STEP * DUMP_INTERVAL
        unwrapped = base + amplitude * np.sin(2 * np.pi * 7.0 * t + phase)
        unwrapped[:, 2] -= SPEED * t
        image = np.zeros(base.shape, dtype=np.int32)
        image[:, 2] = np.floor(unwrapped[:, 2] / length).astype(np.int32)
        positions = unwrapped.copy()
        positions[:, 2] -= image[:, 2] * length
        keep = ids != LOST if k >= 5 else np.ones(len(ids), dtype=bool)
        frames.append(DumpFrame(k * DUMP_INTERVAL, box_lo, box_hi, (False, False, True), ids[keep], positions[keep], image[keep]))
    return frames, tube_radius, length


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """Input files of the stage: positions, walls, HTC and RDF tables, and the spec."""
    folder = tmp_path_factory.mktemp("stage")
    frames, tube_radius, length = sinking_bed(n_frames=12)
    write_positions(folder / "positions.h5", frames, radius=R, density=3560.0, timestep=DEM_STEP, dump_interval=DUMP_INTERVAL)
    save_walls(folder / "walls.h5", scenes.tube_walls(tube_radius, length, element=2 * R), "{}", 2 * R)
    s = scenes.spec([m.name for m in modes.MODES], walls={"hot": {"temperature": T_WALL}},
                    initial_temperature=T_COLD, inlet_temperature=T_COLD)  # fmt: skip
    tables = {}
    for kind, table in scenes.htc_tables(s).items():
        tables[kind] = folder / f"{kind}.h5"
        htc.save_table(tables[kind], table)
    rdf.save(folder / "rdf.h5", scenes.synthetic_rdf())
    return folder, s, tables


def run_stage(scene, name, threads=None, **thermal):
    folder, s, tables = scene
    s = json.loads(json.dumps(s))
    s["thermal"].update(thermal)
    out = folder / f"{name}.h5"
    saved = numba.get_num_threads()
    try:
        summary = stage.run(s, folder / "positions.h5", folder / "walls.h5", tables, out,
                            rdf_table=folder / "rdf.h5", xdmf=out.with_suffix(".xdmf"), threads=threads)  # fmt: skip
    finally:
        numba.set_num_threads(saved)
    return out, summary


@pytest.fixture(scope="module")
def result(scene):
    return run_stage(scene, "thermal")


def read_all(path):
    """Every dataset and attribute of an HDF5 file, the run-dependent summary fields dropped."""
    data = {}
    with h5py.File(path) as f:
        f.visititems(lambda name, obj: data.__setitem__(name, obj[...]) if isinstance(obj, h5py.Dataset) else None)
        attrs = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in f.attrs.items()}
    summary = json.loads(attrs.pop("summary"))
    for key in ("seconds", "threads"):
        summary.pop(key)
    return data, attrs, summary


def test_energy_is_conserved_every_frame(result):
    """Particle energy change = wall heat + enthalpy reset at re-entry, per frame, to round-off."""
    out, summary = result
    with h5py.File(out) as f:
        E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
        time, wall_heat = f["time"][...], f["wall_heat"][...]
    dE, dW, dR = np.diff(E), np.diff(W), np.diff(Rc)
    assert np.all(dW > 0) and np.all(dR < 0)  # the wall heats, cold re-entering particles cool the bed
    assert np.count_nonzero(dR) == dR.size  # particles re-enter at every frame
    assert np.max(np.abs(dE - dW - dR) / (np.abs(dW) + np.abs(dR))) <= 1e-12
    # The wall energy is the time integral of the wall heat (the interval's mean, per frame).
    np.testing.assert_allclose(dW, np.diff(time) * wall_heat[:-1].sum(axis=1), rtol=1e-12)
    assert (summary["wall_energy_J"], summary["recycled_energy_J"]) == (W[-1], Rc[-1])  # the last frame only evaluates


def test_maximum_principle(result):
    """Without sources every temperature stays within the initial, inlet and wall temperatures."""
    out, _ = result
    with h5py.File(out) as f:
        T = f["temperature"][...]
    finite = T[np.isfinite(T)]
    assert finite.min() >= T_COLD - 1e-3 and finite.max() <= T_WALL + 1e-3  # float32 storage
    assert finite.max() > T_COLD + 1.0  # the wall did heat the bed


def test_output_layout(scene, result):
    out, summary = result
    folder = scene[0]
    with h5py.File(folder / "positions.h5") as f:
        assert f.attrs["format"] == POSITIONS_FORMAT
        n_frames, n = f["positions"].shape[:2]
        times, ids = f["time"][...], f["ids"][...]
    with h5py.File(folder / "walls.h5") as f:
        m = f["area"].shape[0]
    pw = [mode.name for mode in modes.MODES if mode.side == "pw"]
    with h5py.File(out) as f:
        assert f.attrs["format"] == FORMAT and bool(f.attrs["complete"])
        assert list(f.attrs["wall_modes"]) == pw
        assert sorted(json.loads(f.attrs["modes"])) == sorted(mode.name for mode in modes.MODES)
        assert f.attrs["positions"] == "positions.h5"
        shapes = {
            "ids": ((n,), np.int64), "time": ((n_frames,), np.float64), "temperature": ((n_frames, n), np.float32),
            "wall_heat": ((n_frames, len(pw)), np.float64), "element_heat": ((n_frames, m, len(pw)), np.float32),
            "substeps": ((n_frames,), np.int32), "energy/particles": ((n_frames,), np.float64),
            "energy/wall": ((n_frames,), np.float64), "energy/recycled": ((n_frames,), np.float64),
        }  # fmt: skip
        for name, (shape, dtype) in shapes.items():
            assert (f[name].shape, f[name].dtype) == (shape, dtype), name
        assert np.array_equal(f["ids"][...], ids) and np.array_equal(f["time"][...], times)
        T = f["temperature"][...]
        lost = int(np.flatnonzero(ids == LOST)[0])
        assert np.all(np.isnan(T[5:, lost])) and np.all(np.isfinite(np.delete(T, lost, axis=1)))
        assert np.all(f["substeps"][:-1] >= 1) and f["substeps"][-1] == 0  # the last frame only evaluates
        assert json.loads(f.attrs["summary"]) == summary
        np.testing.assert_allclose(f["wall_heat"][...], f["element_heat"][...].sum(axis=1), rtol=1e-5)
    assert summary["frames"] == n_frames and summary["particles"] == n
    assert list(summary["wall_heat_last_W"]) == pw
    grids = ET.parse(out.with_suffix(".xdmf")).getroot().findall(".//Grid[@GridType='Uniform']")
    assert len(grids) == n_frames


def test_one_and_two_threads_write_identical_files(scene, result):
    files = [read_all(run_stage(scene, f"threads{k}", threads=k)[0]) for k in (1, 2)]
    for data, attrs, summary in files[1:]:
        assert attrs == files[0][1] and summary == files[0][2]
        assert data.keys() == files[0][0].keys()
        for name, value in data.items():
            assert np.array_equal(value, files[0][0][name], equal_nan=value.dtype.kind == "f"), name


def test_particle_particle_modes_only(scene):
    """No particle-wall mode: zero wall-heat columns, and a warm bed's energy changes only by the
    cold particles re-entering; temperatures stay within the inlet and initial ones."""
    pp = {m: m in modes.PP_MODES for m in modes.NAMES}
    out, summary = run_stage(scene, "pp_only", modes=pp, initial_temperature=600.0)
    with h5py.File(out) as f:
        assert not np.any(f["element_heat"][...]) and not np.any(f["wall_heat"][...])
        E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
        T = f["temperature"][...]
    assert not np.any(W) and summary["wall_heat_last_W"] == dict.fromkeys(modes.PW_MODES, 0.0)
    assert np.all(np.diff(Rc) < 0)
    assert np.max(np.abs(np.diff(E) - np.diff(Rc)) / np.abs(np.diff(Rc))) <= 1e-12
    assert np.nanmin(T) >= T_COLD - 1e-3 and np.nanmax(T) <= 600.0 + 1e-3


def test_frame_stride_keeps_every_other_frame(scene, result):
    out, summary = run_stage(scene, "stride", frame_stride=2)
    with h5py.File(out) as f, h5py.File(result[0]) as full:
        assert np.array_equal(f["time"][...], full["time"][::2])
        assert np.array_equal(f["temperature"][0], full["temperature"][0])
        E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
    dE, dW, dR = np.diff(E), np.diff(W), np.diff(Rc)
    assert np.max(np.abs(dE - dW - dR) / (np.abs(dW) + np.abs(dR))) <= 1e-12
    assert summary["frames"] == math.ceil(12 / 2)


@pytest.fixture(scope="module")
def resolved(scene):
    return run_stage(scene, "resolved", intraparticle=True, shells=6)


def test_resolved_particles_conserve_energy_and_keep_the_maximum_principle(result, resolved):
    """Intra-particle conduction on: the same books to round-off, temperatures in range, and the
    bed takes less heat than uniform particles (the surface touching the wall is hotter than the mean)."""
    test_energy_is_conserved_every_frame(resolved)
    test_maximum_principle(resolved)
    _, lumped_summary = result
    out, summary = resolved
    assert summary["intraparticle"]["resolved"] and summary["intraparticle"]["reason"] == "set in the config"
    assert 0 < summary["wall_energy_J"] < lumped_summary["wall_energy_J"]


def test_resolved_one_and_two_threads_write_identical_files(scene, resolved):
    out, _ = run_stage(scene, "resolved_one_thread", threads=1, intraparticle=True, shells=6)
    a, b = read_all(out), read_all(resolved[0])
    assert a[2] == b[2] and set(a[0]) == set(b[0])
    assert all(np.array_equal(a[0][k], b[0][k], equal_nan=True) for k in a[0])


def test_auto_decides_by_the_largest_biot_number(scene, result, caplog):
    """Below the scene's largest Bi the particles are resolved, above it they stay uniform (and the
    run is the lumped one), each decision logged with its numbers."""
    caplog.set_level("INFO", logger="dpht")
    _, on = run_stage(scene, "auto_on", intraparticle="auto", shells=6, biot_threshold=1e-6)
    record = on["intraparticle"]
    assert record["resolved"] and record["biot_max"] > 1e-6 and record["fraction_above"] == 1.0
    assert "thermal.intraparticle auto: resolved, 6 shells (Bi up to" in caplog.text
    out, off = run_stage(scene, "auto_off", intraparticle="auto", biot_threshold=2 * record["biot_max"])
    assert not off["intraparticle"]["resolved"] and off["intraparticle"]["biot_max"] == record["biot_max"]
    assert "auto: uniform particles" in caplog.text
    with h5py.File(out) as f, h5py.File(result[0]) as g:
        assert np.array_equal(f["temperature"][...], g["temperature"][...], equal_nan=True)
