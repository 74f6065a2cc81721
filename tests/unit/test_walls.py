"""Exact particle-to-triangle-mesh distances against an independent minimisation."""

import numpy as np
import pytest
import trimesh
from scipy.optimize import minimize

from dpht.thermal import wall_distance as walls


def independent_distance(p, tri):
    """Distance from p to triangle tri by constrained minimisation over barycentric coordinates."""
    a, b, c = tri

    def f(x):
        q = a + x[0] * (b - a) + x[1] * (c - a)
        return np.sum((q - p) ** 2)

    best = min(
        (minimize(f, x0, bounds=[(0, 1), (0, 1)], constraints=[{"type": "ineq", "fun": lambda x: 1 - x[0] - x[1]}],
                  method="SLSQP", options={"ftol": 1e-22, "maxiter": 200}) for x0 in [(0.2, 0.2), (0.7, 0.1), (0.1, 0.7)]),
        key=lambda r: r.fun,
    )  # fmt: skip
    return np.sqrt(best.fun)


def test_closest_point_regions_against_minimisation():
    rng = np.random.default_rng(0)
    for _ in range(60):
        tri = rng.normal(size=(3, 3))
        p = rng.normal(size=3) * 2
        ours = np.sqrt(walls.closest_distance2(p, tri[0], tri[1], tri[2]))
        assert ours == pytest.approx(independent_distance(p, tri), rel=1e-6, abs=1e-9)


def test_nearest_matches_exhaustive_search_on_a_tube():
    mesh = trimesh.creation.cylinder(radius=4.5e-3, height=0.05, sections=48)
    tri = mesh.vertices[mesh.faces]
    rng = np.random.default_rng(1)
    pts = rng.uniform([-5e-3, -5e-3, -0.027], [5e-3, 5e-3, 0.027], (3000, 3))
    cutoff = 1.5e-3
    index = walls.build_index(tri, cutoff)
    element, distance = walls.nearest(index, pts)
    ref_element, ref_distance = walls.brute_force_nearest(tri, pts, cutoff)
    found = ref_element >= 0
    assert found.sum() > 300
    np.testing.assert_array_equal(element >= 0, found)
    np.testing.assert_allclose(distance[found], ref_distance[found], rtol=0, atol=1e-15)
    # The element may differ only where two triangles are equally close (shared edges).
    differs = element[found] != ref_element[found]
    for e, p, d in zip(element[found][differs], pts[found][differs], distance[found][differs]):
        assert np.sqrt(walls.closest_distance2(p, *tri[e])) == pytest.approx(d, abs=1e-15)


def test_plane_distance_is_the_perpendicular_distance_not_the_centroid():
    tri = np.array([[[0, 0, 0], [1e-3, 0, 0], [0, 1e-3, 0]]], dtype=float)
    index = walls.build_index(tri, 5e-4)
    element, distance = walls.nearest(index, np.array([[2e-4, 2e-4, 3e-4], [1.2e-3, 0, 1e-4], [5e-3, 5e-3, 0]]))
    assert element.tolist() == [0, 0, -1]
    assert distance[0] == pytest.approx(3e-4, rel=1e-12)
    assert distance[1] == pytest.approx(np.hypot(2e-4, 1e-4), rel=1e-12)  # beyond the edge: to the vertex
    assert np.isinf(distance[2])
