"""DEM stage: parameters, deck rendering, config checks, and real LIGGGHTS runs (a short flow, kill
and resume, failure, mixers) of the tiny scene in :mod:`dem_scene`."""

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

import dem_scene
from dem_scene import (
    D, GEOMETRY, LENGTH, R_HOLE, R_TUBE, SPEC, Z_PLATE, geometry_summary, needs_liggghts, spec_with, tube_meshes,
)
from dpht.defaults import default
from dpht.dem import params as dem_params
from dpht.dem.decks import render_decks
from dpht.dem.params import DemParams
from dpht.dem.dumps import PositionsFile
from dpht.errors import ConfigError, DPHTError, ExternalToolError
from dpht.dem.liggghts import read_thermo, run_dem, run_liggghts


# --- rendering and config checks (no LIGGGHTS) ----------------------------------------------------


def test_decks_are_deterministic_and_carry_the_config():
    params = DemParams.from_spec(SPEC, GEOMETRY)
    decks = render_decks(params)
    assert decks == render_decks(DemParams.from_spec(copy.deepcopy(SPEC), GEOMETRY))
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
    # Every mesh zone is in one mesh (meshes/walls.stl, zone after zone in mesh_zones' order).
    assert "primitive type 2 zcylinder 0.004 0.0 0.0" in flow and "mesh n_meshes 1 meshes mesh_walls" in flow
    assert "fix mesh_walls all mesh/surface file meshes/walls.stl type 2" in flow and params.mesh_zones == ("orifice",)
    meshed = DemParams.from_spec(spec_with(tube_wall="mesh"), GEOMETRY)
    assert "zcylinder" not in render_decks(meshed)["flow.in"]
    assert meshed.mesh_zones == ("heated_wall", "adiabatic_wall", "orifice")
    assert "density constant 3560.0 radius constant 0.0005" in settle
    assert "dump positions all custom 500 flow/post/dump.*.txt id x y z ix iy iz" in flow
    assert "restart 4000 flow/restart/flow.*.restart" in flow
    seeds = [int(s) for s in re.findall(r"(?:seed|sphere|discrete) (\d+)", settle)]
    assert len(set(seeds)) == 3 and all(dem_params._is_prime(s) and s > 10000 for s in seeds)
    # The insertion cylinder lies inside the tube, above the plate, below the periodic top.
    match = re.search(r"region fill cylinder z 0.0 0.0 (\S+) (\S+) (\S+)", settle)
    radius, z_lo, z_hi = map(float, match.groups())
    assert radius + D / 2 < R_TUBE and Z_PLATE + D / 2 < z_lo < z_hi < LENGTH - D / 2
    steps = params.steps()
    assert steps["settle_end"] % 500 == 0 and (steps["flow_end"] - steps["settle_end"]) * 1e-5 >= 0.1
    assert f"run {steps['flow_end']} upto" in flow
    assert f"run {steps['insert_end']} upto\nunfix insert" in settle
    assert steps["fill_end"] < steps["insert_end"] < steps["settle_end"] and steps["insert_end"] % steps["insert_every"] == 0


def test_driven_slice_deck_balances_gravity_and_holds_the_velocity():
    """dem.drive: the flow deck balances gravity and relaxes the mean axial velocity to -velocity;
    the orifice plate is left out (no mesh wall at all with the primitive tube); the slice is filled
    over its whole periodic length at dem.fill_solid_fraction."""
    params = DemParams.from_spec(spec_with(drive={"velocity": 0.05, "time_constant": 0.002}, fill_solid_fraction=0.6),
                                 GEOMETRY)  # fmt: skip
    flow = render_decks(params)["flow.in"]
    assert "variable drive_error equal vcm(all,z)+0.05" in flow
    assert "variable drive_force atom mass*(9.81-v_drive_error/0.002)" in flow
    assert "fix drive all addforce 0.0 0.0 v_drive_force" in flow
    assert "mesh/surface" not in flow and "wall/gran" in flow and "zcylinder" in flow
    assert params.n_particles == round(0.6 * math.pi * R_TUBE**2 * LENGTH / (math.pi * D**3 / 6))
    assert "fix drive" not in render_decks(DemParams.from_spec(SPEC, GEOMETRY))["flow.in"]


def test_driven_tube_keeps_its_plate_and_holds_the_mass_flow():
    """dem.drive with mass_flow and orifice: the velocity held is mass_flow x box length / mass of all
    particles (so the mass flow is the same whatever the bed holds), the orifice plate stays a mesh
    wall, the bed is filled to fill_height as for orifice flow, and the controller's acceleration
    is the thermo output's last column."""
    plain = DemParams.from_spec(SPEC, GEOMETRY)
    params = DemParams.from_spec(spec_with(drive={"mass_flow": 0.002, "orifice": True, "time_constant": 3e-5}), GEOMETRY)
    decks = render_decks(params)
    flow = decks["flow.in"]
    assert "zplane" in decks["settle.in"] and "deform" not in decks["settle.in"]  # poured onto the plate, not packed
    assert "variable drive_error equal vcm(all,z)+0.002*lz/mass(all)" in flow
    assert "variable drive_force atom mass*(9.81-v_drive_error/3e-05)" in flow
    assert "variable drive_acceleration equal v_drive_error/3e-05" in flow  # gravity balanced: the force alone
    assert "fix drive_mean all ave/time 1 500 500 v_drive_acceleration" in flow
    assert flow.rstrip().splitlines()[-1].startswith("run ") and "f_ts_check[2] f_drive_mean" in flow
    assert params.mesh_zones == ("orifice",) and params.driven and not params.packed
    assert params.n_particles == plain.n_particles
    with pytest.raises(ConfigError, match="velocity .m/s. or mass_flow"):
        DemParams.from_spec(spec_with(drive={"velocity": 0.01, "mass_flow": 0.002}), GEOMETRY)


