"""Geometry stage: zones, areas and volume against closed forms; file consistency; config errors."""

from __future__ import annotations

import json
import math
import threading

import h5py
import meshio
import numpy as np
import pytest
import trimesh

from dpht.geometry.errors import GeometryConfigError, GeometryError
from dpht.geometry.walls import load_walls
from dpht.geometry import build, picture

D_PARTICLE = 1.0e-3  # m
TUBE = {
    "inner_diameter": 9.0e-3,
    "length": 0.05,
    "orifice_height": 0.004,
    "orifice_diameter": 6.0e-3,
    "heated": [0.010, 0.040],  # cuts at 0, 0.004, 0.010, 0.040, 0.05: adiabatic on both sides of the plate
}
R, L, Z_PLATE, R_HOLE = 4.5e-3, 0.05, 0.004, 3.0e-3


def config(mesh_size=0.5, **tube):
    return {"tube": {**TUBE, **tube}, "mesh_size": mesh_size}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    outdir = tmp_path_factory.mktemp("tube")
    summary = build(config(), D_PARTICLE, outdir)
    return outdir, summary, load_walls(outdir / "walls.h5")


def vertex_ids(vertices):
    """Integer id per corner (M,3); corners shared by triangles are the same gmsh node, bit for bit."""
    _, ids = np.unique(vertices.reshape(-1, 3), axis=0, return_inverse=True)
    return ids.reshape(-1, 3)


def directed_edges(ids):
    return np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]])


def boundary_edges(vertices):
    """Corner pairs (K,2,3) of the edges used by one triangle only."""
    ids = vertex_ids(vertices)
    edges = np.sort(directed_edges(ids), axis=1)
    unique, first, count = np.unique(edges, axis=0, return_index=True, return_counts=True)
    flat = vertices.reshape(-1, 3)
    corner_of = np.empty(ids.max() + 1, dtype=np.int64)
    corner_of[ids.ravel()] = np.arange(ids.size)
    return flat[corner_of[unique[count == 1]]]


def cylinder(walls):
    return ~walls.zone_mask("orifice")


def max_edge(vertices):
    return max(np.linalg.norm(vertices[:, i] - vertices[:, (i + 1) % 3], axis=1).max() for i in range(3))


def test_cylinder_zone_areas_match_pi_d_times_length(built):
    # Leading order, an inscribed surface whose edges subtend at most theta at the axis falls short
    # of the cylinder like the inscribed polygon prism, 1 - sin(theta/2)/(theta/2) <= theta^2/24;
    # the tilt of triangles across the axis adds terms of the same order, hence theta^2/12.
    # Measured here: -3.8e-4 against a tolerance of 2.6e-3.
    _, _, walls = built
    z0, z1 = TUBE["heated"]
    lengths = {"heated_wall": z1 - z0, "adiabatic_wall": L - (z1 - z0)}
    for zone, length in lengths.items():
        mask = walls.zone_mask(zone)
        h_max = max_edge(walls.vertices[mask])
        assert h_max < 2.0 * 0.5 * D_PARTICLE  # the tolerance below cannot be inflated by huge triangles
        theta = 2.0 * math.asin(h_max / (2.0 * R))
        exact = math.pi * 2.0 * R * length
        assert 0.0 < (exact - walls.area[mask].sum()) / exact <= theta**2 / 12.0, zone


def test_cylinder_area_error_is_second_order(tmp_path):
    errors = []
    for mesh_size in (1.0, 0.5):
        walls_area = build(config(mesh_size), D_PARTICLE, tmp_path / str(mesh_size))["zones"]["heated_wall"]
        errors.append(abs(walls_area["area"] - walls_area["area_exact"]) / walls_area["area_exact"])
    assert 2.5 < errors[0] / errors[1] < 6.0  # halving the element size divides a theta^2 error by ~4


