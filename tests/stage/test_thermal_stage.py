"""The thermal stage end to end on a synthetic positions file (no LIGGGHTS): a dense bed sinking
through a tube with a heated wall whose z axis recycles particles (periodic in the "DEM", open for
heat), so particles are recycled at the inlet every frame."""

import json
import logging
import math
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

import h5py
import numba
import numpy as np
import pytest

from dpht.closures import htc, rdf
from dpht.dem.dumps import FORMAT as POSITIONS_FORMAT, DumpFrame, write_positions
from dpht.errors import ConfigError
from dpht.thermal import modes, stage
from dpht.thermal.output import FORMAT
from dpht.verification import scenes
from dpht.geometry.walls import save_walls

R = scenes.RADIUS
T_COLD, T_WALL = 300.0, 900.0
DEM_STEP, DUMP_INTERVAL = 1e-5, 1000  # frames 0.01 s apart, the paper's thermal step
SPEED = 0.1  # m/s downwards: a diameter per frame, so several particles re-enter each frame
LOST = 7  # a particle the "DEM" loses from frame 5 on


def sinking_bed(n_frames: int, n: int = 500, seed: int = 3, dump_interval: int = DUMP_INTERVAL) -> list[DumpFrame]:
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
        t = k * DEM_STEP * dump_interval
        unwrapped = base + amplitude * np.sin(2 * np.pi * 7.0 * t + phase)
        unwrapped[:, 2] -= SPEED * t
        image = np.zeros(base.shape, dtype=np.int32)
        image[:, 2] = np.floor(unwrapped[:, 2] / length).astype(np.int32)
        positions = unwrapped.copy()
        positions[:, 2] -= image[:, 2] * length
        keep = ids != LOST if k >= 5 else np.ones(len(ids), dtype=bool)
        frames.append(DumpFrame(k * dump_interval, box_lo, box_hi, (False, False, True), ids[keep], positions[keep], image[keep]))
    return frames, tube_radius, length


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return make_scene(tmp_path_factory.mktemp("stage"), n_frames=12)


def make_scene(folder, n_frames: int, dump_interval: int = DUMP_INTERVAL):
    """Input files of the stage in ``folder``: positions (:func:`sinking_bed`), walls, HTC and RDF
    tables; returns (folder, spec, tables)."""
    frames, tube_radius, length = sinking_bed(n_frames, dump_interval=dump_interval)
    write_positions(folder / "positions.h5", frames, radius=R, density=3560.0, timestep=DEM_STEP, dump_interval=dump_interval,
                    attrs={"recycled": [False, False, True]})  # the DEM stage's tube: z recycles particles
    s = scenes.spec([m.name for m in modes.MODES], walls={"hot": {"temperature": T_WALL}},
                    initial_temperature=T_COLD, inlet_temperature=T_COLD)  # fmt: skip
    return folder, s, write_inputs(folder, scenes.tube_walls(tube_radius, length, element=2 * R), s)


def write_inputs(folder, walls, s) -> dict:
    """The stage's other inputs in ``folder``: ``walls.h5``, the HTC tables of spec ``s`` (returned
    by kind) and the synthetic RDF tables ``rdf.h5``."""
    save_walls(folder / "walls.h5", walls, "{}", 2 * R)
    tables = {}
    for kind, table in scenes.htc_tables(s).items():
        tables[kind] = folder / f"{kind}.h5"
        htc.save_table(tables[kind], table)
    rdf.save(folder / "rdf.h5", scenes.synthetic_rdf())
    return tables


def run_stage(scene, name, threads=None, dem_summary=None, checkpoints=stage.Checkpoints(), **thermal):
    folder, s, tables = scene
    s = json.loads(json.dumps(s))
    s["thermal"].update(thermal)
    out = folder / f"{name}.h5"
    saved = numba.get_num_threads()
    try:
        summary = stage.run(s, folder / "positions.h5", folder / "walls.h5", tables, out,
                            rdf_table=folder / "rdf.h5", xdmf=out.with_suffix(".xdmf"), threads=threads,
                            dem_summary=dem_summary, checkpoints=checkpoints)  # fmt: skip
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
    return data, attrs, stage.reproducible(json.loads(attrs.pop("summary")))


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
            "energy/convected": ((n_frames,), np.float64),
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