def test_a_loaded_slice_can_hold_a_mass_flow_but_a_driven_tube_is_never_loaded():
    """dem.drive.wall_stress with mass_flow: the slice is packed and loaded like one driven at a
    velocity, keeps its weight while it flows, and its net acceleration (the thermo's last column)
    counts gravity; mass_flow x lz, the box's length after the loading shortened it. A driven tube
    with its orifice plate is poured, not packed: a wall stress for it is refused, naming the key."""
    params = DemParams.from_spec(spec_with(drive={"mass_flow": 0.002, "wall_stress": "weight"}, fill_solid_fraction=0.6),
                                 GEOMETRY)  # fmt: skip
    assert params.packed and params.loaded and params.wall_stress > 0
    decks = render_decks(params)
    assert "# Load the bed" in decks["settle.in"]
    flow = decks["flow.in"]
    assert "variable drive_error equal vcm(all,z)+0.002*lz/mass(all)" in flow
    assert "variable drive_force atom mass*(-v_drive_error/" in flow
    assert "variable drive_acceleration equal 9.81+v_drive_error/" in flow
    # Every thermo_style is followed by its thermo_modify (thermo_style resets it).
    for deck in decks.values():
        lines = deck.splitlines()
        styles = [k for k, line in enumerate(lines) if line.startswith("thermo_style")]
        assert styles and all(lines[k + 2].startswith("thermo_modify flush yes lost ignore") for k in styles)
    with pytest.raises(ConfigError, match=r"dem.drive.wall_stress = .* Pa loads a packed slice"):
        DemParams.from_spec(spec_with(drive={"mass_flow": 0.002, "orifice": True, "wall_stress": 100.0}), GEOMETRY)


def test_thermo_rows_keep_the_drive_column_when_asked():
    """A driven flow's table has the controller's acceleration after the usual columns: read with
    DRIVE_COLUMN it is kept under that name, read plainly it is dropped (as a loading's wall stress)."""
    from dpht.dem.liggghts import DRIVE_COLUMN, THERMO_COLUMNS, _ThermoParser

    text = "Step Atoms Time iz_sum z_max ts_check ts_check drive_me\n  100 5 0.001 0 0.01 0.1 0.01 4.5\n"
    row = dict(zip(THERMO_COLUMNS, (100.0, 5.0, 0.001, 0.0, 0.01, 0.1, 0.01)))
    assert _ThermoParser(DRIVE_COLUMN).feed(text) == [{**row, DRIVE_COLUMN: 4.5}]
    assert _ThermoParser().feed(text) == [row]


def test_soft_particles_only_below_liggghts_floor():
    """LIGGGHTS refuses a Young's modulus below 5 MPa in SI units unless told the softening is meant."""
    assert "soft_particles yes" not in render_decks(DemParams.from_spec(SPEC, GEOMETRY))["settle.in"]
    soft = copy.deepcopy(SPEC)
    soft["particles"]["youngs_modulus_dem"] = 1.25e6
    decks = render_decks(DemParams.from_spec(soft, GEOMETRY))
    assert all("soft_particles yes\nfix m1 all property/global youngsModulus" in deck for deck in decks.values())


def test_driven_tube_is_packed_without_a_seam():
    """dem.drive: the settle deck packs the periodic tube (pack.in): all particles inserted at once
    into a box taller by fill_solid_fraction / PACK_INSERT_SOLID_FRACTION, no floor, no gravity,
    frictionless contacts while the box shrinks to the tube's length; the flow deck has the config's
    friction."""
    params = DemParams.from_spec(spec_with(drive={"velocity": 0.05}, fill_solid_fraction=0.6), GEOMETRY)
    decks = render_decks(params)
    settle, flow = decks["settle.in"], decks["flow.in"]
    assert params.packed and params.pack_length == pytest.approx(LENGTH * 0.6 / dem_params.PACK_INSERT_SOLID_FRACTION)
    assert f"0.0 {params.pack_length!r} units box" in settle and "zplane" not in settle and "unfix gravity" in settle
    assert f"particles_in_region {params.n_particles} region fill" in settle
    steps = params.steps()
    assert f"fix squeeze all deform 1 z final 0.0 {LENGTH!r} remap x\nrun {steps['compress_end']} upto\nunfix squeeze" in settle
    assert 0 < steps["compress_end"] < steps["settle_end"] < steps["flow_end"] and steps["settle_end"] % 500 == 0
    for deck, (mu_pp, mu_pw) in ((settle, (0.0, 0.0)), (flow, SPEC["contact"]["friction"].values())):
        assert f"coefficientFriction peratomtypepair 2 {float(mu_pp)!r} {float(mu_pw)!r}" in deck
    assert "coefficientRollingFriction peratomtypepair 2 0.0 0.0 0.0 0.0" in settle
    assert params.z_slabs(2) == 2  # the whole periodic length is bed


