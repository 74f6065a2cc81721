"""The ParaView export (dpht.export, ``python -m dpht export``) of a small thermal run made here with
the stages' own writers (positions: dpht.dem.dumps, walls: geometry.walls, thermal: dpht.thermal.output),
read back with VTK's readers through pyvista after the folder was moved elsewhere."""

import json
import shutil

import h5py
import numpy as np
import pytest

from dpht.__main__ import main
from dpht.dem import dumps
from dpht.export import FORMAT, Sources, export, find_sources
from dpht.errors import DPHTError
from dpht.thermal.modes import PW_MODES
from dpht.thermal.output import Row, ThermalWriter
from dpht.geometry.walls import Walls, load_walls, save_walls

pv = pytest.importorskip("pyvista")

RADIUS, TUBE, LENGTH = 5e-4, 4e-3, 0.02  # m
N, DEM_FRAMES, STRIDE = 40, 5, 2  # particles, positions frames, thermal.frame_stride
THERMAL_FRAMES = list(range(0, DEM_FRAMES, STRIDE))  # 0, 2, 4
WALL_CONDITIONS = {"heated": {"temperature": "900 + 1000 * z"}, "adiabatic": "adiabatic"}  # K, z in m
LOST = (3, 7)  # (DEM frame, particle index): missing from that dump


