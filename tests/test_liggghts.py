"""DEM stage: deck rendering, config checks, and real LIGGGHTS runs (a short flow, kill and resume, failure).

The real runs use a small periodic tube (8 mm, 20 mm long, 6 mm orifice, ~420 particles of 1 mm)
with wall STLs made here, so the tests do not depend on the geometry stage.
"""

from __future__ import annotations

import copy
import fcntl
import json
import math
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

from dpht import liggghts
from dpht.dumps import PositionsFile
from dpht.errors import ConfigError, DPHTError, ExternalToolError
from dpht.liggghts import DemParams, read_thermo, render_decks, run_dem, run_liggghts

needs_liggghts = pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed")

D, R_TUBE, LENGTH, Z_PLATE, R_HOLE = 1.0e-3, 4.0e-3, 0.02, 0.002, 3.0e-3
SPEC = {
    "particles": {"diameter": D, "density": 3560.0, "youngs_modulus_dem": 5.0e6, "poisson_ratio": 0.3},
    "wall": {"youngs_modulus_dem": 5.0e6, "poisson_ratio": 0.3},
    "contact": {
        "restitution": {"pp": 0.82, "pw": 0.44},
        "friction": {"pp": 0.72, "pw": 0.30},
        "rolling_friction": {"pp": 0.13, "pw": 0.50},
    },
    "geometry": {
        "tube": {
            "inner_diameter": 2 * R_TUBE,
            "length": LENGTH,
            "orifice_height": Z_PLATE,
            "orifice_diameter": 2 * R_HOLE,
            "heated": [Z_PLATE, 0.016],
        },
        "mesh_size": 1.0,
    },
    "dem": {
        "timestep": 1.0e-5,
        "fill_height": 0.008,
        "settle_time": 0.05,
        "flow_time": 0.1,
        "dump_interval": 500,
        "restart_interval": 4000,
        "seed": 32452843,
    },
}


def spec_with(**dem) -> dict:
    spec = copy.deepcopy(SPEC)
    spec["dem"].update(dem)
    return spec


# --- wall STLs ------------------------------------------------------------------------------


def _write_stl(path: Path, triangles: np.ndarray) -> None:
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    record = np.zeros(len(triangles), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["n"], record["v"] = normal, triangles
    path.write_bytes(bytes(80) + np.uint32(len(triangles)).tobytes() + record.tobytes())


def _grid(u: np.ndarray, v: np.ndarray, point) -> np.ndarray:
    """Two triangles per cell of the (u, v) grid mapped to 3-D by ``point(u, v)``."""
    uu, vv = np.meshgrid(u, v, indexing="ij")
    p = point(uu, vv)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])


def tube_meshes(folder: Path, size: float = 1.0e-3) -> Path:
    """heated/adiabatic cylinder pieces (radius R_TUBE, 0 <= z <= LENGTH) and the orifice annulus."""
    folder.mkdir(parents=True, exist_ok=True)
    theta = np.linspace(0.0, 2 * np.pi, math.ceil(2 * np.pi * R_TUBE / size) + 1)

    def cylinder(z0, z1):
        z = np.linspace(z0, z1, max(1, math.ceil((z1 - z0) / size)) + 1)
        return _grid(theta, z, lambda t, zz: np.stack([R_TUBE * np.cos(t), R_TUBE * np.sin(t), zz], -1))

    z_heat = SPEC["geometry"]["tube"]["heated"]
    _write_stl(folder / "heated_wall.stl", cylinder(*z_heat))
    _write_stl(folder / "adiabatic_wall.stl", np.concatenate([cylinder(0.0, z_heat[0]), cylinder(z_heat[1], LENGTH)]))
    r = np.linspace(R_HOLE, R_TUBE, 3)
    plate = _grid(theta, r, lambda t, rr: np.stack([rr * np.cos(t), rr * np.sin(t), np.full_like(t, Z_PLATE)], -1))
    _write_stl(folder / "orifice.stl", plate)
    return folder


# --- rendering and config checks (no LIGGGHTS) ----------------------------------------------------