def test_loaded_slice_is_packed_with_a_little_friction_then_shortened_until_the_wall_carries_its_stress():
    """dem.drive.wall_stress: the bed packs at PACK_FRICTION, comes to rest, gets the config's friction
    back and is shortened LOAD_INCREMENTS times by LOAD_STRAIN while its wall stress (the Hertz
    overlaps with the cylinder, as dpht.dem.report.wall_stress) is below the target; a fixed number of
    steps. "weight" is Janssen's deep-bed wall stress rho_p phi g D / (4 mu_w)."""
    weightless = DemParams.from_spec(spec_with(drive={"velocity": 0.05}, fill_solid_fraction=0.6), GEOMETRY)
    params = DemParams.from_spec(spec_with(drive={"velocity": 0.05, "wall_stress": "weight"}, fill_solid_fraction=0.6), GEOMETRY)
    rho, mu_w = SPEC["particles"]["density"], SPEC["contact"]["friction"]["pw"]
    assert params.wall_stress == pytest.approx(rho * 0.6 * 9.81 * 2 * R_TUBE / (4 * mu_w), rel=1e-12)
    assert params.loaded and not weightless.loaded and weightless.wall_stress == 0.0
    E_star = 1.0 / ((1 - params.poisson_p**2) / params.youngs_p + (1 - params.poisson_w**2) / params.youngs_w)
    assert params.wall_hertz == pytest.approx(4.0 / 3.0 * E_star * math.sqrt(D / 2), rel=1e-12)
    settle, flow = render_decks(params)["settle.in"], render_decks(params)["flow.in"]
    mu = dem_params.PACK_FRICTION
    assert f"coefficientFriction peratomtypepair 2 {mu!r} {mu!r} {mu!r} {mu!r}" in settle
    restored = [line for line in flow.splitlines() if "coefficient" in line and "Friction" in line]
    load = settle[settle.index("# Load the bed"):]
    assert len(restored) == 2 and all(line in load for line in restored)  # the flow's friction, before shortening
    steps, w = params.steps(), weightless.steps()
    assert steps["rest_end"] == w["settle_end"] and steps["settle_end"] % params.dump_interval == 0
    assert steps["settle_end"] - steps["rest_end"] >= dem_params.LOAD_INCREMENTS * (steps["load_steps"] + steps["load_rest"])
    assert f"variable load_step loop {dem_params.LOAD_INCREMENTS}" in load and "jump SELF load" in load
    assert f"(v_wall_stress<{params.wall_stress!r})" in load and f"{dem_params.LOAD_STRAIN!r}*" in load
    assert load.index("jump SELF load") < load.index(f"run {steps['settle_end']} upto")
    # Flowing, the loaded slice keeps its weight (the wall carries it); a weightless one has gravity balanced.
    assert "variable drive_force atom mass*(-v_drive_error/" in flow
    assert "variable drive_force atom mass*(9.81-v_drive_error/" in render_decks(weightless)["flow.in"]
    # A weightless slice packs frictionless and is not loaded; other beds are never loaded.
    assert "Load the bed" not in render_decks(weightless)["settle.in"] and "v_wall_stress" not in render_decks(weightless)["settle.in"]


def test_thermo_rows_of_a_table_with_extra_columns_keep_their_keys():
    """The loading's thermo table has the wall stress after the usual columns: its rows still count
    (the settle's progress), a table with fewer columns does not."""
    from dpht.dem.liggghts import THERMO_COLUMNS, _ThermoParser

    text = ("Step Atoms Time iz_sum z_max ts_check[1] ts_check[2] wall_stress\n  100 5 0.001 0 0.01 0.1 0.01 150.5\n"
            "Step Atoms Time\n 200 5 0.002\n")
    rows = _ThermoParser().feed(text)
    assert rows == [dict(zip(THERMO_COLUMNS, (100.0, 5.0, 0.001, 0.0, 0.01, 0.1, 0.01)))]


def test_fill_count_matches_the_bed_volume():
    params = DemParams.from_spec(SPEC, GEOMETRY)
    solid = params.n_particles * math.pi * D**3 / 6
    bed = math.pi * R_TUBE**2 * SPEC["dem"]["fill_height"]
    assert solid / bed == pytest.approx(default("dem.fill_solid_fraction"), rel=0.01)


def test_rayleigh_time_scales_as_radius_over_shear_wave_speed():
    # Doubling r doubles it; quadrupling E halves it (t_R ~ r sqrt(rho/G)).
    base = dem_params.rayleigh_time(5e-4, 2500.0, 1e7, 0.25)
    assert dem_params.rayleigh_time(1e-3, 2500.0, 1e7, 0.25) == pytest.approx(2 * base, rel=1e-12)
    assert dem_params.rayleigh_time(5e-4, 2500.0, 4e7, 0.25) == pytest.approx(base / 2, rel=1e-12)


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
        ({"target_mass_flow": -0.01}, "dem.target_mass_flow"),
        ({"target_mass_flow": 0.01, "mass_flow_tolerance": 0.0}, "dem.mass_flow_tolerance"),
    ],
)
def test_bad_dem_config_names_the_key(tmp_path, change, message):
    with pytest.raises(ConfigError, match=message):
        run_dem(spec_with(**change), tube_meshes(tmp_path / "m"), tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)


def test_missing_key_geometry_or_mesh(tmp_path):
    spec = copy.deepcopy(SPEC)
    del spec["contact"]["friction"]["pw"]
    with pytest.raises(ConfigError, match="contact.friction.pw"):
        DemParams.from_spec(spec, GEOMETRY)
    with pytest.raises(DPHTError, match="geometry.json is missing"):
        run_dem(SPEC, tmp_path / "nowhere", tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)
    meshes = tube_meshes(tmp_path / "m")
    (meshes / "orifice.stl").unlink()
    with pytest.raises(DPHTError, match="orifice.stl"):
        run_dem(SPEC, meshes, tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)
    meshes = tube_meshes(tmp_path / "m")
    (meshes / "heated_wall.stl").unlink()  # not needed with the primitive tube wall, needed as a mesh
    with pytest.raises(DPHTError, match="heated_wall.stl"):
        run_dem(spec_with(tube_wall="mesh"), meshes, tmp_path / "w", tmp_path / "p.h5", log=lambda _: None)


def test_geometry_of_another_config_is_refused():
    other = copy.deepcopy(GEOMETRY)
    other["geometry"]["tube"]["orifice_diameter"] = 5.0e-3
    with pytest.raises(DPHTError, match="geometry.tube"):
        DemParams.from_spec(SPEC, other)
    with_plate = copy.deepcopy(SPEC)
    with_plate["geometry"]["mixers"] = [PLATE]
    with pytest.raises(DPHTError, match="geometry.mixers"):
        DemParams.from_spec(with_plate, GEOMETRY)  # built without the plate


PLATE = {"type": "flat_plate", "height": 0.010, "thickness": 0.5e-3, "opening": 0.5}
PLATE_VOLUME = 0.5 * math.pi * R_TUBE**2 * PLATE["thickness"]  # half the cross-section is solid


