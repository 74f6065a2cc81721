"""Exact distances to the wall primitives (dpht.thermal.primitives) against closed forms and brute
force over the surface (the primitives the geometry stage records, against its faceted mesh, and
the STLs LIGGGHTS reads: tests/stage/test_mixers.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from dpht.thermal import primitives
from dpht.geometry.walls import Primitive

R, Z0, Z1 = 4.5e-3, 0.004, 0.040
rng = np.random.default_rng(0)


def on_azimuth(rho, z, phi=None):
    """Points at distance ``rho`` from the axis and height ``z``, at random azimuths."""
    phi = rng.uniform(0, 2 * np.pi, np.size(rho)) if phi is None else phi
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z * np.ones(np.size(rho))])


def distances(points, segment):
    return np.array([primitives.distance(*p, np.asarray(segment, dtype=float)) for p in points])


def test_cylinder_piece_closed_forms():
    seg = Primitive.cylinder("tube", R, Z0, Z1).segment
    rho = rng.uniform(0, 1.2 * R, 500)
    z = rng.uniform(0.0, 0.045, 500)
    beyond = np.where(z < Z0, Z0 - z, np.where(z > Z1, z - Z1, 0.0))
    expected = np.hypot(rho - R, beyond)
    assert np.allclose(distances(on_azimuth(rho, z), seg), expected, rtol=1e-13, atol=1e-19)
    # Inside the heated range: exactly R - rho, the gap LIGGGHTS' zcylinder sees (to round-off of rho).
    inside = (z > Z0) & (z < Z1) & (rho < R)
    points = on_azimuth(rho[inside], z[inside])
    exact = R - np.hypot(points[:, 0], points[:, 1])
    assert np.abs(distances(points, seg) - exact).max() < 1e-18


def test_annulus_closed_forms():
    h, r_in = 0.002, 3.5e-3
    seg = Primitive.annulus("orifice", h, r_in, R).segment
    rho = rng.uniform(0, 1.3 * R, 500)
    z = rng.uniform(0.0, 0.004, 500)
    radial = np.where(rho < r_in, r_in - rho, np.where(rho > R, rho - R, 0.0))
    assert np.allclose(distances(on_azimuth(rho, z), seg), np.hypot(radial, z - h), rtol=1e-13, atol=1e-19)


def test_cone_distance_along_the_normal_and_to_the_rims():
    r0, z0, r1, z1 = 3.3e-3, 0.016, 1.5e-3, 0.0175  # a funnel narrowing upwards
    length = np.hypot(r1 - r0, z1 - z0)
    u = np.array([r1 - r0, z1 - z0]) / length
    n = np.array([-u[1], u[0]])
    t = rng.uniform(0.05, 0.95, 300)
    s = rng.uniform(-0.3e-3, 0.3e-3, 300)  # both sides, small enough that the foot stays inside
    rho = r0 + t * length * u[0] + s * n[0]
    z = z0 + t * length * u[1] + s * n[1]
    keep = rho > 0
    assert np.allclose(distances(on_azimuth(rho[keep], z[keep]), (r0, z0, r1, z1)), np.abs(s[keep]), rtol=1e-10, atol=1e-18)
    # Beyond the ends: the distance to the rim circle.
    beyond = np.array([r1, z1]) + 0.5e-3 * u + 0.2e-3 * n
    p = on_azimuth(beyond[:1], beyond[1:])
    assert distances(p, (r0, z0, r1, z1))[0] == pytest.approx(np.hypot(0.5e-3, 0.2e-3), rel=1e-12)


@pytest.mark.parametrize("segment", [(R, Z0, R, Z1), (1e-3, 0.002, R, 0.002), (3.3e-3, 0.016, 1.5e-3, 0.0175)])
def test_the_closest_point_lies_in_the_meridian_plane_brute_force(segment):
    """The 2-D reduction against the 3-D surface sampled densely (azimuth and generator): never
    farther than the samples, and within their spacing."""
    phi = np.linspace(0, 2 * np.pi, 721)
    t = np.linspace(0, 1, 401)
    r0, z0, r1, z1 = segment
    rr, pp = np.meshgrid(r0 + t * (r1 - r0), phi, indexing="ij")
    zz = np.broadcast_to((z0 + t * (z1 - z0))[:, None], rr.shape)
    surface = np.column_stack([(rr * np.cos(pp)).ravel(), (rr * np.sin(pp)).ravel(), zz.ravel()])
    tree = cKDTree(surface)
    points = on_azimuth(rng.uniform(0, 6e-3, 200), rng.uniform(0.0, 0.045, 200))
    sampled, _ = tree.query(points)
    exact = distances(points, segment)
    spacing = max(np.hypot(r1 - r0, z1 - z0) / 400, max(r0, r1) * 2 * np.pi / 720)
    assert np.all(exact <= sampled + 1e-15) and np.all(sampled - exact < spacing)
    for p, d in zip(points[:20], exact[:20]):
        q = np.array(primitives.closest_point(*p, np.asarray(segment, dtype=float)))
        assert np.linalg.norm(p - q) == pytest.approx(d, rel=1e-12, abs=1e-18)
        assert distances(q[None, :], segment)[0] < 1e-15  # on the surface


def test_nearest_of_several_surfaces():
    tube = primitives.Surfaces(
        np.array([Primitive.cylinder("a", R, 0.0, Z0).segment, Primitive.cylinder("b", R, Z0, Z1).segment,
                  Primitive.annulus("c", 0.002, 3e-3, R).segment]),  # fmt: skip
        np.array([0, 1, 2]),
    )
    points = on_azimuth(rng.uniform(0, R, 1000), rng.uniform(0.0, Z1, 1000))
    best, which = primitives.nearest(points, tube.segment)
    each = np.column_stack([distances(points, seg) for seg in tube.segment])
    assert np.array_equal(best, each.min(axis=1)) and np.array_equal(which, each.argmin(axis=1))
    assert primitives.nearest(points, np.zeros((0, 4)))[1].max() == -1