def test_orifice_area_equals_annulus_between_its_boundary_polygons(built):
    _, _, walls = built
    plate = walls.vertices[walls.zone_mask("orifice")]
    assert np.all(plate[:, :, 2] == Z_PLATE)
    edges = boundary_edges(plate)
    radius = np.hypot(edges[:, :, 0], edges[:, :, 1])
    polygon = {}
    for ring, r in (("outer", R), ("inner", R_HOLE)):
        on_ring = np.all(np.abs(radius - r) < 1e-12, axis=1)
        angles = np.arctan2(edges[on_ring, :, 1], edges[on_ring, :, 0])
        step = np.abs((angles[:, 1] - angles[:, 0] + np.pi) % (2 * np.pi) - np.pi)
        assert step.sum() == pytest.approx(2 * np.pi, rel=1e-12), ring  # the ring closes
        polygon[ring] = 0.5 * r**2 * np.sin(step).sum()  # inscribed polygon
        exact = math.pi * r**2
        assert 0 < exact - polygon[ring] <= exact * step.max() ** 2 / 6  # 1 - sin(t)/t <= t^2/6
    assert len(edges) == sum(np.all(np.abs(radius - r) < 1e-12, axis=1).sum() for r in (R, R_HOLE))
    assert walls.area[walls.zone_mask("orifice")].sum() == pytest.approx(polygon["outer"] - polygon["inner"], rel=1e-12)


def test_every_triangle_tagged_exactly_once(built):
    outdir, summary, walls = built
    msh = meshio.read(outdir / "geometry.msh")
    tag_of = {name: int(tag) for name, (tag, dim) in msh.field_data.items()}
    assert set(tag_of) == set(walls.zone_names) == {"heated_wall", "adiabatic_wall", "orifice"}
    blocks = [i for i, cells in enumerate(msh.cells) if cells.type == "triangle"]
    physical = np.concatenate([msh.cell_data["gmsh:physical"][i] for i in blocks])
    assert physical.size == len(walls) == summary["triangles"]  # every meshed triangle is in one group
    for name in walls.zone_names:
        assert np.sum(physical == tag_of[name]) == walls.zone_mask(name).sum() == summary["zones"][name]["triangles"]
    triangles = np.sort(vertex_ids(walls.vertices), axis=1)
    assert len(np.unique(triangles, axis=0)) == len(walls)  # no triangle listed twice


def test_zones_are_split_at_the_heated_ends(built):
    _, _, walls = built
    z0, z1 = TUBE["heated"]
    z_heated = walls.vertices[walls.zone_mask("heated_wall")][:, :, 2]
    assert z_heated.min() == z0 and z_heated.max() == z1
    z_adiabatic = walls.vertices[walls.zone_mask("adiabatic_wall")][:, :, 2]
    below, above = np.all(z_adiabatic <= z0, axis=1), np.all(z_adiabatic >= z1, axis=1)
    assert np.all(below | above)


def test_cylinder_on_radius_open_ends_exactly_on_periodic_boundaries(built):
    _, _, walls = built
    tube = walls.vertices[cylinder(walls)]
    assert np.abs(np.hypot(tube[:, :, 0], tube[:, :, 1]) - R).max() <= 1e-9
    assert tube[:, :, 2].min() == 0.0 and tube[:, :, 2].max() == L
    # The only open edges are the two end rings: the segments and zones join without gaps.
    edges = boundary_edges(tube)
    z = edges[:, :, 2]
    assert np.all((z == 0.0) | (z == L))
    for z_end in (0.0, L):
        ring = edges[np.all(z == z_end, axis=1)]
        perimeter = np.linalg.norm(ring[:, 1] - ring[:, 0], axis=1).sum()
        assert perimeter == pytest.approx(2 * math.pi * R, rel=1e-2)
    # The plate's outer ring is made of cylinder edges (conformal joint, no leak for particles).
    plate_edges = boundary_edges(walls.vertices[walls.zone_mask("orifice")])
    outer = plate_edges[np.all(np.abs(np.hypot(plate_edges[:, :, 0], plate_edges[:, :, 1]) - R) < 1e-12, axis=1)]
    tube_edges = {tuple(sorted(map(tuple, e))) for t in tube for e in (t[[0, 1]], t[[1, 2]], t[[2, 0]])}
    assert all(tuple(sorted(map(tuple, e))) in tube_edges for e in outer)