def test_mixers_get_a_mesh_and_stay_out_of_the_fill():
    spec = copy.deepcopy(SPEC)
    spec["geometry"]["mixers"] = [PLATE]
    bottom, top = PLATE["height"] - PLATE["thickness"], PLATE["height"]
    extent = {"key": "geometry.mixers[0]", "zone": "mixer", "z_range": [bottom, top], "volume": PLATE_VOLUME}
    params = DemParams.from_spec(spec, geometry_summary(spec, [extent]))
    settle = render_decks(params)["settle.in"]
    assert params.mesh_zones == ("orifice", "mixer") and "mesh n_meshes 1 meshes mesh_walls" in settle
    slabs = [tuple(map(float, m)) for m in re.findall(r"region fill_\d cylinder z 0.0 0.0 (\S+) (\S+) (\S+)", settle)]
    assert len(slabs) == 2 and "region fill union 2 fill_1 fill_2" in settle
    for radius, lo, hi in slabs:  # clear of the tube wall, both plates and the periodic top by a radius
        assert radius + D / 2 < R_TUBE
        assert Z_PLATE + D / 2 < lo < hi < LENGTH - D / 2 and (hi < bottom - D / 2 or lo > top + D / 2)
    assert sum(hi - lo for _, lo, hi in slabs) == pytest.approx(LENGTH - Z_PLATE - PLATE["thickness"] - 4 * 0.55 * D)
    # The fill leaves out the plate's solid volume: the bed from the orifice plate up to fill_height holds it.
    plain = DemParams.from_spec(SPEC, GEOMETRY)
    bed = math.pi * R_TUBE**2 * SPEC["dem"]["fill_height"]
    assert params.n_particles == pytest.approx(plain.n_particles * (1 - PLATE_VOLUME / bed), abs=1)
    # A packed slice's box shrinks through the tube: mixers are refused there, kept in a driven tube.
    spec["dem"]["drive"] = {"velocity": 0.05}
    with pytest.raises(ConfigError, match="geometry.mixers .geometry.mixers.0.. would block"):
        DemParams.from_spec(spec, geometry_summary(spec, [extent]))
    spec["dem"]["drive"]["orifice"] = True
    assert DemParams.from_spec(spec, geometry_summary(spec, [extent])).mesh_zones == ("orifice", "mixer")


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
    script = "import sys; from dpht.dem.liggghts import run_liggghts; run_liggghts('long.in', sys.argv[1], sys.argv[2])"
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path), str(tmp_path / "screen.txt")])
    deadline = time.monotonic() + 30
    while not _processes_in(tmp_path.resolve()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _processes_in(tmp_path.resolve()), "LIGGGHTS did not start"
    child.send_signal(signal.SIGTERM)
    assert child.wait(timeout=20) == 128 + signal.SIGTERM
    # mpirun has ended; its ranks end with it (parent-death signal), a moment later.
    deadline = time.monotonic() + 5
    while _processes_in(tmp_path.resolve()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _processes_in(tmp_path.resolve())


def _children(pid: int) -> list[int]:
    return [int(c) for t in Path(f"/proc/{pid}/task").iterdir() for c in (t / "children").read_text().split()]


def _start_long_mpi_run(tmp_path) -> tuple[subprocess.Popen, int, list[int]]:
    """run_liggghts of a deck that never ends, on 2 MPI ranks, in a Python process of its own:
    (that process, mpirun's pid, the ranks' pids)."""
    (tmp_path / "long.in").write_text(
        "units si\natom_style granular\natom_modify sort 0 0.0\n"
        "region box block 0 1 0 1 0 1 units box\ncreate_box 1 box\nrun 2000000000\n"
    )
    script = ("import sys; from dpht.dem.liggghts import run_liggghts; "
              "run_liggghts('long.in', sys.argv[1], sys.argv[2], ranks=2)")  # fmt: skip
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path), str(tmp_path / "screen.txt")])
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        ranks = [r for m in _children(child.pid) for r in _children(m)]
        if len(ranks) >= 2:
            (mpirun,) = _children(child.pid)
            return child, mpirun, ranks
        time.sleep(0.05)
    child.kill()
    raise AssertionError("mpirun did not start two ranks")


def _seconds_until_gone(pids, timeout=20.0) -> float:
    start = time.monotonic()
    while any(Path(f"/proc/{p}").exists() and Path(f"/proc/{p}/stat").read_text().split()[2] != "Z" for p in pids):
        assert time.monotonic() - start < timeout, f"{pids} still running {timeout} s later"
        time.sleep(0.01)
    return time.monotonic() - start


@needs_liggghts
def test_mpirun_and_its_ranks_die_with_a_killed_stage(tmp_path):
    # SIGKILL of the Python process alone (no clean-up runs): the kernel sends mpirun SIGTERM
    # (PR_SET_PDEATHSIG), which stops the ranks.
    child, mpirun, ranks = _start_long_mpi_run(tmp_path)
    child.kill()
    child.wait()
    seconds = _seconds_until_gone([mpirun, *ranks])
    print(f"stage SIGKILLed: mpirun and its ranks ended {seconds:.2f} s later")


@needs_liggghts
def test_ranks_die_with_a_killed_mpirun(tmp_path):
    child, mpirun, ranks = _start_long_mpi_run(tmp_path)
    try:
        os.kill(mpirun, signal.SIGKILL)
        seconds = _seconds_until_gone(ranks, timeout=1.0)  # ~1 s without setpriv --pdeathsig, 5-25 ms with it
        print(f"mpirun SIGKILLed: its ranks ended {seconds:.3f} s later")
        assert child.wait(timeout=20) == 1  # run_liggghts reports LIGGGHTS killed (ExternalToolError)
    finally:
        child.kill()


BOX_DECK = "units si\natom_style granular\nboundary f f p\nprocessors * * ${pz}\nregion box block 0 1 0 1 0 4 units box\ncreate_box 1 box\n"


@needs_liggghts
def test_the_mpi_launcher_comes_from_the_caller_and_must_exist(tmp_path):
    (tmp_path / "box.in").write_text(BOX_DECK)
    run_liggghts("box.in", tmp_path, tmp_path / "screen.txt", ranks=2, mpi="mpirun", variables={"pz": "2"})
    assert "1 by 1 by 2 MPI processor grid" in (tmp_path / "screen.txt").read_text()
    with pytest.raises(ExternalToolError, match=r"MPI launcher 'no-such-srun --mpi=pmix' \(the rule's resources.mpi\)"):
        run_liggghts("box.in", tmp_path, tmp_path / "screen.txt", ranks=2, mpi="no-such-srun --mpi=pmix")