def test_resolved_particles_run_under_auto(resolved):
    _, summary = resolved
    assert summary["integrator"]["requested"] == "auto" and summary["integrator"]["frames"]["multirate"] == 0
    assert sum(summary["integrator"]["frames"].values()) == summary["frames"] - 1


def test_resolved_particles_run_implicit_through_the_stage(scene, resolved):
    """Resolved particles and a gas with the implicit integrator: the energy books to round-off
    every frame, temperatures in range, and the wall heat of explicit's run within the step's error."""
    out, summary = run_stage(scene, "resolved_implicit", intraparticle=True, shells=6, integrator="implicit")
    test_energy_is_conserved_every_frame((out, summary))
    test_maximum_principle((out, summary))
    assert summary["integrator"]["frames"]["implicit"] == summary["frames"] - 1
    assert summary["wall_energy_J"] == pytest.approx(resolved[1]["wall_energy_J"], rel=0.05)
    out, summary = run_stage(scene, "convection_implicit", intraparticle=True, shells=6, integrator="implicit",
                             convection={"coefficient": 200.0, "gas_temperature": 500.0})  # fmt: skip
    with h5py.File(out) as f:
        E, W, Rc, C = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled", "convected"))
    dE, dW, dR, dC = np.diff(E), np.diff(W), np.diff(Rc), np.diff(C)
    assert np.all(dC > 0) and np.max(np.abs(dE - dW - dR - dC) / (np.abs(dW) + np.abs(dR) + np.abs(dC))) <= 1e-12


def test_resolved_particles_with_multirate_stop_before_work(scene):
    with pytest.raises(ConfigError, match="thermal.integrator: 'multirate' cannot advance resolved particles"):
        run_stage(scene, "refused_multirate", intraparticle="auto", integrator="multirate")
    assert not list(scene[0].glob("refused_multirate*"))


@pytest.mark.parametrize("resolve", [False, True])
def test_convection_is_booked_every_frame(scene, resolve):
    """A gas hotter than the bed: particle energy change = wall heat + convected heat + recycling per
    frame to 1e-12, the gas heats the bed, and auto counts its conductance in the Biot number."""
    out, summary = run_stage(scene, f"convection{resolve}", intraparticle=resolve, shells=6,
                             convection={"coefficient": 200.0, "gas_temperature": 700.0})  # fmt: skip
    with h5py.File(out) as f:
        E, W, Rc, C = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled", "convected"))
    dE, dW, dR, dC = np.diff(E), np.diff(W), np.diff(Rc), np.diff(C)
    assert np.all(dC > 0) and summary["convected_energy_J"] == C[-1]
    assert np.max(np.abs(dE - dW - dR - dC) / (np.abs(dW) + np.abs(dR) + np.abs(dC))) <= 1e-12
    test_maximum_principle((out, summary))


def test_auto_counts_the_convection_in_the_biot_number(scene):
    _, still = run_stage(scene, "auto_still", intraparticle="auto", biot_threshold=1e3)
    _, blown = run_stage(scene, "auto_blown", intraparticle="auto", biot_threshold=1e3,
                         convection={"coefficient": 1000.0, "gas_temperature": 300.0})  # fmt: skip
    h_conv_biot = 1000.0 * 2 * R / 2.0  # h d_p / k_p with k_p = 2 W/(m K)
    assert blown["intraparticle"]["biot_max"] == pytest.approx(still["intraparticle"]["biot_max"] + h_conv_biot, rel=1e-9)


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


# --- checkpoints and resume ------------------------------------------------------------------


