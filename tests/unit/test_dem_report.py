"""DEM run report: sphere-cylinder volumes, the solid-fraction estimator, periodic crossings and the
mass-flow check, on synthetic positions files (no LIGGGHTS)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from dem_scene import D, GEOMETRY, LENGTH, R_TUBE, SPEC
from dpht.dem import report as dem_report, dumps
from dpht.dem.params import DemParams
from dpht.dem.dumps import PositionsFile
from dpht.errors import DPHTError


def _arc_quadrature(rho: float, radius: float, a: float) -> float:
    """Sphere volume inside the cylinder r < a by another route: shells about the sphere's vertical
    axis, V = int_0^r 2 q sqrt(r^2 - q^2) * phi(q) dq, phi the angle of the circle of radius q about
    the centre that lies inside the cylinder (law of cosines), by adaptive quadrature."""

    def integrand(q):
        if rho == 0.0:
            inside = 2 * math.pi if q < a else 0.0
        else:
            inside = 2 * math.acos(min(1.0, max(-1.0, (rho**2 + q**2 - a**2) / (2 * rho * q))))
        return 2 * q * math.sqrt(max(radius**2 - q**2, 0.0)) * inside

    kinks = [k for k in (abs(a - rho), a + rho) if 0 < k < radius]
    return quad(integrand, 0.0, radius, points=kinks or None, epsabs=0.0, epsrel=1e-12, limit=200)[0]


@pytest.mark.parametrize(
    "rho, a", [(0.2, 0.3), (1.0, 0.7), (4.2, 4.5), (0.1, 0.45), (0.3, 0.05), (3.9, 3.5), (0.25, 0.25)]
)
def test_sphere_in_cylinder_matches_an_independent_quadrature(rho, a):
    r = 0.5
    exact = _arc_quadrature(rho, r, a)
    assert dem_report.sphere_in_cylinder(np.array([rho]), r, a)[0] == pytest.approx(exact, rel=1e-5)


def test_sphere_in_cylinder_closed_forms_and_partition():
    r = 0.5e-3
    full = 4 / 3 * math.pi * r**3
    # Coaxial: the sphere less two caps, 4/3 pi (r^3 - (r^2 - a^2)^(3/2)).
    for a in (0.1e-3, 0.3e-3, 0.49e-3):
        exact = 4 / 3 * math.pi * (r**3 - (r**2 - a**2) ** 1.5)
        assert dem_report.sphere_in_cylinder(np.zeros(1), r, a)[0] == pytest.approx(exact, rel=1e-12)
    # Annuli share every sphere out exactly: the pieces sum to the whole sphere.
    rho = np.random.default_rng(3).uniform(0.0, 3.4e-3, 500)
    edges = np.linspace(0.0, 4.0e-3, 17)
    pieces = np.diff([dem_report.sphere_in_cylinder(rho, r, a) for a in edges], axis=0)
    assert np.all(pieces >= -1e-12 * full)
    np.testing.assert_allclose(pieces.sum(axis=0), full, rtol=1e-6)


def _positions_file(path: Path, frames: list[np.ndarray], image=None) -> PositionsFile:
    """A positions file of synthetic frames (N, 3) in SPEC's periodic box, steps 500 apart."""
    lo, hi = np.array([-0.005, -0.005, 0.0]), np.array([0.005, 0.005, LENGTH])
    ids = np.arange(1, len(frames[0]) + 1)
    image = image or [np.zeros((len(f), 3), dtype=np.int32) for f in frames]
    dump = []
    for k, (f, i) in enumerate(zip(frames, image)):
        present = ~np.isnan(f[:, 0])  # NaN rows: particles missing from that dump
        dump.append(dumps.DumpFrame(500 * k, lo, hi, (False, False, True), ids[present], f[present], i[present]))
    dumps.write_positions(path, dump, radius=D / 2, density=3560.0, timestep=1e-5, dump_interval=500)
    return PositionsFile(path)