@needs_liggghts
def test_a_launcher_that_starts_unconnected_copies_is_caught(tmp_path):
    """What srun does with an MPI built for another PMI: N serial copies instead of one N-rank job."""
    launcher = tmp_path / "copies"
    launcher.write_text('#!/bin/sh\nn=$2; shift 2\nfor i in $(seq "$n"); do "$@" & done\nwait\n')
    launcher.chmod(0o755)
    (tmp_path / "box.in").write_text(BOX_DECK)
    with pytest.raises(ExternalToolError, match="1 x 1 x 1 processor grid but 2 ranks were launched"):
        run_liggghts("box.in", tmp_path, tmp_path / "screen.txt", ranks=2, mpi=str(launcher), variables={"pz": "1"})


def test_axis_slabs_unless_the_bed_fills_only_part_of_the_tube():
    spec = copy.deepcopy(SPEC)  # the default scene's tube: 50 mm periodic, orifice plate at 4 mm
    spec["geometry"]["tube"].update(length=0.05, orifice_height=0.004, heated=[0.004, 0.04])
    spec["dem"]["fill_height"] = 0.042  # a bed from 4 to 46 mm: slabs along the axis
    tube = DemParams.from_spec(spec, geometry_summary(spec))
    assert [tube.z_slabs(r) for r in (1, 2, 3, 4, 8, 12)] == [1, 2, 3, 4, 8, 12]
    assert tube.z_slabs(16) == 8  # 16 slabs would be 3.1 mm thin (< 4 d): 8 slabs, 2 ranks per slab
    spec["dem"]["fill_height"] = 0.014  # 4 to 18 mm: one slab of two would hold the whole bed
    assert [DemParams.from_spec(spec, geometry_summary(spec)).z_slabs(r) for r in (2, 4)] == [1, 1]


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
    return dem_scene.short_run(tmp_path_factory)


@needs_liggghts
@pytest.mark.slow
def test_short_run_flows_through_the_orifice(short_run):
    root, _, summary, lines, seconds = short_run
    params = DemParams.from_spec(SPEC, GEOMETRY)
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
    beverloo = 0.58 * default("dem.fill_solid_fraction") * 3560.0 * math.sqrt(9.81) * (2 * R_HOLE - 1.5 * D) ** 2.5
    assert 0.5 < summary["mass_flow_second_half_kg_s"] / beverloo < 3.0
    # LIGGGHTS' own Rayleigh-time check (fix check/timestep/gran) agrees with ours.
    assert summary["rayleigh_fraction_liggghts"] == pytest.approx(summary["rayleigh_fraction"], rel=1e-6)
    bed = summary["bed_top_settled_m"] - Z_PLATE
    assert bed == pytest.approx(SPEC["dem"]["fill_height"], rel=0.25)
    # The settled bed is a random packing (between random loose, ~0.55, and random close, 0.64),
    # looser in the particle diameter at the wall, which no sphere can cross.
    settled = summary["solid_fraction"]["settled"]
    assert 0.5 < settled["bulk"] < 0.64 and settled["near_wall"] < settled["bulk"]
    assert summary["mixers"] == []
    # What the thermal stage needs to see what the DEM saw: the surface of each wall zone, and the
    # axis that only recycles particles (no heat across it).
    assert summary["walls"] == {"heated_wall": "primitive", "adiabatic_wall": "primitive", "orifice": "mesh"}
    with PositionsFile(root / "positions.h5") as f:
        assert f.attrs["recycled"].tolist() == [False, False, True] and f.attrs["periodic"].tolist() == [False, False, True]
    # Tagged with the stage key, the folder of the positions file.
    assert any(f"DEM {root.name} flow: step" in line and "ETA" in line for line in lines)


@needs_liggghts
@pytest.mark.slow
def test_a_static_bed_settles_only(short_run, tmp_path):
    """dem.flow_time 0: no flow phase; the one frame is the settled bed, the very bed the flowing run
    (same decks up to the settling) starts its flow from, bit for bit."""
    root, meshes, _, _, _ = short_run
    lines = []
    summary = run_dem(spec_with(flow_time=0.0), meshes, tmp_path / "work", tmp_path / "positions.h5", ranks=1,
                      log=lines.append)  # fmt: skip
    assert not (tmp_path / "work" / "flow").exists() and any("a static bed: no flow phase" in line for line in lines)
    assert summary["frames"] == 1 and summary["flow_attempts"] == [] and summary["wall_time_s"]["flow"] == 0
    assert summary["mass_flow_kg_s"] == 0 and summary["orifice_crossings"] == 0 and not summary["jammed"]
    with PositionsFile(tmp_path / "positions.h5") as static, PositionsFile(root / "positions.h5") as flowing:
        assert static.n_frames == 1 and static.steps[0] == flowing.steps[0]
        np.testing.assert_array_equal(static.frame(0).positions, flowing.frame(0).positions)
        np.testing.assert_array_equal(static.frame(0).image, flowing.frame(0).image)


@needs_liggghts
@pytest.mark.slow
def test_rerun_is_a_no_op_and_decks_stay_for_inspection(short_run):
    root, meshes, summary, _, _ = short_run
    lines = []
    start = time.monotonic()
    again = run_dem(SPEC, meshes, root / "work", root / "positions.h5", ranks=1, log=lines.append)
    assert again == summary and time.monotonic() - start < 5
    assert any("up to date" in line for line in lines)
    decks = render_decks(DemParams.from_spec(SPEC, GEOMETRY))
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


