"""The particle-wall overlaps LIGGGHTS computes on a real frame equal those from the surfaces the
thermal stage measures: the exact cylinder where the DEM used the primitive tube (not the faceted
gmsh mesh, which sits inside it), the same triangles where it used a mesh; on a test tube and,
through the thermal stage's own contacts, on the default scene's geometry."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dem_scene
from dem_scene import D, GEOMETRY, LENGTH, R_TUBE, SPEC, needs_liggghts
from dpht.dem.dumps import PositionsFile
from dpht.dem.liggghts import run_dem
from dpht.dem.params import DemParams, read_geometry
from dpht.thermal import primitives
from dpht.thermal.schedule import Schedule
from dpht.thermal.wall_distance import build_index, closest_distance2, nearest
from dpht.geometry import build
from dpht.geometry.walls import Primitive, load_walls
from wall_contacts import liggghts_wall_contacts, newest_restart, per_particle

RADIUS = 0.5 * D

pytestmark = needs_liggghts


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """LIGGGHTS' contacts on the last restart frame of the shared short DEM run (primitive tube)."""
    root, meshes, _, _, _ = dem_scene.short_run(tmp_path_factory)
    params = DemParams.from_spec(SPEC, GEOMETRY)
    return params, meshes, liggghts_wall_contacts(params, root / "work", newest_restart(root / "work"), meshes)


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


# --- the thermal stage's own wall contacts on the default scene's geometry -----------------------

DEFAULT_DEM = {"fill_height": 0.010, "settle_time": 0.05, "flow_time": 0.02, "dump_interval": 500, "restart_interval": 1000}


@pytest.fixture(scope="module")
def default_scene(tmp_path_factory):
    """The default config's geometry (gmsh, the geometry stage) and materials, a short DEM run on it
    (a 10 mm bed, 0.02 s of flow) and LIGGGHTS' contacts on its last restart frame."""
    from dpht import config

    root = tmp_path_factory.mktemp("default_walls")
    c = config.variant(config.load(Path(__file__).resolve().parents[2] / "config" / "config.yaml"), "base")
    c["dem"].update(DEFAULT_DEM)
    build(c["geometry"], c["particles"]["diameter"], root / "geometry")
    spec = config.dem_spec(c)
    summary = run_dem(spec, root / "geometry", root / "work", root / "positions.h5", ranks=1, log=lambda line: None)
    params = DemParams.from_spec(spec, read_geometry(root / "geometry"))
    return c, root, summary, params, liggghts_wall_contacts(params, root / "work", newest_restart(root / "work"),
                                                            root / "geometry")


def test_the_thermal_stage_measures_liggghts_own_overlaps_on_the_default_geometry(default_scene):
    """Through the thermal stage's own path (the model from the DEM run's record of its wall surfaces,
    prepare_frame's contacts, one per surface): every particle's overlap with the tube (LIGGGHTS'
    exact cylinder) and the orifice plate (its STL) equals LIGGGHTS' to 1e-6 R, and no particle
    touches a wall in one and not in the other."""
    from dpht.thermal import integrate, model as thermal_model
    from dpht.verification import scenes

    c, root, summary, params, contacts = default_scene
    assert summary["walls"] == {"heated_wall": "primitive", "adiabatic_wall": "primitive", "orifice": "mesh"}
    walls = load_walls(root / "geometry" / "walls.h5")
    s = scenes.spec(["pw_contact"], walls=dict.fromkeys(walls.zone_names, {"temperature": 600.0}))
    s["particles"]["diameter"] = c["particles"]["diameter"]
    model = thermal_model.build(s, walls, scenes.htc_tables(s), wall_kinds=summary["walls"])
    assert [surface.name for surface in model.surfaces] == ["tube", "orifice_plate"]
    assert model.surfaces[0].mesh is None and model.surfaces[1].mesh is not None  # exact cylinder, plate triangles
    with PositionsFile(root / "positions.h5") as dem:
        schedule = Schedule.of(dem, 1)
    frame = integrate.prepare_frame(model, contacts.positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    radius = contacts.radius[frame.particles]
    thermal = np.where(frame.wall_element >= 0, np.maximum(radius - frame.wall_distance, 0.0), 0.0)
    liggghts = np.array([contacts.tube_overlap, per_particle(contacts, "orifice")])[:, frame.particles]
    for name, ours, theirs in zip(("tube", "orifice plate"), thermal, liggghts):
        touching = (ours > 0) | (theirs > 0)
        assert touching.sum() >= 20
        report(f"thermal stage {name} - LIGGGHTS", ours[touching] - theirs[touching])
        assert np.all((ours > 0) == (theirs > 0))
        assert np.abs(ours - theirs).max() < 1e-6 * RADIUS