def test_solid_fraction_of_a_wall_ring_and_an_axis_column(tmp_path):
    params = DemParams.from_spec(SPEC, GEOMETRY)
    bed_top = 0.018  # window: 2 d above the orifice plate to 2 d below the bed top, z in [0.004, 0.016]
    z = 0.004 + D * (np.arange(12) + 0.5)
    ring_radius, n_ring = R_TUBE - D / 2, 21  # 21 spheres touching the wall fit around it (22 do not)
    assert n_ring * 2 * math.asin(D / 2 / ring_radius) < 2 * math.pi
    frames = []
    for k in range(4):
        phi = 2 * math.pi * np.arange(n_ring) / n_ring + 0.1 * k  # the ring turns from frame to frame
        ring = [(ring_radius * np.cos(phi), ring_radius * np.sin(phi), np.full(n_ring, zk)) for zk in z]
        column = np.column_stack([np.zeros(12), np.zeros(12), z])
        outside = [[0.0, 0.0, 0.0035], [0.0, ring_radius, 0.0165]]  # centres outside the window
        lost = [[np.nan] * 3] if k else [[0.0, 0.0, 0.010]]  # present in frame 0 only, inside the window
        frames.append(np.vstack([*(np.column_stack(layer) for layer in ring), column, outside, lost]))
    with _positions_file(tmp_path / "p.h5", frames) as positions:
        report = dem_report.solid_fraction_report(params, positions, bed_top)
    assert report["z_window_m"] == [pytest.approx([0.004, 0.016])]
    # Each ring sphere lies wholly in the band R - d < r < R: 21 spheres per d of height in 7 pi d^2
    # of annulus gives 21 (pi/6) / (7 pi) = 1/2. The axis column in r < R - 2 d = 2 d: 1/24.
    assert report["flowing"]["near_wall"] == pytest.approx(0.5, rel=1e-9)
    assert report["flowing"]["bulk"] == pytest.approx(1 / 24, rel=1e-9)
    assert report["settled"]["near_wall"] == pytest.approx(0.5, rel=1e-9)
    assert report["settled"]["bulk"] == pytest.approx(1 / 24 + 1 / 12 / 24, rel=1e-9)  # plus the extra sphere
    # Per frame (what the thermal stage averages over its own frames): the extra sphere in frame 0 only.
    np.testing.assert_allclose(report["per_frame"]["bulk"], [1 / 24 + 1 / 12 / 24] + [1 / 24] * 3, rtol=1e-9)
    np.testing.assert_allclose(report["per_frame"]["near_wall"], [0.5] * 4, rtol=1e-9)
    summary = {"solid_fraction": report}
    assert dem_report.measured_solid_fraction(summary, "bulk", "s.json") == report["flowing"]["bulk"]
    over = dem_report.solid_fraction_over(summary, range(4))
    assert over["bulk"]["mean"] == pytest.approx(1 / 24 + 1 / 12 / 24 / 4, rel=1e-9) and over["near_wall"]["std"] < 1e-12
    with pytest.raises(DPHTError, match=r"s.json: the DEM run measured no near_wall solid fraction"):
        dem_report.measured_solid_fraction({"solid_fraction": None}, "near_wall", "s.json")
    edges = np.array(report["profile"]["r_edges_m"])
    np.testing.assert_allclose(edges, np.arange(9) * D / 2, atol=1e-15)
    gap = (edges[:-1] >= R_TUBE - 2 * D - 1e-12) & (edges[1:] <= R_TUBE - D + 1e-12)
    np.testing.assert_allclose(np.array(report["profile"]["flowing"])[gap], 0.0, atol=1e-12)


def test_net_crossings_count_every_passage_through_the_periodic_tube(tmp_path):
    # Particles fall at steady speeds through the periodic box (several laps for some): the count from
    # the first and last frames alone must equal the passages seen step by step along the way.
    rng = np.random.default_rng(7)
    n, level = 40, 0.0123
    z0, speed = rng.uniform(0.0, LENGTH, n), rng.uniform(0.0, 0.5, n)  # m, m/s downwards
    t = np.linspace(0.0, 0.1, 2001)
    unwrapped = z0[None, :] - speed[None, :] * t[:, None]
    wrapped = np.mod(unwrapped, LENGTH)
    stepwise = np.sum(np.floor((unwrapped[:-1] - level) / LENGTH) != np.floor((unwrapped[1:] - level) / LENGTH))
    assert stepwise > n  # some particles pass the level more than once
    xy = rng.uniform(-2e-3, 2e-3, (n, 2))
    frames = [np.column_stack([xy, wrapped[k]]) for k in (0, -1)]
    image = [np.column_stack([np.zeros((n, 2)), np.floor(unwrapped[k] / LENGTH)]).astype(np.int32) for k in (0, -1)]
    with _positions_file(tmp_path / "p.h5", frames, image) as positions:
        assert dem_report._net_crossings(positions.frame(0), positions.frame(-1), level, LENGTH) == stepwise


def test_mass_flow_check_flags_flows_outside_the_tolerance():
    assert not dem_report.mass_flow_check(0.0105, 0.010, 0.1)["off_target"]
    low = dem_report.mass_flow_check(0.0085, 0.010, 0.1)
    assert low["off_target"] and low["relative_error"] == pytest.approx(-0.15)