@needs_liggghts
@pytest.mark.slow
def test_mass_flow_target_is_checked_without_rerunning(short_run):
    root, meshes, summary, _, _ = short_run
    measured = summary["mass_flow_second_half_kg_s"]

    def run(spec):
        lines = []
        result = run_dem(spec, meshes, root / "work", root / "positions.h5", ranks=1, log=lines.append)
        assert any("up to date" in line for line in lines)  # LIGGGHTS did not run again
        return result, lines

    near, lines = run(spec_with(target_mass_flow=1.05 * measured))
    assert near["mass_flow_target"]["off_target"] is False and not any("DEM warning" in line for line in lines)
    far, lines = run(spec_with(target_mass_flow=1.5 * measured, mass_flow_tolerance=0.2))
    assert far["mass_flow_target"]["off_target"] is True
    assert far["mass_flow_target"]["relative_error"] == pytest.approx(1 / 1.5 - 1)
    assert any("DEM warning: mass flow" in line and "-33.3%" in line for line in lines)
    with PositionsFile(root / "positions.h5") as f:  # a check, not a result: never written into it
        assert "mass_flow_target" not in f.summary
    restored, _ = run(SPEC)
    assert restored == summary and restored["mass_flow_target"] is None


def _copy_of(short_run, folder: Path) -> tuple[Path, Path, Path]:
    """The short run's meshes, work directory and positions file copied to ``folder`` (the positions
    file a copy of its work copy, as the stage leaves them)."""
    root = short_run[0]
    shutil.copytree(root / "meshes", folder / "meshes")
    shutil.copytree(root / "work", folder / "work")
    shutil.copyfile(folder / "work" / "positions.h5", folder / "positions.h5")
    return folder / "meshes", folder / "work", folder / "positions.h5"


@needs_liggghts
@pytest.mark.slow
def test_deleted_output_is_published_again_without_liggghts(short_run, tmp_path):
    # Snakemake deletes a job's outputs before it runs it again (after an interruption, say just
    # after the positions file was written): the complete work copy is published again.
    meshes, workdir, out = _copy_of(short_run, tmp_path)
    published, work = short_run[0] / "positions.h5", short_run[0] / "work" / "positions.h5"
    assert published.read_bytes() == work.read_bytes() and not os.path.samefile(published, work)  # never a hard link
    out.unlink()
    lines = []
    summary = run_dem(SPEC, meshes, workdir, out, ranks=1, log=lines.append)
    assert any("complete" in line and "earlier run" in line for line in lines), lines
    assert not any("DEM settle" in line or "DEM flow" in line for line in lines)
    assert summary == short_run[2] and out.read_bytes() == (workdir / "positions.h5").read_bytes()
    assert out.stat().st_mtime > (workdir / "flow" / "state.json").stat().st_mtime  # newer than its inputs