def test_normals_unit_oriented_and_consistent(built):
    _, _, walls = built
    assert np.all(walls.area > 0)
    assert np.abs(np.linalg.norm(walls.normal, axis=1) - 1).max() < 1e-12
    tube = cylinder(walls)
    radial = walls.centroid[tube, :2] / np.linalg.norm(walls.centroid[tube, :2], axis=1)[:, None]
    assert np.all(np.einsum("ij,ij->i", walls.normal[tube, :2], radial) < -0.9)  # towards the axis
    assert np.all(walls.normal[walls.zone_mask("orifice")] == [0.0, 0.0, 1.0])
    for part in (tube, walls.zone_mask("orifice")):  # neighbours traverse a shared edge in opposite senses
        edges = directed_edges(vertex_ids(walls.vertices[part]))
        assert len(np.unique(edges, axis=0)) == len(edges)


def test_volume_above_orifice_within_inscribed_bounds(built):
    # Every horizontal section of the faceted tube is a polygon with corners between radius
    # R*cos(theta/2) and R, so 0 <= 1 - V/V_exact <= sin^2(theta/2).
    _, summary, walls = built
    exact = math.pi * R**2 * (L - Z_PLATE)
    assert summary["volume_above_orifice_exact"] == pytest.approx(exact, rel=1e-14)
    theta = 2.0 * math.asin(max_edge(walls.vertices[cylinder(walls)]) / (2.0 * R))
    assert 0.0 < 1.0 - summary["volume_above_orifice"] / exact <= math.sin(theta / 2) ** 2


def test_stl_files_together_equal_the_wall_table(built):
    outdir, summary, walls = built
    total = 0
    for name in walls.zone_names:
        mesh = trimesh.load(outdir / summary["zones"][name]["stl"], process=False)
        mask = walls.zone_mask(name)
        assert np.array_equal(mesh.triangles, walls.vertices[mask])  # shortest round-trip decimals
        assert np.allclose(mesh.face_normals, walls.normal[mask], atol=1e-12)
        total += len(mesh.faces)
    assert total == len(walls)


def test_summary_file_and_attributes(built):
    outdir, summary, walls = built
    assert json.loads((outdir / "geometry.json").read_text()) == summary
    with h5py.File(outdir / "walls.h5") as f:
        assert f.attrs["format"] == "dpht-walls-3"
        assert json.loads(f.attrs["geometry"]) == {**config(), "min_passage": 3.0}
        assert f.attrs["particle_diameter"] == D_PARTICLE
        assert f["zone"].dtype == np.int32 and f["surface"].dtype == np.int32


def test_the_tube_zones_lie_on_two_surfaces_cylinder_and_plate(built):
    """Zones carry boundary conditions, surfaces are the parts a particle touches: the heated and
    adiabatic zones are one cylinder, the orifice plate another."""
    _, summary, walls = built
    assert walls.surface_names == ("tube", "orifice_plate")
    assert summary["surfaces"] == {
        "tube": {"triangles": int(np.sum(cylinder(walls))), "zones": ["adiabatic_wall", "heated_wall"]},
        "orifice_plate": {"triangles": int(walls.zone_mask("orifice").sum()), "zones": ["orifice"]},
    }
    assert {walls.surface_names[walls.primitive_surface(p)] for p in walls.primitives if p.kind == "cylinder"} == {"tube"}


def test_heated_over_whole_length_leaves_no_adiabatic_zone(tmp_path):
    summary = build(config(mesh_size=2.0, heated=[0.0, L]), D_PARTICLE, tmp_path)
    assert summary["zone_names"] == ["heated_wall", "orifice"]
    assert summary["zones"]["heated_wall"]["area_exact"] == pytest.approx(2 * math.pi * R * L, rel=1e-14)