def tube(n_theta=8, n_z=4):
    """A faceted tube, its lower half the zone "heated", the upper "adiabatic"."""
    theta = np.linspace(0.0, 2 * np.pi, n_theta + 1)
    ring = TUBE * np.column_stack([np.cos(theta), np.sin(theta)])
    z = np.linspace(0.0, LENGTH, n_z + 1)
    triangles, zone = [], []
    for k, (z0, z1) in enumerate(zip(z[:-1], z[1:])):
        for (x0, y0), (x1, y1) in zip(ring[:-1], ring[1:]):
            a, b, c, d = (x0, y0, z0), (x1, y1, z0), (x1, y1, z1), (x0, y0, z1)
            triangles += [(a, c, b), (a, d, c)]  # normals towards the axis
            zone += [int(k >= n_z // 2)] * 2
    return Walls.from_vertices(np.array(triangles), np.array(zone), ("heated", "adiabatic"))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """results/ of one variant "base": geometry, DEM and thermal runs and the variant's summary."""
    results = tmp_path_factory.mktemp("export") / "results"
    rng = np.random.default_rng(3)
    walls = tube()
    folders = {stage: results / stage / f"{stage[0]}0000000000a" for stage in ("geometry", "dem", "thermal")}
    for folder in folders.values():
        folder.mkdir(parents=True)
    save_walls(folders["geometry"] / "walls.h5", walls, json.dumps({"synthetic": True}), 2 * RADIUS)

    ids = np.arange(101, 101 + N, dtype=np.int64)
    x = np.column_stack([rng.uniform(-2e-3, 2e-3, (N, 2)), rng.uniform(0.001, 0.019, N)])
    lo, hi = np.array([-TUBE, -TUBE, 0.0]), np.array([TUBE, TUBE, LENGTH])
    centres, frames = [], []
    for k in range(DEM_FRAMES):
        centres.append(x - [0.0, 0.0, 1e-4 * k])  # moving down
        keep = np.ones(N, bool)
        if k == LOST[0]:
            keep[LOST[1]] = False
        frames.append(dumps.DumpFrame(100 * k, lo, hi, (False, False, True), ids[keep], centres[k][keep],
                                      np.zeros((int(keep.sum()), 3), np.int32)))  # fmt: skip
    positions = folders["dem"] / "positions.h5"
    dumps.write_positions(positions, frames, radius=RADIUS, density=2500.0, timestep=1e-4, dump_interval=100)

    times = 0.01 * np.array(THERMAL_FRAMES, float)
    temperature = 300.0 + rng.uniform(0.0, 500.0, (len(times), N))
    element_heat = rng.normal(0.0, 1e-3, (len(times), len(walls), len(PW_MODES)))
    element_heat[:, walls.zone_mask("adiabatic")] = 0.0
    writer = ThermalWriter(folders["thermal"] / "thermal.h5", ids=ids, dem_frames=THERMAL_FRAMES,
                           n_elements=len(walls), attrs={"modes": json.dumps(["pw_contact"]), "positions": "positions.h5",
                                  "spec": json.dumps({"thermal": {"walls": WALL_CONDITIONS}})})  # fmt: skip
    for k, t in enumerate(times):
        T = temperature[k].astype(np.float32)
        if THERMAL_FRAMES[k] == LOST[0]:
            T[LOST[1]] = np.nan
        writer.write(k, Row(float(t), T, element_heat[k].astype(np.float32), 1, 0.0, 0.0, 0.0))
    writer.finish({})
    keys = {stage: folder.name for stage, folder in folders.items()}
    (results / "run" / "base").mkdir(parents=True)  # a run's variant folder (dpht.paths)
    (results / "run" / "base" / "summary.json").write_text(json.dumps({"stage_keys": {**keys, "pfp": None}}))
    return {"results": results, "folders": folders, "walls": walls, "ids": ids, "centres": centres, "times": times}


def test_export_reads_back_after_the_folder_moved(run, tmp_path):
    results = run["results"]
    assert main(["export", str(results / "run" / "base")]) == 0
    moved = tmp_path / "elsewhere" / "paraview"
    shutil.copytree(results / "run" / "base" / "paraview", moved)
    shutil.rmtree(results / "run" / "base" / "paraview")  # nothing in the copy may point back

    walls, times = run["walls"], run["times"]
    with h5py.File(run["folders"]["thermal"] / "thermal.h5") as f:
        stored_T, stored_heat, wall_heat = f["temperature"][...], f["element_heat"][...], f["wall_heat"][...]
    particles, wall_reader = pv.get_reader(moved / "particles.pvd"), pv.get_reader(moved / "walls.pvd")
    np.testing.assert_array_equal(particles.time_values, times)
    np.testing.assert_array_equal(wall_reader.time_values, times)
    for k, t in enumerate(times):
        particles.set_active_time_value(t)
        (cloud,) = particles.read()
        present = np.ones(len(run["ids"]), bool)
        if THERMAL_FRAMES[k] == LOST[0]:
            present[LOST[1]] = False  # lost: neither position nor temperature
        assert cloud.n_points == present.sum()
        np.testing.assert_array_equal(cloud.point_data["id"], run["ids"][present])
        np.testing.assert_array_equal(cloud.points, run["centres"][THERMAL_FRAMES[k]][present])
        np.testing.assert_array_equal(cloud.point_data["temperature"], stored_T[k][present])
        np.testing.assert_array_equal(cloud.point_data["radius"], RADIUS)
        assert cloud.field_data["TimeValue"][0] == t

        wall_reader.set_active_time_value(t)
        (mesh,) = wall_reader.read()
        assert mesh.n_cells == len(walls)
        corners = mesh.points[mesh.regular_faces]  # (M, 3, 3): the triangles as stored
        np.testing.assert_array_equal(corners, walls.vertices)
        np.testing.assert_array_equal(mesh.cell_data["zone"], walls.zone)
        assert list(mesh.field_data["zone_names"]) == ["heated", "adiabatic"]
        heated = walls.zone_mask("heated")
        np.testing.assert_allclose(mesh.cell_data["wall_temperature"][heated], 900.0 + 1000.0 * walls.centroid[heated, 2],
                                   rtol=1e-15)  # fmt: skip
        assert np.all(np.isnan(mesh.cell_data["wall_temperature"][~heated]))
        area = mesh.cell_data["area"]
        np.testing.assert_allclose(area, walls.area, rtol=1e-15)
        np.testing.assert_allclose(mesh.cell_data["normal"], walls.normal, rtol=0, atol=1e-15)
        for j, mode in enumerate(PW_MODES):  # flux x area: the stored element heat, and its sum /wall_heat
            heat = mesh.cell_data[f"heat_flux_{mode}"] * area
            np.testing.assert_allclose(heat, stored_heat[k, :, j], rtol=1e-12, atol=1e-30)
            # the writer sums the float32 element heats in float32
            assert heat.sum() == pytest.approx(wall_heat[k, j], rel=0, abs=1e-6 * np.abs(heat).sum())
            assert mesh.field_data[f"wall_heat_{mode}"][0] == wall_heat[k, j]
        np.testing.assert_allclose(mesh.cell_data["heat_flux"] * area, stored_heat[k].astype(float).sum(axis=1),
                                   rtol=1e-12, atol=1e-30)
        assert np.all(mesh.cell_data["heat_flux"][walls.zone_mask("adiabatic")] == 0.0)
    readme = (moved / "README.md").read_text()
    assert readme.startswith(f"# {FORMAT}") and "W/m^2" in readme and "heat rates per particle" in readme


def test_a_thermal_run_folder_finds_its_inputs_through_the_variant(run, tmp_path):
    sources = find_sources(run["folders"]["thermal"])
    assert sources == Sources(run["folders"]["thermal"] / "thermal.h5", run["folders"]["dem"] / "positions.h5",
                              run["folders"]["geometry"] / "walls.h5")  # fmt: skip
    out = export(sources, tmp_path / "pv")
    assert (out / "walls.pvd").is_file()
    stale = out / "frames" / "particles_000099.vtp"
    stale.write_text("from an earlier export")
    export(sources, out)  # replaces an earlier export as a whole
    assert not stale.exists()


def test_bad_inputs_are_refused_before_writing(run, tmp_path, capsys):
    folders = run["folders"]
    lonely = tmp_path / "thermal" / "ffffffffffff"
    lonely.mkdir(parents=True)
    shutil.copy(folders["thermal"] / "thermal.h5", lonely)
    with pytest.raises(DPHTError, match="names thermal run ffffffffffff.*--positions"):
        find_sources(lonely)
    assert main(["export", str(tmp_path)]) == 2
    assert "neither a thermal run folder" in capsys.readouterr().err
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "notes.txt").write_text("mine")
    sources = find_sources(folders["thermal"])
    with pytest.raises(DPHTError, match="occupied.*no ParaView export"):
        export(sources, occupied)
    assert (occupied / "notes.txt").read_text() == "mine"
    other = tmp_path / "walls.h5"  # a wall table of another mesh
    save_walls(other, tube(n_theta=6), "{}", 2 * RADIUS)
    with pytest.raises(DPHTError, match="element_heat has 64 wall elements.*48"):
        export(Sources(sources.thermal, sources.positions, other), tmp_path / "mismatch")
    assert not (tmp_path / "mismatch").exists() and not list(tmp_path.glob(".mismatch.*"))
    assert len(load_walls(other)) == 48