@needs_liggghts
@pytest.mark.slow
def test_truncated_positions_file_is_regenerated(short_run, tmp_path):
    meshes, workdir, out = _copy_of(short_run, tmp_path)
    with h5py.File(out) as f:
        digest = f.attrs["content_sha256"]
    for file in (out, workdir / "positions.h5"):  # the published file and its work copy both cut in place
        with open(file, "r+b") as f:
            f.truncate(file.stat().st_size // 2)
    lines = []
    summary = run_dem(SPEC, meshes, workdir, out, ranks=1, log=lines.append)
    assert any("damaged; running it again" in line for line in lines), lines
    assert any("reusing the settled bed" in line for line in lines)
    assert summary["orifice_crossings"] == short_run[2]["orifice_crossings"]
    with h5py.File(out) as f:  # serial LIGGGHTS is reproducible: the very file again
        assert f.attrs["content_sha256"] == digest


# --- mixers: a flat plate in a short 9 mm tube (1 mm particles) --------------------------------

PLATE_SPEC = copy.deepcopy(SPEC)
PLATE_SPEC["geometry"] = {
    "tube": {
        "inner_diameter": 9.0e-3,
        "length": 0.024,
        "orifice_height": Z_PLATE,
        "orifice_diameter": 7.0e-3,
        "heated": [Z_PLATE, 0.024],
    },
    # 0.3 (a 3.06 d wide segment) jams 1 mm particles within 0.3 s, 0.5 (4.5 d) within ~1 s.
    "mixers": [{**PLATE, "height": 0.011, "opening": 0.65}],
    "mesh_size": 1.0,
}
PLATE_SPEC["dem"].update(fill_height=0.016, settle_time=0.05, flow_time=0.15)


@pytest.fixture(scope="module")
def plate_run(tmp_path_factory):
    from dpht.geometry import build

    root = tmp_path_factory.mktemp("plate")
    geometry = build(PLATE_SPEC["geometry"], D, root / "geometry")
    start = time.monotonic()
    summary = run_dem(PLATE_SPEC, root / "geometry", root / "work", root / "positions.h5", ranks=1, log=lambda _: None)
    return root, geometry, summary, time.monotonic() - start


@needs_liggghts
@pytest.mark.slow
def test_particles_flow_through_the_flat_plate(plate_run):
    root, geometry, summary, seconds = plate_run
    assert seconds < 60
    plate = PLATE_SPEC["geometry"]["mixers"][0]
    top, bottom = plate["height"], plate["height"] - plate["thickness"]
    (mixer,) = summary["mixers"]
    assert mixer["z_range_m"] == pytest.approx([bottom, top]) and mixer["zone"] == "mixer"
    assert summary["particles"] == summary["particles_inserted"] == summary["particles_target"]
    assert summary["lost_particles"]["count"] == 0 and not summary["jammed"]
    # Particles pass the plate: more than four bed layers (67 particles per mm of bed height) in
    # 0.15 s, and the count balances against the orifice's: passages through the plate - through
    # z = 0 = growth of the population between the two.
    assert mixer["crossings"] > 270
    sagitta = geometry["mixers"][0]["passages"][0]["width"]  # the opening: x > R - sagitta (orientation 0)
    with PositionsFile(root / "positions.h5") as f:
        first, last = f.frame(0), f.frame(-1)
        below = [np.count_nonzero(frame.positions[:, 2] < bottom) for frame in (first, last)]
        assert mixer["crossings"] - summary["orifice_crossings"] == below[1] - below[0]
        # No centre comes closer than 0.45 d to the plate's solid part: it holds like a wall.
        for frame in f.frames():
            x, z = frame.positions[:, 0], frame.positions[:, 2]
            over_solid = x < 4.5e-3 - sagitta - 0.45 * D
            assert not np.any(over_solid & (z > bottom - 0.45 * D) & (z < top + 0.45 * D))
    # The report samples the bed above and below the plate. Settled: a random packing, looser at the
    # wall. The plate passes less than the orifice: in flow the bed under it drains loose, far more
    # than the bed over it.
    report = summary["solid_fraction"]
    below, above = report["by_interval"]
    assert below["z_m"][1] <= bottom - 2 * D and above["z_m"][0] >= top + 2 * D
    assert 0.5 < report["settled"]["bulk"] < 0.64 and report["settled"]["near_wall"] < report["settled"]["bulk"]
    assert below["flowing"]["bulk"] < 0.5 * below["settled"]["bulk"] < above["flowing"]["bulk"]


# --- mixers: a radial mixer (funnel + 3 small tubes) in a short 6 mm tube (0.37 mm particles) ----

D_SMALL = 0.37e-3
RADIAL = {"type": "radial", "height": 0.006, "outlet_diameter": 2.2e-3, "angle": 30.0, "wall_thickness": 0.2e-3,
          "n_tubes": 3, "tube_diameter": 1.4e-3, "inclination": 75.0, "tube_inlet_radius": 1.9e-3}
RADIAL_SPEC = copy.deepcopy(SPEC)
RADIAL_SPEC["particles"]["diameter"] = D_SMALL
RADIAL_SPEC["geometry"] = {
    "tube": {"inner_diameter": 6.0e-3, "length": 0.010, "orifice_height": 0.0015, "orifice_diameter": 4.5e-3,
             "heated": [0.0015, 0.010]},
    "mixers": [RADIAL],
    "mesh_size": 1.0,
}
# The fill phase (three times the insertion time) settles the bed too; dumps every 1 ms resolve the
# particles' way through the mixer (they move ~0.1 mm between dumps).
RADIAL_SPEC["dem"].update(timestep=4.0e-6, fill_height=0.005, settle_time=0.005, flow_time=0.05,
                          dump_interval=250, restart_interval=5000)


def _downward_crossings(positions: PositionsFile, level: float, length: float) -> np.ndarray:
    """(x, y) (m) where particles passed down through the plane z = level (mod length) between
    consecutive frames, linearly interpolated."""
    found, previous = [], None
    for frame in positions.frames():
        z = frame.positions[:, 2] + frame.image[:, 2] * length
        if previous is not None:
            z0, xy0 = previous
            sheet = np.floor((z0 - level) / length)
            passed = np.floor((z - level) / length) < sheet  # at most one lap between dumps
            t = (z0[passed] - level - sheet[passed] * length) / (z0[passed] - z[passed])
            found.append(xy0[passed] + t[:, None] * (frame.positions[passed, :2] - xy0[passed]))
        previous = (z, frame.positions[:, :2])
    return np.concatenate(found)


@needs_liggghts
@pytest.mark.slow
def test_particles_pass_the_radial_mixer_tubes_and_funnel(tmp_path):
    from dpht.geometry import build
    from dpht.geometry.mixers import mixers_from_config
    from dpht.geometry.tube import Tube

    geometry_cfg = RADIAL_SPEC["geometry"]
    build(geometry_cfg, D_SMALL, tmp_path / "geometry")
    summary = run_dem(RADIAL_SPEC, tmp_path / "geometry", tmp_path / "work", tmp_path / "positions.h5", ranks=2,
                      log=lambda _: None)
    assert summary["lost_particles"]["count"] == 0 and summary["mixers"][0]["crossings"] > 100
    tube = Tube.from_config(geometry_cfg["tube"], D_SMALL, 3.0, D_SMALL)
    (mixer,) = mixers_from_config(geometry_cfg["mixers"], tube, D_SMALL, 3.0)
    length = geometry_cfg["tube"]["length"]
    with PositionsFile(tmp_path / "positions.h5") as f:
        # Through the funnel: down across the middle of its outlet band, inside the outlet radius.
        outlet = _downward_crossings(f, mixer.funnel_bottom + 0.5 * mixer.dz, length)
        assert np.count_nonzero(np.hypot(outlet[:, 0], outlet[:, 1]) < mixer.outlet_radius) > 50
        # Through each small tube: down across its mid-height within a bore radius of its axis.
        for azimuth in mixer.azimuths():
            inlet, exit_ = mixer.tube_axis(azimuth)
            middle = 0.5 * (inlet + exit_)
            passed = _downward_crossings(f, middle[2], length)
            assert np.count_nonzero(np.hypot(*(passed - middle[:2]).T) < mixer.bore_radius) >= 3, azimuth


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
    # A longer flow than the short run's (the settled bed is the same): time to see the first
    # restart in LIGGGHTS' block-buffered screen file before the run ends on a quiet machine.
    spec = copy.deepcopy(SPEC)
    spec["dem"]["flow_time"] = 0.3
    meshes = tube_meshes(tmp_path / "meshes")
    workdir, out = tmp_path / "work", tmp_path / "positions.h5"
    # Start from the short run's settled bed (same spec and meshes), which also checks it is reused.
    shutil.copytree(short_run[0] / "work" / "settle", workdir / "settle")
    ranks = 2 if (os.cpu_count() or 1) >= 2 else 1
    steps = DemParams.from_spec(spec, GEOMETRY).steps()
    first_restart = dem_params._ceil_to(steps["settle_end"] + 1, spec["dem"]["restart_interval"])
    script = (
        "import json, sys; from dpht.dem.liggghts import run_dem; "
        "run_dem(json.loads(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], ranks=int(sys.argv[5]))"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", script, json.dumps(spec), str(meshes), str(workdir), str(out), str(ranks)],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    screen = workdir / "flow" / "screen.1.txt"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and child.poll() is None:
        reached = max((int(r["step"]) for r in read_thermo(screen)), default=0)
        if reached >= first_restart + 3 * spec["dem"]["dump_interval"]:
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
    summary = run_dem(spec, meshes, workdir, out, ranks=ranks, log=lines.append)
    resumed = [int(m.group(1)) for line in lines if (m := re.search(r"resuming from .* \(step (\d+)", line))]
    assert len(resumed) == 1 and steps["settle_end"] < resumed[0] <= stale
    assert any("reusing the settled bed" in line for line in lines)
    assert summary["flow_attempts"] == [steps["settle_end"], resumed[0]]
    with PositionsFile(out) as f:
        np.testing.assert_array_equal(f.steps, np.arange(steps["settle_end"], steps["flow_end"] + 1, 500))
        assert f.n_particles == summary["particles_inserted"]
        np.testing.assert_array_equal(f.ids, np.arange(1, f.n_particles + 1))
        assert not any(frame.lost.any() for frame in f.frames())
        from_dumps = {int(step): -int(f.frame(k).image[:, 2].sum()) for k, step in enumerate(f.steps)}
    # One count of the mass flow: LIGGGHTS' (the progress lines) equals the dumps' at every dump
    # step of both attempts, the resumed one included (it lagged by the particles not yet wrapped).
    printed = {}
    for attempt, start in enumerate(summary["flow_attempts"], 1):
        end = summary["flow_attempts"][attempt] if attempt < len(summary["flow_attempts"]) else steps["flow_end"] + 1
        rows = read_thermo(workdir / "flow" / f"screen.{attempt}.txt")
        printed.update({int(r["step"]): -int(r["iz_sum"]) for r in rows if start <= r["step"] < end})
    assert printed == from_dumps
    assert from_dumps[steps["flow_end"]] == summary["orifice_crossings"] > 0


def test_progress_gives_the_eta_at_the_rate_since_the_first_row():
    """A resumed flow (from step 1000 of 0..5000) at 100 steps per wall second: the ETA counts the
    steps left at the rate measured in this run, not from step 0."""
    from dpht.dem.liggghts import _Progress

    now, lines = [0.0], []
    progress = _Progress("flow", 0, 5000, 1.0e-5, lines.append, clock=lambda: now[0])
    for t, step in ((0.0, 1000), (20.0, 3000), (40.0, 5000)):
        now[0] = t
        progress({"step": step, "atoms": 10, "iz_sum": -3})
    assert "step 1000/5000" in lines[0] and lines[0].endswith("elapsed 0:00:00, ETA ?")
    assert "t = 0.030/0.050 s" in lines[1] and lines[1].endswith("elapsed 0:00:20, ETA 0:00:20")
    assert lines[2].endswith("elapsed 0:00:40, ETA 0:00:00")


@needs_liggghts
def test_an_interrupted_settle_resumes_from_its_newest_restart_file(tmp_path):
    """The settle used to start again from step 0 (it wrote no restart file): SIGKILL the stage once a
    settle restart file is complete, run it again: it continues from that file, to the same end."""
    spec = spec_with(settle_time=0.08, restart_interval=1000, flow_time=0.0)
    meshes = tube_meshes(tmp_path / "meshes", spec)
    script = ("import json, sys; from dpht.dem.liggghts import run_dem; "
              "run_dem(json.loads(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], ranks=1)")  # fmt: skip
    work, out = tmp_path / "work", tmp_path / "positions.h5"
    child = subprocess.Popen([sys.executable, "-c", script, json.dumps(spec), str(meshes), str(work), str(out)],
                             start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    deadline = time.monotonic() + 300
    steps = DemParams.from_spec(spec, geometry_summary(spec)).steps()
    while time.monotonic() < deadline and child.poll() is None:
        restarts = sorted(work.glob("settle/restart/settle.*.restart"))
        reached = max((int(r["step"]) for r in read_thermo(work / "settle" / "screen.txt")), default=0)
        if restarts and reached >= int(restarts[0].name.split(".")[1]) + 500:
            break
        time.sleep(0.1)
    assert child.poll() is None, "the settle ended before it could be killed"
    os.killpg(child.pid, signal.SIGKILL)
    child.wait()
    deadline = time.monotonic() + 10
    while _processes_in(work.resolve()) and time.monotonic() < deadline:
        time.sleep(0.1)
    killed_at = max(int(r["step"]) for r in read_thermo(work / "settle" / "screen.txt"))
    assert killed_at < steps["settle_end"]
    lines = []
    summary = run_dem(spec, meshes, work, out, ranks=1, log=lines.append)
    resumed = [line for line in lines if "DEM settle: resuming from settle/restart/settle." in line]
    assert resumed, lines
    start = int(re.search(r"settle\.(\d+)\.restart", resumed[0]).group(1))
    assert steps["insert_end"] <= start <= killed_at
    second = read_thermo(work / "settle" / "screen.2.txt")
    assert int(second[0]["step"]) == start and int(second[-1]["step"]) == steps["settle_end"]
    assert summary["particles"] == spec["dem"].get("n_particles", summary["particles"]) and summary["frames"] == 1
    assert json.loads((work / "settle" / "state.json").read_text())["attempts"] == 2
    # The resumed settle ends in the very bed an uninterrupted one settles to.
    run_dem(spec, meshes, tmp_path / "again", tmp_path / "again.h5", ranks=1, log=lambda line: None)
    settled = f"settle/post/dump.{steps['settle_end']}.txt"
    assert (work / settled).read_bytes() == (tmp_path / "again" / settled).read_bytes()


@needs_liggghts
def test_a_settled_restart_without_its_record_is_not_reused(tmp_path):
    """Killed after LIGGGHTS wrote the settled bed but before the stage recorded it complete: the
    settle resumes (from the inserted bed) instead of reading a record that was never written."""
    spec = spec_with(settle_time=0.08, flow_time=0.0)
    meshes = tube_meshes(tmp_path / "meshes", spec)
    work = tmp_path / "work"
    run_dem(spec, meshes, work, tmp_path / "positions.h5", ranks=1, log=lambda line: None)
    state = work / "settle" / "state.json"
    state.write_text(json.dumps({"key": json.loads(state.read_text())["key"], "complete": False}))
    (tmp_path / "positions.h5").unlink()
    (work / "positions.h5").unlink(missing_ok=True)
    lines = []
    run_dem(spec, meshes, work, tmp_path / "positions.h5", ranks=1, log=lines.append)
    assert any("DEM settle: resuming from settle/restart/settle." in line for line in lines), lines