def test_checkpoints_do_not_change_the_file(scene, result):
    """Rows written in segments of 5 and 1 frames, then assembled: every dataset and attribute as
    from one segment (the timings aside)."""
    reference = read_all(result[0])
    for frames in (5, 1):
        out, _ = run_stage(scene, f"segments{frames}", checkpoints=stage.Checkpoints(frames=frames))
        assert_same(read_all(out), reference)
        assert not list(out.with_name(out.stem + ".work").glob("rows.*"))  # segments gone once assembled


def assert_same(files, reference):
    (data, attrs, summary), (data0, attrs0, summary0) = files, reference
    assert attrs == attrs0 and summary == summary0 and data.keys() == data0.keys()
    for name, value in data.items():
        assert np.array_equal(value, data0[name], equal_nan=value.dtype.kind == "f"), name


def failing_after(frames: int):
    """stage.step, raising once it has stepped ``frames`` frames (a run that fails there)."""
    real, calls = stage.step, []

    def failing(*args, **kwargs):
        if len(calls) == frames:
            raise RuntimeError("injected failure")
        calls.append(1)
        return real(*args, **kwargs)

    return failing


def test_resolved_run_resumes_bitwise_from_a_checkpoint(scene, resolved, monkeypatch):
    """A resolved run that fails after 7 frames resumes from its checkpoint after frame 6, whose
    State holds the shells, and writes the file of the uninterrupted run."""
    real = stage.step
    monkeypatch.setattr(stage, "step", failing_after(7))
    with pytest.raises(RuntimeError, match="injected failure"):
        run_stage(scene, "resumed", checkpoints=stage.Checkpoints(frames=3), intraparticle=True, shells=6)
    monkeypatch.setattr(stage, "step", real)
    with h5py.File(scene[0] / "resumed.work" / "checkpoint.h5") as f:
        assert f.attrs["count"] == 6 and f["shells"].shape == (f["h"].shape[0], 6)
    out, _ = run_stage(scene, "resumed", checkpoints=stage.Checkpoints(frames=3), intraparticle=True, shells=6)
    assert_same(read_all(out), read_all(resolved[0]))


def test_a_complete_output_is_published_again_not_recomputed(scene, result, caplog):
    out, summary = result
    work = out.with_name(out.stem + ".work")
    published = out.read_bytes()  # a copy of the work copy, never a hard link to it (dpht.util.files.publish)
    assert published == (work / "thermal.h5").read_bytes() and not os.path.samefile(out, work / "thermal.h5")
    out.unlink()  # as Snakemake does before it runs a job again
    with caplog.at_level(logging.INFO, logger="dpht"):
        again = run_stage(scene, "thermal")[1]
    assert again == summary and out.read_bytes() == published
    assert "complete" in caplog.text and "earlier run" in caplog.text and "thermal: 12/12" not in caplog.text
    # Other inputs under the same output name are computed, not taken from the work copy.
    hot, _ = run_stage(scene, "thermal", initial_temperature=T_COLD + 100.0)
    with h5py.File(hot) as f:
        assert f["temperature"][0].min() > T_COLD + 99.0
    run_stage(scene, "thermal")  # the original again for the other tests


KILL_SCRIPT = """
import json, sys
from pathlib import Path
from dpht.thermal import stage
spec, folder, name, frames = json.loads(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], int(sys.argv[4])
tables = {kind: folder / f"{kind}.h5" for kind in ("pfp", "pfw")}
stage.run(spec, folder / "long_positions.h5", folder / "walls.h5", tables, folder / f"{name}.h5",
          rdf_table=folder / "rdf.h5", checkpoints=stage.Checkpoints(frames=frames))
"""


@pytest.fixture(scope="module")
def long_scene(scene):
    """The scene over 40 frames, and its uninterrupted result with the time it took."""
    folder, s, tables = scene
    frames, _, _ = sinking_bed(n_frames=40)
    write_positions(folder / "long_positions.h5", frames, radius=R, density=3560.0, timestep=DEM_STEP,
                    dump_interval=DUMP_INTERVAL)  # fmt: skip
    started = time.perf_counter()
    out = folder / "long.h5"
    stage.run(s, folder / "long_positions.h5", folder / "walls.h5", tables, out, rdf_table=folder / "rdf.h5")
    return out, time.perf_counter() - started


