"""A mixer from the user's CAD (geometry.stl_mixer): the file is checked before gmsh runs (empty,
open, inverted, in millimetres, outside the tube), and the geometry stage meshes it like the built-in
mixers, so the same triangles reach LIGGGHTS and the thermal stage."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from dpht import config
from dpht.errors import ConfigError
from dpht.dem.dumps import PositionsFile
from dpht.dem.liggghts import run_dem
from dpht.plan import Plan, from_workflow
from dem_scene import SPEC, needs_liggghts
from dpht.geometry import build
from dpht.geometry.closed_surface import is_closed_and_consistent, signed_volume
from dpht.geometry.errors import GeometryConfigError
from dpht.geometry.layout import layout, zone_points
from dpht.geometry.tube import Tube
from dpht.geometry.walls import load_walls

ROOT = Path(__file__).resolve().parents[2]
D = 1e-3
TUBE_CFG = {"inner_diameter": 9e-3, "length": 0.05, "orifice_height": 0.004, "orifice_diameter": 7e-3,
            "heated": [0.004, 0.04]}  # fmt: skip
TUBE = Tube.from_config(TUBE_CFG, D, 3.0, 0.5 * D)


def ring(path, scale=1.0, z=0.02):
    """An annular baffle (r 2.5-4.4 mm, 1 mm high at height z), written in units of ``scale`` m."""
    mesh = trimesh.creation.annulus(r_min=2.5e-3 / scale, r_max=4.4e-3 / scale, height=1e-3 / scale, sections=24)
    mesh.apply_translation([0.0, 0.0, z / scale])
    mesh.export(path)
    return mesh


def mixer(path, **extra):
    return layout({"tube": TUBE_CFG, "mixers": [{"type": "stl", "file": str(path), **extra}]}, D).mixers[0]


def test_a_file_in_millimetres_is_named_with_the_scale_to_use(tmp_path):
    ring(tmp_path / "ring.stl", scale=1e-3)
    with pytest.raises(GeometryConfigError, match=r"978 times the tube's inner diameter, so the file is probably "
                                                  r"in millimetres: set geometry.mixers\[0\].scale: 0.001"):
        mixer(tmp_path / "ring.stl")
    assert mixer(tmp_path / "ring.stl", scale=0.001).z_range() == pytest.approx((0.0195, 0.0205))


@pytest.mark.parametrize("content", [b"", b"solid x\nendsolid x\n", b"\x00garbage" * 20])
def test_empty_or_foreign_files_are_refused(tmp_path, content):
    (tmp_path / "m.stl").write_bytes(content)
    with pytest.raises(GeometryConfigError, match=r"geometry.mixers\[0\].file: .*m.stl holds no triangles"):
        mixer(tmp_path / "m.stl")
    with pytest.raises(GeometryConfigError, match="does not exist"):
        mixer(tmp_path / "none.stl")


def test_an_open_surface_is_refused(tmp_path):
    mesh = ring(tmp_path / "ring.stl")
    trimesh.Trimesh(mesh.vertices, mesh.faces[1:], process=False).export(tmp_path / "open.stl")
    with pytest.raises(GeometryConfigError, match="must be a closed solid, but its surface is not closed: 3 edges"):
        mixer(tmp_path / "open.stl")


def test_inverted_and_inconsistent_normals_are_fixed(tmp_path):
    mesh = ring(tmp_path / "ring.stl")
    trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False).export(tmp_path / "inverted.stl")
    faces = mesh.faces.copy()
    faces[::3] = faces[::3, ::-1]
    trimesh.Trimesh(mesh.vertices, faces, process=False).export(tmp_path / "mixed.stl")
    for name, note in (("inverted.stl", "normals pointed into the solid"), ("mixed.stl", "re-wound consistently")):
        m = mixer(tmp_path / name)
        assert any(note in n for n in m.notes), m.notes
        assert is_closed_and_consistent(m.faces) and m.volume == pytest.approx(mesh.volume, rel=1e-12)


def test_a_solid_outside_the_tube_is_refused(tmp_path):
    ring(tmp_path / "high.stl", z=0.06)
    with pytest.raises(GeometryConfigError, match=r"z = 0.0595 to 0.0605 m; the tube has .* must lie inside the tube"):
        mixer(tmp_path / "high.stl")
    big = trimesh.creation.annulus(r_min=2.5e-3, r_max=5e-3, height=1e-3)
    big.apply_translation([0.0, 0.0, 0.02])
    big.export(tmp_path / "big.stl")
    with pytest.raises(GeometryConfigError, match="reaches r = 0.005 m"):
        mixer(tmp_path / "big.stl")


def test_the_geometry_stage_meshes_it_for_liggghts_and_the_thermal_stage(tmp_path):
    ring(tmp_path / "ring.stl")
    source = trimesh.load(tmp_path / "ring.stl")  # as stored: float32 corners
    summary = build({"tube": TUBE_CFG, "mixers": [{"type": "stl", "file": str(tmp_path / "ring.stl")}]}, D,
                    tmp_path / "out")  # fmt: skip
    walls = load_walls(tmp_path / "out" / "walls.h5")
    zone = walls.zone_mask("mixer")
    corners, faces = np.unique(walls.vertices[zone].reshape(-1, 3), axis=0, return_inverse=True)
    faces = faces.reshape(-1, 3)
    assert is_closed_and_consistent(faces) and signed_volume(corners, faces) > 0  # closed, outward
    # Flat facets are meshed exactly: the same volume and area as the user's solid.
    assert signed_volume(corners, faces) == pytest.approx(source.volume, rel=1e-12)
    assert summary["mixers"][0]["area"] == pytest.approx(source.area, rel=1e-12)
    # LIGGGHTS reads mixer.stl, the thermal stage walls.h5: the same triangles.
    liggghts = trimesh.load(tmp_path / "out" / "mixer.stl", process=False)
    np.testing.assert_array_equal(np.asarray(liggghts.triangles), walls.vertices[zone])
    assert summary["mixers"][0]["z_range"] == pytest.approx([0.0195, 0.0205])


def test_the_plan_keys_follow_the_file_and_the_checks_use_its_triangles(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the file path is relative to the working folder, as in the workflow
    ring(tmp_path / "ring.stl")
    override = tmp_path / "stl.yaml"
    override.write_text(yaml.safe_dump({
        "geometry": {"mixers": [{"type": "stl", "file": "ring.stl"}]},
        "thermal": {"walls": {"mixer": {"temperature": "where(z > 0.0204, 0, 900)"}}}}))
    files = [ROOT / "config" / "config.yaml", override]
    with pytest.raises(ConfigError, match=r"thermal.walls.mixer.temperature: .* gives 0.0 at \d+ of \d+ points"):
        from_workflow(config.Sources(files).merged(), files)  # the ring's top face is at z = 0.0205
    cfg = config.load(*files)
    cfg["thermal"]["walls"]["mixer"] = "adiabatic"
    given = {**cfg, "thermal": {**cfg["thermal"], "solid_fraction": 0.6}}
    first, first_given = Plan(cfg).keys["base"], Plan(given).keys["base"]
    ring(tmp_path / "ring.stl", z=0.025)
    moved = Plan(cfg).keys["base"]
    assert moved["geometry"] != first["geometry"] and moved["dem"] != first["dem"]
    assert moved["pfp"] != first["pfp"]  # its solid fraction is measured by the (moved) DEM run
    assert Plan(given).keys["base"]["pfp"] == first_given["pfp"]  # a given one: the same table
    points = zone_points(layout(json.loads(json.dumps(Plan(cfg).configs["base"]["geometry"])), D))["mixer"]
    assert points[:, 2].min() >= 0.0245 - 1e-9 and points[:, 2].max() <= 0.0255 + 1e-9  # float32 in STL


@needs_liggghts
@pytest.mark.slow
def test_liggghts_collides_particles_with_the_users_solid(tmp_path, monkeypatch):
    """A real DEM run with the ring from an STL in a short 9 mm tube: particles pass its 5 mm hole
    and none goes through its solid part."""
    monkeypatch.chdir(tmp_path)
    ring(tmp_path / "ring.stl", z=0.011)
    spec = copy.deepcopy(SPEC)
    spec["geometry"] = {"tube": {**TUBE_CFG, "length": 0.024, "heated": [0.004, 0.024]},
                        "mixers": [{"type": "stl", "file": "ring.stl"}], "mesh_size": 1.0}  # fmt: skip
    spec["dem"].update(fill_height=0.016, settle_time=0.05, flow_time=0.1)
    build(spec["geometry"], D, tmp_path / "geometry")
    summary = run_dem(spec, tmp_path / "geometry", tmp_path / "work", tmp_path / "positions.h5", ranks=1,
                      log=lambda _: None)  # fmt: skip
    (passages,) = summary["mixers"]
    assert summary["lost_particles"]["count"] == 0 and passages["crossings"] > 50
    with PositionsFile(tmp_path / "positions.h5") as f:
        for frame in f.frames():
            r, z = np.hypot(frame.positions[:, 0], frame.positions[:, 1]), frame.positions[:, 2]
            in_solid = (r > 2.5e-3 + 0.45 * D) & (z > 0.0105 - 0.45 * D) & (z < 0.0115 + 0.45 * D)
            assert not np.any(in_solid)


def test_a_folder_given_as_the_file_is_named_a_folder(tmp_path):
    (tmp_path / "cad").mkdir()
    with pytest.raises(GeometryConfigError, match=r"geometry.mixers\[0\].file: .*cad is a folder; give the STL file in it"):
        mixer(tmp_path / "cad")


def test_a_small_mixer_in_millimetres_is_told_the_scale_that_puts_it_in_the_tube(tmp_path):
    """A 2 mm disc: 222 times the tube's 9 mm bore as metres, so the order of magnitude alone said
    0.01 (centimetres), which leaves it outside the tube."""
    disc = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=16)  # mm
    disc.apply_translation([0.0, 0.0, 20.0])
    disc.export(tmp_path / "disc.stl")
    with pytest.raises(GeometryConfigError, match=r"probably in millimetres: set geometry.mixers\[0\].scale: 0.001$"):
        mixer(tmp_path / "disc.stl")
    assert mixer(tmp_path / "disc.stl", scale=0.001).z_range() == pytest.approx((0.0195, 0.0205))


def test_overlapping_or_nested_shells_are_refused(tmp_path):
    """Two closed boxes that overlap pass the closed-surface check (every edge has two triangles),
    and gmsh meshed them silently into overlapping walls."""
    def box(centre, size=1.5e-3):
        return trimesh.creation.box(extents=(size, size, size)).apply_translation(centre)

    trimesh.util.concatenate([box((0, 0, 0.02)), box((0.7e-3, 0, 0.0205))]).export(tmp_path / "overlap.stl")
    with pytest.raises(GeometryConfigError, match=r"overlap.stl: the surface crosses itself .* two shells overlap"):
        mixer(tmp_path / "overlap.stl")
    trimesh.util.concatenate([box((0, 0, 0.02)), box((0, 0, 0.02), 0.5e-3)]).export(tmp_path / "nested.stl")
    with pytest.raises(GeometryConfigError, match=r"nested.stl: one of its 2 closed shells .* lies inside another"):
        mixer(tmp_path / "nested.stl")
    trimesh.util.concatenate([box((0, 0, 0.015)), box((0, 0, 0.025))]).export(tmp_path / "apart.stl")
    assert mixer(tmp_path / "apart.stl").z_range() == pytest.approx((0.01425, 0.02575))


def test_the_example_insert_is_its_generators_twisted_plate_and_meshes(tmp_path, monkeypatch):
    """geometry/twisted_plate.stl is what dpht.geometry.twisted_plate writes, a closed solid of the
    plate's volume (every cross-section is the w x t rectangle: V = w t L, Cavalieri), and the
    example config that names it is valid and meshed by the geometry stage."""
    from dpht.geometry import twisted_plate

    twisted_plate.write(tmp_path / "plate.stl", *twisted_plate.twisted_plate(**twisted_plate.EXAMPLE), "twisted_plate")
    example = ROOT / twisted_plate.EXAMPLE_FILE
    assert (tmp_path / "plate.stl").read_bytes() == example.read_bytes()
    assert example.stat().st_size < 200_000
    monkeypatch.chdir(ROOT)  # the config names the file relative to the repository's top folder
    cfg = config.load(ROOT / "config" / "config.yaml", ROOT / "config" / "examples" / "twisted_plate.yaml")
    scene = Plan(cfg).configs["twisted_plate"]
    (inserted,) = layout(scene["geometry"], scene["particles"]["diameter"]).mixers
    p = twisted_plate.EXAMPLE
    assert inserted.notes == ()  # wound outwards as written
    assert inserted.volume == pytest.approx(p["width"] * p["thickness"] * (p["z1"] - p["z0"]) * 1e-9, rel=0.01)
    summary = build(scene["geometry"], scene["particles"]["diameter"], tmp_path / "out")
    walls = load_walls(tmp_path / "out" / "walls.h5")
    corners, faces = np.unique(walls.vertices[walls.zone_mask("mixer")].reshape(-1, 3), axis=0, return_inverse=True)
    assert is_closed_and_consistent(faces.reshape(-1, 3))
    assert signed_volume(corners, faces.reshape(-1, 3)) == pytest.approx(inserted.volume, rel=1e-9)
    assert summary["mixers"][0]["z_range"] == pytest.approx([0.010, 0.022])