def test_build_is_deterministic_and_runs_outside_the_main_thread(tmp_path):
    results = {}
    worker = threading.Thread(target=lambda: results.update(a=build(config(2.0), D_PARTICLE, tmp_path / "a")))
    worker.start()
    worker.join()
    assert "a" in results
    build(config(2.0), D_PARTICLE, tmp_path / "b")
    first, second = load_walls(tmp_path / "a" / "walls.h5"), load_walls(tmp_path / "b" / "walls.h5")
    for name in ("vertices", "centroid", "normal", "area", "zone"):
        assert np.array_equal(getattr(first, name), getattr(second, name)), name
    for stl in ("heated_wall.stl", "adiabatic_wall.stl", "orifice.stl"):
        assert (tmp_path / "a" / stl).read_bytes() == (tmp_path / "b" / stl).read_bytes()


_DELETE = object()


def _with(path, value):
    cfg = config()
    node = cfg
    for key in path[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return cfg


@pytest.mark.parametrize(
    "path, value, key",
    [
        (("tube", "orifice_diameter"), 9.0e-3, "geometry.tube.orifice_diameter"),
        (("tube", "orifice_diameter"), 2.9e-3, "geometry.tube.orifice_diameter"),
        (("min_passage",), 7.0, "geometry.tube.orifice_diameter"),
        (("min_passage",), -1.0, "geometry.min_passage"),
        (("tube", "heated"), [0.03, 0.02], "geometry.tube.heated"),
        (("tube", "heated"), [0.0, 0.06], "geometry.tube.heated"),
        (("tube", "heated"), [0.01], "geometry.tube.heated"),
        (("tube", "orifice_height"), 0.0, "geometry.tube.orifice_height"),
        (("tube", "orifice_height"), L, "geometry.tube.orifice_height"),
        (("tube", "inner_diameter"), -9.0e-3, "geometry.tube.inner_diameter"),
        (("tube", "length"), "long", "geometry.tube.length"),
        (("tube", "length"), _DELETE, "geometry.tube"),
        (("tube", "radius"), 1.0, "geometry.tube"),
        (("tube", "heated"), [0.004 + 1e-9, 0.04], "geometry.tube"),
        (("mesh_size",), 0.01, "geometry.mesh_size"),
        (("mesh_size",), 3.0, "geometry.mesh_size"),
        (("mesh_size",), True, "geometry.mesh_size"),
        (("mixer",), {}, "geometry"),
    ],
)
def test_bad_config_raises_error_naming_the_key(tmp_path, path, value, key):
    with pytest.raises(GeometryConfigError, match=key.replace(".", r"\.")):
        build(_with(path, value), D_PARTICLE, tmp_path)
    assert not (tmp_path / "walls.h5").exists()


def test_bad_particle_diameter(tmp_path):
    with pytest.raises(GeometryConfigError, match="particle_diameter"):
        build(config(), 0.0, tmp_path)


def test_load_walls_rejects_malformed_files(built, tmp_path):
    outdir, _, walls = built
    with pytest.raises(GeometryError, match="missing.h5"):
        load_walls(tmp_path / "missing.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(GeometryError, match="text.h5"):
        load_walls(tmp_path / "text.h5")
    for tamper, message in (
        (lambda f: f.attrs.__setitem__("format", "other"), "format"),
        (lambda f: f.__delitem__("area"), "missing"),
        (lambda f: f["normal"].__setitem__(0, [1.0, 0.0, 0.0]), "disagree"),
        (lambda f: f["zone"].__setitem__(0, 7), "zone indices"),
    ):
        broken = tmp_path / "broken.h5"
        broken.write_bytes((outdir / "walls.h5").read_bytes())
        with h5py.File(broken, "r+") as f:
            tamper(f)
        with pytest.raises(GeometryError, match=f"broken.h5.*{message}"):
            load_walls(broken)
    with pytest.raises(GeometryError, match="mixer"):
        walls.zone_mask("mixer")


def test_picture_writes_a_png_showing_the_zones(built, tmp_path):
    import matplotlib.image

    outdir, _, _ = built
    png = picture(outdir, tmp_path / "walls.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = matplotlib.image.imread(png)[:, :, :3]
    assert np.mean(np.any(image < 0.9, axis=2)) > 0.05  # not a blank canvas
