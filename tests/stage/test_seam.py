"""No heat across the recycling seam: an axis the DEM is periodic along only to recycle particles
(the tube's z: out through the orifice, back in at the top) is open for heat in the thermal stage;
an axis marked physically periodic stays periodic (dpht.thermal.schedule.Schedule)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dpht.dem.dumps import DumpFrame, PositionsFile, write_positions
from dpht.errors import DPHTError
from dpht.thermal import modes, stage
from dpht.thermal.schedule import Schedule
from dpht.verification import scenes
from dpht.geometry.walls import Walls
from test_thermal_stage import write_inputs
from test_wall_surfaces import cylinder

R = scenes.RADIUS
R_TUBE, LENGTH = 8 * R, 24 * R
T_COLD, T_HOT = 300.0, 900.0


def layers(rng):
    """Two touching layers, one just below the top of the box, one just above its bottom: across
    the seam they touch; through the box they are 20 radii apart, beyond every cutoff."""
    points = []
    for z in (1.0 * R, LENGTH - 1.0 * R):
        rho = np.sqrt(rng.uniform(0, (R_TUBE - 1.2 * R) ** 2, 40))
        phi = rng.uniform(0, 2 * np.pi, 40)
        points.append(np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z + rng.uniform(-0.02, 0.02, 40) * R]))
    return np.vstack(points)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A tube whose top quarter is heated; the bed is the two layers, at rest for 12 frames."""
    folder = tmp_path_factory.mktemp("seam")
    positions = layers(np.random.default_rng(0))
    lo, hi = np.array([-R_TUBE, -R_TUBE, 0.0]), np.array([R_TUBE, R_TUBE, LENGTH])
    ids = np.arange(1, len(positions) + 1)
    frames = [DumpFrame(k * 1000, lo, hi, (False, False, True), ids, positions, np.zeros(positions.shape, np.int32)) for k in range(12)]
    for name, recycled in (("recycled", [False, False, True]), ("periodic", [False, False, False])):
        write_positions(folder / f"{name}.h5", frames, radius=R, density=3560.0, timestep=1e-5, dump_interval=1000,
                        attrs={"recycled": recycled})  # fmt: skip
    parts = [cylinder(0.0, 0.75 * LENGTH), cylinder(0.75 * LENGTH, LENGTH)]
    walls = Walls.from_vertices(np.concatenate(parts), np.repeat([0, 1], [len(p) for p in parts]), ["cold_part", "hot_part"])
    s = scenes.spec([m.name for m in modes.MODES], walls={"cold_part": "adiabatic", "hot_part": {"temperature": T_HOT}},
                    initial_temperature=T_COLD, inlet_temperature=T_COLD)  # fmt: skip
    return folder, s, write_inputs(folder, walls, s), positions


def run(scene, positions_name):
    folder, s, tables, positions = scene
    out = folder / f"{positions_name}_thermal.h5"
    stage.run(s, folder / f"{positions_name}.h5", folder / "walls.h5", tables, out, rdf_table=folder / "rdf.h5")
    with h5py.File(out) as f:
        return f["temperature"][...], positions


def test_no_heat_crosses_the_recycling_seam(scene):
    """The wall heats the top layer; the bottom layer, whose only neighbours lie across the seam,
    stays exactly at its initial temperature."""
    T, positions = run(scene, "recycled")
    bottom = positions[:, 2] < 0.5 * LENGTH
    assert np.all(T[-1, bottom] == np.float32(T_COLD))
    assert np.all(T[-1, ~bottom] > T_COLD)


def test_a_physically_periodic_axis_stays_periodic_for_heat(scene):
    """The same bed with z marked physically periodic: the bottom layer takes heat across the
    boundary from the top one (what the tube's recycling seam did before)."""
    T, positions = run(scene, "periodic")
    bottom = positions[:, 2] < 0.5 * LENGTH
    assert np.count_nonzero(T[-1, bottom] > T_COLD) >= 0.9 * bottom.sum() and T[-1, bottom].mean() > T_COLD + 1e-4


def test_the_schedule_separates_recycled_from_periodic_axes(scene):
    folder = scene[0]
    with PositionsFile(folder / "recycled.h5") as dem:
        schedule = Schedule.of(dem, 1)
    assert schedule.periodic.tolist() == [False, False, False] and schedule.flow_axis == 2
    with PositionsFile(folder / "periodic.h5") as dem:
        schedule = Schedule.of(dem, 1)
    assert schedule.periodic.tolist() == [False, False, True] and schedule.flow_axis is None
    with h5py.File(folder / "periodic.h5", "r+") as f:
        f.attrs["recycled"] = [True, False, False]  # x is not periodic at all
    with PositionsFile(folder / "periodic.h5") as dem, pytest.raises(DPHTError, match="recycled axes"):
        Schedule.of(dem, 1)
