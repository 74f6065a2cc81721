"""The geometry a config describes, before gmsh (geometry.layout): the same zones as the geometry
stage writes, and sample points on each zone's meshed surfaces."""

import subprocess
import sys

import numpy as np
import pytest

from dpht.thermal.wall_distance import build_index, nearest
from dpht.verification.cases import geometry as reference
from dpht.geometry.errors import GeometryConfigError
from dpht.geometry.layout import layout, sample_walls, zone_points


def test_zones_are_those_the_geometry_stage_writes():
    summary, walls = reference.scene()
    parts = layout(reference.SCENE, reference.D_PAPER)
    assert parts.zone_names == walls.zone_names == tuple(summary["zone_names"])
    plain = layout({"tube": {**reference.TUBE, "heated": [0.0, reference.TUBE["length"]]}}, reference.D_PAPER)
    assert plain.zone_names == ("heated_wall", "orifice")  # heated end to end: no adiabatic wall


def test_sample_points_lie_on_the_meshed_surfaces():
    """Each zone's points are within the facets' sag of that zone's triangles (the tube, orifice,
    plate and funnel exactly; the radial mixer's small-tube points within its wall thickness, since
    those fused into the funnel wall lie inside the solid)."""
    _, walls = reference.scene()
    parts = layout(reference.SCENE, reference.D_PAPER)
    element = reference.D_PAPER * reference.SCENE["mesh_size"]
    # Sag of an element-long chord on the tightest circle, the funnels' outlets.
    sag = element**2 / (8 * 0.5 * reference.RADIAL["outlet_diameter"])
    for zone, points in zone_points(parts).items():
        index = build_index(walls.vertices[walls.zone_mask(zone)], cutoff=5 * element)
        _, distance = nearest(index, points)
        limit = reference.RADIAL["wall_thickness"] + sag if zone == "radial" else sag
        assert np.all(distance <= limit), (zone, distance.max(), limit)
        assert len(points) >= 100


def test_sample_walls_is_a_wall_table_with_the_points_as_centroids():
    parts = layout(reference.SCENE, reference.D_PAPER)
    walls = sample_walls(parts)
    points = zone_points(parts)
    assert walls.zone_names == parts.zone_names
    for zone, expected in points.items():
        np.testing.assert_allclose(walls.centroid[walls.zone_mask(zone)], expected, rtol=0, atol=1e-15)


def test_bad_geometry_is_refused_without_gmsh():
    with pytest.raises(GeometryConfigError, match="geometry.tube.orifice_diameter"):
        layout({"tube": {**reference.TUBE, "orifice_diameter": 0.02}}, reference.D_PAPER)
    with pytest.raises(GeometryConfigError, match=r"geometry.mixers\[0\].opening"):
        layout({**reference.SCENE, "mixers": [{**reference.PLATE, "opening": 0.01}]}, reference.D_PAPER)


def test_reading_a_config_and_planning_do_not_load_gmsh():
    """dpht.config, dpht.plan, the preflight and the cost preview read the geometry's layout and
    checks only, and importing the geometry package loads no mesher: gmsh, imported by the functions
    that mesh, stays unloaded (in a fresh interpreter, where nothing else imported it)."""
    code = ("import sys, dpht.config, dpht.plan, dpht.preflight, dpht.cost, dpht.geometry, dpht.geometry.layout; "
            "assert 'gmsh' not in sys.modules, 'gmsh was imported'")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