def test_decks_are_deterministic_and_carry_the_config():
    params = DemParams.from_spec(SPEC)
    decks = render_decks(params)
    assert decks == render_decks(DemParams.from_spec(copy.deepcopy(SPEC)))
    settle, flow = decks["settle.in"], decks["flow.in"]
    for deck in (settle, flow):
        assert "@" not in deck.replace("%", "")  # every placeholder substituted
        assert "youngsModulus peratomtype 5000000.0 5000000.0" in deck
        assert "coefficientRestitution peratomtypepair 2 0.82 0.44 0.44 0.44" in deck
        assert "coefficientFriction peratomtypepair 2 0.72 0.3 0.3 0.3" in deck
        assert "coefficientRollingFriction peratomtypepair 2 0.13 0.5 0.5 0.5" in deck
        assert "pair_style gran model hertz tangential history rolling_friction epsd2" in deck
        assert "timestep 1e-05" in deck and "boundary f f p" in deck
    assert "zplane 0.002" in settle and "zplane" not in flow
    # Default: exact cylinder for the tube, STL for the plate; "mesh": all three zones as STL.
    assert "primitive type 2 zcylinder 0.004 0.0 0.0" in flow and "mesh n_meshes 1 meshes orifice" in flow
    meshed = render_decks(DemParams.from_spec(spec_with(tube_wall="mesh")))["flow.in"]
    assert "zcylinder" not in meshed
    assert "mesh n_meshes 3 meshes heated_wall adiabatic_wall orifice" in meshed
    assert "fix heated_wall all mesh/surface file meshes/heated_wall.stl type 2" in meshed
    assert "density constant 3560.0 radius constant 0.0005" in settle
    assert "dump positions all custom 500 flow/post/dump.*.txt id x y z ix iy iz" in flow
    assert "restart 4000 flow/restart/flow.*.restart" in flow
    seeds = [int(s) for s in re.findall(r"(?:seed|sphere|discrete) (\d+)", settle)]
    assert len(set(seeds)) == 3 and all(liggghts._is_prime(s) and s > 10000 for s in seeds)
    # The insertion cylinder lies inside the tube, above the plate, below the periodic top.
    match = re.search(r"region fill cylinder z 0.0 0.0 (\S+) (\S+) (\S+)", settle)
    radius, z_lo, z_hi = map(float, match.groups())
    assert radius + D / 2 < R_TUBE and Z_PLATE + D / 2 < z_lo < z_hi < LENGTH - D / 2
    steps = params.steps()
    assert steps["settle_end"] % 500 == 0 and (steps["flow_end"] - steps["settle_end"]) * 1e-5 >= 0.1
    assert f"run {steps['flow_end']} upto" in flow


def test_fill_count_matches_the_bed_volume():
    params = DemParams.from_spec(SPEC)
    solid = params.n_particles * math.pi * D**3 / 6
    bed = math.pi * R_TUBE**2 * SPEC["dem"]["fill_height"]
    assert solid / bed == pytest.approx(liggghts.FILL_SOLID_FRACTION, rel=0.01)


def test_rayleigh_time_scales_as_radius_over_shear_wave_speed():
    # Doubling r doubles it; quadrupling E halves it (t_R ~ r sqrt(rho/G)).
    base = liggghts.rayleigh_time(5e-4, 2500.0, 1e7, 0.25)
    assert liggghts.rayleigh_time(1e-3, 2500.0, 1e7, 0.25) == pytest.approx(2 * base, rel=1e-12)
    assert liggghts.rayleigh_time(5e-4, 2500.0, 4e7, 0.25) == pytest.approx(base / 2, rel=1e-12)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"restart_interval": 1200}, "multiple of dem.dump_interval"),
        ({"seed": 32452844}, "prime"),
        ({"fill_height": 0.02}, "dem.fill_height"),
        ({"timestep": 1e-4}, "Rayleigh"),
        ({"dump_interval": 0}, "dem.dump_interval"),
        ({"position_precision": "float16"}, "position_precision"),
        ({"tube_wall": "cylinder"}, "tube_wall"),
    ],
)
def test_bad_dem_config_names_the_key(tmp_path, change, message):
    with pytest.raises(ConfigError, match=message):
        run_dem(spec_with(**change), tmp_path, tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)


def test_missing_key_and_missing_mesh(tmp_path):
    spec = copy.deepcopy(SPEC)
    del spec["contact"]["friction"]["pw"]
    with pytest.raises(ConfigError, match="contact.friction.pw"):
        DemParams.from_spec(spec)
    with pytest.raises(DPHTError, match="orifice.stl"):
        run_dem(SPEC, tmp_path / "nowhere", tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)
    meshes = tube_meshes(tmp_path / "m")
    (meshes / "heated_wall.stl").unlink()  # not needed with the primitive tube wall, needed as a mesh
    with pytest.raises(DPHTError, match="heated_wall.stl"):
        run_dem(spec_with(tube_wall="mesh"), meshes, tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)