def _saved_frames(work) -> int:
    try:
        with h5py.File(work / "checkpoint.h5") as f:
            return int(f.attrs["count"])
    except (OSError, KeyError):
        return 0


def interrupted_run(scene, name, sig, delay, frames=3, after=0, copies=1):
    """Start the long scene's stage in its own process and send it ``sig`` (``copies`` times, 20 ms
    apart) ``delay`` seconds after its checkpoint holds ``after`` frames (0: after its first
    segment is opened); returns (exit code, frames saved by then)."""
    folder, s, _ = scene
    work, out = folder / f"{name}.work", folder / f"{name}.h5"
    stale = set(work.glob(".rows.*.part.h5"))  # left by a killed run
    child = subprocess.Popen([sys.executable, "-c", KILL_SCRIPT, json.dumps(s), str(folder), name, str(frames)])
    deadline = time.monotonic() + 120
    while child.poll() is None and not (_saved_frames(work) >= after if after else set(work.glob(".rows.*.part.h5")) - stale):
        assert time.monotonic() < deadline
        time.sleep(0.002)
    time.sleep(delay)
    for _ in range(copies):
        child.send_signal(sig)
        time.sleep(0.02)
    code = child.wait(timeout=60)
    if out.exists():  # finished before the signal came: complete, never partial at the output's name
        with h5py.File(out) as f:
            assert f.attrs["complete"]
            return code, f["time"].size
    return code, _saved_frames(work)


def test_killed_at_random_frames_resumes_bitwise(scene, long_scene):
    """SIGKILL of the stage's process at random frames (twice, each past a checkpoint and within a
    segment of 3 frames), then a run to the end: the same file as the uninterrupted run, bit for
    bit (every dataset and attribute but the timings)."""
    reference, _ = long_scene
    seed = int(np.random.default_rng().integers(1 << 30))
    rng = np.random.default_rng(seed)
    first = int(rng.integers(1, 6)) * 3
    targets = [first, first + 3 * int(rng.integers(1, 5))]
    saved = [interrupted_run(scene, "killed", signal.SIGKILL, rng.uniform(0, 0.05), after=t) for t in targets]
    assert [code for code, _ in saved] == [-signal.SIGKILL] * 2, (seed, saved)
    assert targets[0] <= saved[0][1] <= saved[1][1] < 40, (seed, saved)
    folder, s, tables = scene
    out = folder / "killed.h5"
    stage.run(s, folder / "long_positions.h5", folder / "walls.h5", tables, out, rdf_table=folder / "rdf.h5",
              checkpoints=stage.Checkpoints(frames=3))  # fmt: skip
    assert_same(read_all(out), read_all(reference))


def test_sigint_saves_the_frame_it_finished(scene, long_scene):
    """SIGINT (and SIGTERM) stop the stage after the frame in progress, saved: no frame is lost.
    Ctrl-C reaches a stage twice (from the terminal and through snakemake): still one request."""
    reference, _ = long_scene
    # The scene's 40 frames take under a second: signal soon after a segment is opened (at its first
    # row), or the run may be complete before the signal comes.
    code, saved = interrupted_run(scene, "stopped", signal.SIGINT, 0.03, frames=1000, copies=2)
    assert code in (130, -signal.SIGINT) and 0 < saved < 40  # one segment: saved only because it stopped
    code, saved_again = interrupted_run(scene, "stopped", signal.SIGTERM, 0.0, frames=1000)
    assert code == 128 + signal.SIGTERM and saved < saved_again < 40
    folder, s, tables = scene
    stage.run(s, folder / "long_positions.h5", folder / "walls.h5", tables, folder / "stopped.h5",
              rdf_table=folder / "rdf.h5")  # fmt: skip
    assert_same(read_all(folder / "stopped.h5"), read_all(reference))
