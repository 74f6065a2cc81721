"""The particle-wall overlaps LIGGGHTS computes on a real frame equal those from the surfaces the
thermal stage should measure: the exact cylinder where the DEM used the primitive tube (not the
faceted gmsh mesh, which sits inside it), the same triangles where it used a mesh."""

from __future__ import annotations

import numpy as np
import pytest

import dem_scene
from dem_scene import D, GEOMETRY, LENGTH, R_TUBE, SPEC, needs_liggghts
from dpht.dem.params import DemParams
from dpht.thermal import primitives
from dpht.thermal.wall_distance import build_index, closest_distance2, nearest
from geometry import build
from geometry.walls import Primitive
from wall_contacts import liggghts_wall_contacts, newest_restart

RADIUS = 0.5 * D

pytestmark = needs_liggghts


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """LIGGGHTS' contacts on the last restart frame of the shared short DEM run (primitive tube)."""
    root, meshes, _, _, _ = dem_scene.short_run(tmp_path_factory)
    params = DemParams.from_spec(SPEC, GEOMETRY)
    return params, meshes, liggghts_wall_contacts(params, root / "work", newest_restart(root / "work"))


def report(name, difference):
    print(f"{name}: {difference.size} contacts, max |difference| {np.abs(difference).max() / RADIUS:.3g} R, "
          f"mean {difference.mean() / RADIUS:.3g} R")  # fmt: skip


def test_exact_cylinder_overlaps_equal_liggghts_and_faceted_ones_do_not(frame, tmp_path):
    params, _, contacts = frame
    touching = contacts.tube_overlap > 0
    assert touching.sum() >= 30  # a settled bed leans on the tube wall
    cylinder = np.array([Primitive.cylinder("tube", R_TUBE, 0.0, LENGTH).segment])
    exact = contacts.radius - primitives.nearest(contacts.positions, cylinder)[0]
    difference = exact[touching] - contacts.tube_overlap[touching]
    report("exact cylinder - LIGGGHTS", difference)
    assert np.abs(difference).max() < 1e-6 * RADIUS
    assert np.all(exact[~touching] <= 1e-6 * RADIUS)  # and no contact LIGGGHTS did not see
    # The geometry stage's faceted mesh of the same tube (what the thermal stage measured so far).
    build(SPEC["geometry"], D, tmp_path)
    from geometry.walls import load_walls

    walls = load_walls(tmp_path / "walls.h5")
    tube = np.isin(walls.zone, [walls.zone_names.index(z) for z in ("heated_wall", "adiabatic_wall")])
    _, faceted = nearest(build_index(walls.vertices[tube], 2 * RADIUS), contacts.positions[touching])
    facet_difference = (contacts.radius[touching] - faceted) - contacts.tube_overlap[touching]
    report("faceted mesh - LIGGGHTS", facet_difference)
    assert facet_difference.mean() > 1e-3 * RADIUS  # the facets lie inside the cylinder: more overlap


def test_mesh_overlaps_are_liggghts_own_per_triangle(frame):
    """The orifice plate is an STL mesh in the DEM: the distance to each contact's own triangle of
    that very STL gives LIGGGHTS' delta."""
    import trimesh

    params, meshes, contacts = frame
    assert contacts.mesh.size >= 10
    for k, zone in enumerate(contacts.mesh_zones):
        rows = contacts.mesh == k
        tri = np.asarray(trimesh.load(meshes / f"{zone}.stl", process=False).triangles, dtype=np.float64)
        points = contacts.positions[contacts.particle[rows]]
        corners = tri[contacts.triangle[rows]]
        distance = np.sqrt([closest_distance2(p, *c) for p, c in zip(points, corners)])
        difference = (contacts.radius[contacts.particle[rows]] - distance) - contacts.delta[rows]
        report(f"{zone} triangles - LIGGGHTS", difference)
        assert np.abs(difference).max() < 1e-6 * RADIUS