def test_busy_workdir_is_refused(tmp_path):
    workdir = tmp_path / "w"
    workdir.mkdir()
    with open(workdir / ".dem.lock", "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(DPHTError, match="in use"):
            run_dem(SPEC, tube_meshes(tmp_path / "m"), workdir, tmp_path / "p.h5", log=lambda _: None)


# --- real LIGGGHTS runs ------------------------------------------------------------------


@needs_liggghts
def test_failing_deck_reports_the_log_tail(tmp_path):
    (tmp_path / "bad.in").write_text("units si\natom_style granular\nno_such_command 1 2 3\n")
    with pytest.raises(ExternalToolError) as err:
        run_liggghts("bad.in", tmp_path, tmp_path / "screen.txt")
    text = str(err.value)
    assert "ERROR" in text and "no_such_command" in text  # the error line survived MPI_Abort
    assert str(tmp_path / "screen.txt") in text


@needs_liggghts
def test_sigterm_stops_liggghts_too(tmp_path):
    # Python's default SIGTERM action would exit without stopping the child: run_liggghts handles it.
    (tmp_path / "long.in").write_text(
        "units si\natom_style granular\natom_modify sort 0 0.0\n"
        "region box block 0 1 0 1 0 1 units box\ncreate_box 1 box\n"
        "run 2000000000\n"
    )
    script = "import sys; from dpht.liggghts import run_liggghts; run_liggghts('long.in', sys.argv[1], sys.argv[2])"
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path), str(tmp_path / "screen.txt")])
    deadline = time.monotonic() + 30
    while not _processes_in(tmp_path.resolve()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _processes_in(tmp_path.resolve()), "LIGGGHTS did not start"
    child.send_signal(signal.SIGTERM)
    assert child.wait(timeout=20) == 128 + signal.SIGTERM
    assert not _processes_in(tmp_path.resolve())


@needs_liggghts
def test_corrupt_mesh_gives_external_tool_error(tmp_path):
    meshes = tube_meshes(tmp_path / "m")
    (meshes / "orifice.stl").write_text("solid broken\n facet normal 0 0 1\n  outer loop\nendsolid\n")
    with pytest.raises(ExternalToolError) as err:
        run_dem(SPEC, meshes, tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)
    text = str(err.value)
    assert "ERROR" in text and "last 30 lines" in text and "settle/screen.txt" in text


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("dem")
    meshes = tube_meshes(root / "meshes")
    lines = []
    start = time.monotonic()
    summary = run_dem(SPEC, meshes, root / "work", root / "positions.h5", ranks=1, log=lines.append)
    return root, meshes, summary, lines, time.monotonic() - start


@needs_liggghts
@pytest.mark.slow
def test_short_run_flows_through_the_orifice(short_run):
    root, _, summary, lines, seconds = short_run
    params = DemParams.from_spec(SPEC)
    steps = params.steps()
    assert seconds < 60
    assert summary["particles"] == summary["particles_inserted"] == params.n_particles
    assert summary["lost_particles"]["count"] == 0
    with PositionsFile(root / "positions.h5") as f:
        np.testing.assert_array_equal(f.ids, np.arange(1, params.n_particles + 1))
        np.testing.assert_array_equal(np.diff(f.steps), 500)
        assert (f.steps[0], f.steps[-1]) == (steps["settle_end"], steps["flow_end"])
        first, last = f.frame(0), f.frame(-1)
        assert not first.image.any()  # settled bed: nobody has crossed yet
        crossed = np.count_nonzero(last.image[:, 2] < 0)
        assert crossed > 20 and not summary["jammed"]
        _check_walls_hold(f.frames())
    assert -np.sum(last.image[:, 2]) == summary["orifice_crossings"]
    # Beverloo correlation W = C rho_b sqrt(g) (D0 - k d)^2.5 (C ~ 0.58, k ~ 1.5), bulk density from
    # the fill fraction. A tube only 1.3 hole diameters wide is no silo (measured here: 1.9 x
    # Beverloo), so this only catches gross errors: a jam, a missing plate, wrong units.
    beverloo = 0.58 * liggghts.FILL_SOLID_FRACTION * 3560.0 * math.sqrt(9.81) * (2 * R_HOLE - 1.5 * D) ** 2.5
    assert 0.5 < summary["mass_flow_second_half_kg_s"] / beverloo < 3.0
    # LIGGGHTS' own Rayleigh-time check (fix check/timestep/gran) agrees with ours.
    assert summary["rayleigh_fraction_liggghts"] == pytest.approx(summary["rayleigh_fraction"], rel=1e-6)
    bed = summary["bed_top_settled_m"] - Z_PLATE
    assert bed == pytest.approx(SPEC["dem"]["fill_height"], rel=0.25)
    assert any("DEM flow: step" in line for line in lines)


@needs_liggghts
@pytest.mark.slow
def test_rerun_is_a_no_op_and_decks_stay_for_inspection(short_run):
    root, meshes, summary, _, _ = short_run
    lines = []
    start = time.monotonic()
    again = run_dem(SPEC, meshes, root / "work", root / "positions.h5", ranks=1, log=lines.append)
    assert again == summary and time.monotonic() - start < 5
    assert any("up to date" in line for line in lines)
    decks = render_decks(DemParams.from_spec(SPEC))
    for name, text in decks.items():
        assert (root / "work" / name).read_text() == text
    assert not list((root / "work" / "flow" / "post").glob("dump.*.txt"))  # gathered, then deleted


@needs_liggghts
@pytest.mark.slow
def test_serial_runs_are_reproducible(short_run, tmp_path):
    root, meshes, _, _, _ = short_run
    run_dem(SPEC, meshes, tmp_path / "work", tmp_path / "positions.h5", ranks=1, log=lambda _: None)
    with h5py.File(root / "positions.h5") as a, h5py.File(tmp_path / "positions.h5") as b:
        for name in ("positions", "image", "ids", "step"):
            np.testing.assert_array_equal(a[name][...], b[name][...])


def _check_walls_hold(frames) -> None:
    """Centres stay a radius inside the tube (5 % overlap allowed), in the periodic box, and
    cross the plate only through the hole."""
    for frame in frames:
        rho = np.hypot(frame.positions[:, 0], frame.positions[:, 1])
        assert rho.max() < R_TUBE - 0.45 * D
        z = frame.positions[:, 2]
        assert np.all((z >= 0) & (z < LENGTH))
        in_plate = np.abs(z - Z_PLATE) < 0.45 * D
        assert np.all(rho[in_plate] < R_HOLE)


@needs_liggghts
@pytest.mark.slow
def test_meshed_tube_wall_holds_particles(tmp_path):
    spec = spec_with(tube_wall="mesh", settle_time=0.02, flow_time=0.04, restart_interval=20000)
    summary = run_dem(spec, tube_meshes(tmp_path / "m"), tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)
    assert summary["orifice_crossings"] > 0 and summary["lost_particles"]["count"] == 0
    with PositionsFile(tmp_path / "p.h5") as f:
        _check_walls_hold(f.frames())


def _processes_in(folder: Path) -> list[int]:
    """Pids whose working directory is ``folder`` (LIGGGHTS runs there)."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and Path(os.readlink(proc / "cwd")) == folder:
                found.append(int(proc.name))
        except OSError:
            continue
    return found


@needs_liggghts
@pytest.mark.slow
def test_killed_flow_resumes_without_gaps(tmp_path, short_run):
    meshes = tube_meshes(tmp_path / "meshes")
    workdir, out = tmp_path / "work", tmp_path / "positions.h5"
    # Start from the short run's settled bed (same spec and meshes), which also checks it is reused.
    shutil.copytree(short_run[0] / "work" / "settle", workdir / "settle")
    ranks = 2 if (os.cpu_count() or 1) >= 2 else 1
    steps = DemParams.from_spec(SPEC).steps()
    first_restart = liggghts._ceil_to(steps["settle_end"] + 1, SPEC["dem"]["restart_interval"])
    script = (
        "import json, sys; from dpht.liggghts import run_dem; "
        "run_dem(json.loads(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], ranks=int(sys.argv[5]))"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", script, json.dumps(SPEC), str(meshes), str(workdir), str(out), str(ranks)],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    screen = workdir / "flow" / "screen.1.txt"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and child.poll() is None:
        reached = max((int(r["step"]) for r in read_thermo(screen)), default=0)
        if reached >= first_restart + 3 * SPEC["dem"]["dump_interval"]:
            break
        time.sleep(0.1)
    assert child.poll() is None, "the run ended before it could be killed"
    os.killpg(child.pid, signal.SIGKILL)  # Python, mpirun and LIGGGHTS, mid-flow
    child.wait()
    while _processes_in(workdir.resolve()) and time.monotonic() < deadline + 30:
        time.sleep(0.2)  # MPI ranks notice their mpirun is gone
    assert not _processes_in(workdir.resolve())
    stale = max(int(p.name.split(".")[1]) for p in (workdir / "flow" / "post").glob("dump.*.txt"))

    lines = []
    summary = run_dem(SPEC, meshes, workdir, out, ranks=ranks, log=lines.append)
    resumed = [int(m.group(1)) for line in lines if (m := re.search(r"resuming from .* \(step (\d+)", line))]
    assert len(resumed) == 1 and steps["settle_end"] < resumed[0] <= stale
    assert any("reusing the settled bed" in line for line in lines)
    assert summary["flow_attempts"] == [steps["settle_end"], resumed[0]]
    with PositionsFile(out) as f:
        np.testing.assert_array_equal(f.steps, np.arange(steps["settle_end"], steps["flow_end"] + 1, 500))
        assert f.n_particles == summary["particles_inserted"]
        np.testing.assert_array_equal(f.ids, np.arange(1, f.n_particles + 1))
        assert not any(frame.lost.any() for frame in f.frames())
