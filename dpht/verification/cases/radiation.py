"""Verification of particle radiation: the Monte Carlo RDF ray tracer (dpht.radiation.raytrace) and the
radiation-model study (dpht.radiation.study) against exact results.

Reference solutions: the view factor from a sphere to an infinite plane (1/2 for any gap), the
view factor between two spheres by numerical quadrature of the double-area integral, the
two-surface enclosure formula, and reciprocity. For black surfaces the RDF is the view factor.
For the study: the exact linear steady state of the DBA model on a lattice.

The RDF tables shipped in ``tables/rdf/shipped/`` (what the default workflow reads): every entry's
standard error against the table's stated one, its number of emitters, and its binning error
(dpht.radiation.tables), largest over all entries; and the pinned-sphere estimator of the PW
tables against free particles where both exist.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from dpht.closures import rdf
from dpht.radiation import packing
from dpht.radiation import study as rs
from dpht.radiation import raytrace
from dpht.radiation import tables as rdf_build
from dpht.studies.radiation import study_thermal_spec
from dpht.verification import scenes
from dpht.verification.harness import case

SHIPPED_TABLES = Path(__file__).resolve().parents[3] / "tables" / "rdf" / "shipped"


def binomial_stderr(fraction, rays):
    """One standard error of a Monte Carlo fraction estimated from ``rays`` independent rays."""
    return np.sqrt(np.maximum(fraction * (1.0 - fraction), 1.0 / rays) / rays)


def sphere_sphere_view_factor(distance, r1=1.0, r2=1.0, n_outer=200, n_polar=48, n_azimuth=96):
    """View factor F_12 from sphere 1 to sphere 2 (centres ``distance`` apart, > r1 + r2) by
    quadrature of F_12 = 1/A1 int_A1 int_A2 cos(t1) cos(t2) / (pi s^2) dA2 dA1.

    Two convex bodies see each other between two surface points exactly when both cosines are
    positive. By axial symmetry the outer integral is 1-D (polar angle on sphere 1, Gauss-Legendre);
    for each point p the inner integral runs over the cap of sphere 2 that faces p (cos t2 > 0),
    in polar coordinates about the axis c2 -> p: Gauss-Legendre in the cap angle, trapezoidal
    (spectral for periodic integrands) in azimuth; max(cos t1, 0) clips the rest.
    """
    if distance <= r1 + r2:
        raise ValueError("spheres overlap")
    x, w = np.polynomial.legendre.leggauss(n_outer)
    mu1, w1 = x, w  # cos of the polar angle on sphere 1, measured from the line of centres
    p = np.stack([r1 * np.sqrt(1 - mu1**2), np.zeros_like(mu1), r1 * mu1], axis=1)
    n1 = p / r1
    c2 = np.array([0.0, 0.0, distance])
    axis = p - c2
    dist = np.linalg.norm(axis, axis=1)
    axis /= dist[:, None]
    # orthonormal frame (axis, e1, e2) for each p; all p lie in the x-z plane, so e2 = y
    e2 = np.array([0.0, 1.0, 0.0])
    e1 = np.cross(e2, axis)
    cap = np.arccos(r2 / dist)  # half-angle of the cap of sphere 2 visible from p
    xg, wg = np.polynomial.legendre.leggauss(n_polar)
    beta = 0.5 * (xg[None, :] + 1) * cap[:, None]  # (n_outer, n_polar)
    wb = 0.5 * wg[None, :] * cap[:, None]
    phi = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
    total = np.zeros(n_outer)
    for k in range(n_polar):
        b = beta[:, k][:, None]
        # unit normal of sphere 2 at the quadrature point, (n_outer, n_azimuth, 3)
        normal = (
            np.cos(b)[..., None] * axis[:, None, :]
            + (np.sin(b) * np.cos(phi))[..., None] * e1[:, None, :]
            + (np.sin(b) * np.sin(phi))[..., None] * e2[None, None, :]
        )
        q = c2 + r2 * normal
        s = q - p[:, None, :]
        s2 = np.sum(s * s, axis=2)
        cos1 = np.maximum(np.sum(n1[:, None, :] * s, axis=2), 0.0)
        cos2 = -np.sum(normal * s, axis=2)
        integrand = cos1 * cos2 / (np.pi * s2 * s2) * r2**2 * np.sin(b)
        total += wb[:, k] * integrand.mean(axis=1) * 2 * np.pi
    # F_12 = (1 / 4 pi r1^2) int r1^2 dmu dphi G = 1/2 int G dmu
    return 0.5 * np.sum(w1 * total)


@case("rdf_sphere_plane_black", "black sphere above a black infinite plane: RDF to the plane = 1/2", "standard errors")
def sphere_plane_black():
    rays = 200_000
    worst = 0.0
    for gap in (0.0, 0.5, 5.0):  # radii
        result = raytrace.trace(
            [[0.0, 0.0, 1.0 + gap]], 1.0, 1.0, rays, walls=[raytrace.PlaneWall((0, 0, 0), (0, 0, 1), 1.0)]
        )
        worst = max(worst, abs(result.walls[0, 0] - 0.5) / binomial_stderr(0.5, rays))
    return worst, 4.0  # in standard errors


@case("rdf_two_spheres_view_factor", "two black spheres: RDF = view factor from a double-area quadrature", "standard errors")
def two_spheres_view_factor():
    rays = 400_000
    worst = 0.0
    for distance, r2 in ((2.2, 1.0), (4.0, 1.0), (3.0, 1.5)):
        reference = sphere_sphere_view_factor(distance, 1.0, r2)
        result = raytrace.trace([[0, 0, 0], [0, 0, distance]], [1.0, r2], 1.0, rays, emitters=[0])
        worst = max(worst, abs(result.matrix[0, 1] - reference) / binomial_stderr(reference, rays))
    return worst, 4.0


@case("rdf_enclosure_sum_rule", "sphere in a closed gray mesh: RDF to wall = two-surface enclosure formula", "standard errors")
def enclosure():
    """A sphere (radius 1, eps1) at the centre of a closed spherical shell meshed with triangles
    (radius 4, eps2). Every ray ends in the sphere or the wall (sum rule, no leaks through the
    mesh), and the wall absorbs eps2 / (1 - (1 - eps2)(1 - F21 eps1)) with F21 = A1/A2 (exact for
    concentric spheres; the fine mesh's own area is used)."""
    import trimesh

    shell = trimesh.creation.icosphere(subdivisions=3, radius=4.0)
    eps1, eps2, rays = 0.6, 0.3, 200_000
    result = raytrace.trace(
        [[0.0, 0.0, 0.0]], 1.0, eps1, rays, walls=[raytrace.MeshWall(shell.vertices, shell.faces, eps2)]
    )
    f21 = 4 * np.pi / shell.area
    expected = eps2 / (1 - (1 - eps2) * (1 - f21 * eps1))
    if result.lost_counts[0] != 0 or result.counts[0, 0] + result.wall_counts[0, 0] != rays:
        return np.inf, 4.0
    return abs(result.walls[0, 0] - expected) / binomial_stderr(expected, rays), 4.0


@case("radiation_study_lattice_linear", "DBA steady state on a cubic lattice: T^4 linear in x, closed-form heat rate")
def lattice_linear():
    """Simple cubic lattice (spacing 2.3 R, periodic in y and z), held particles at T^4 linear in
    x. Pair offsets come in +- pairs, so a linear T^4 makes every free particle's DBA sum (Eq. 25)
    vanish: it is the exact steady state. Across any plane between layers the heat rate is
    eps A sigma (dT^4/dx) a N_col sum_{k_x > 0} k_x^2 D(|k| a) over the lattice offsets k within the
    cutoff (N_col lattice columns; k_x a is each pair's x gap and k_x the number of such pairs per
    column crossing the plane). Checks the pair search, generator, steady solve and heat balance."""
    radius, a, cutoff, columns, layers = 5e-4, 2.3 * 5e-4, 5.0, 8, 10
    s = dict(radius=radius, emissivity=0.65, solid_fraction=0.55, hot_temperature=1300.0, cold_temperature=900.0,
             radiation_cutoff=cutoff, density=2650.0, specific_heat=800.0)  # fmt: skip
    k = np.arange(-layers, layers + 1)
    m = np.arange(columns) + 0.5
    x, y, z = np.meshgrid(k * a, m * a, m * a, indexing="ij")
    positions = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    box = np.array([[-(layers + 0.5) * a, 0, 0], [(layers + 0.5) * a, columns * a, columns * a]])
    held = 3.5 * a  # three free layers either side of x = 0
    region = np.where(positions[:, 0] > held, rs.HOT, np.where(positions[:, 0] < -held, rs.COLD, rs.FREE))
    bed = rs.Bed(positions, radius, box, region.astype(np.int8), 0.55)
    tm = rs.dba_thermal_model(study_thermal_spec(scenes.spec(), s), scenes.synthetic_rdf())
    dba = rs.dba_model(bed, tm)

    u_lo, u_hi = 900.0**4, 1300.0**4
    slope = (u_hi - u_lo) / (2 * layers * a)  # K^4/m
    linear = u_lo + slope * (positions[:, 0] + layers * a)
    T = rs.steady_state(dba, linear**0.25, region == rs.FREE)
    shape_error = np.abs(T**4 - linear).max() / (u_hi - u_lo)

    u0, du, values = tm.tables["pp_radiation"]
    offsets = np.array(np.meshgrid(*[np.arange(-3, 4)] * 3, indexing="ij")).reshape(3, -1).T
    offsets = offsets[(offsets[:, 0] > 0) & (np.sum(offsets**2, axis=1) * a**2 < (cutoff * radius) ** 2)]
    D = np.interp(np.sum(offsets**2, axis=1) * (a / radius) ** 2, u0 + du * np.arange(values.size), values)
    exact = tm.parameters["pp_radiation"].coefficient * slope * a * columns**2 * np.sum(offsets[:, 0] ** 2 * D)
    b = rs.balance(dba.heat_rates(T), bed.region)
    rate_error = max(abs(b["hot_out_W"] - exact), abs(b["cold_in_W"] - exact)) / exact
    return max(shape_error, rate_error), 1e-10


def shipped_tables() -> list[rdf.RDFTables]:
    """The RDF tables in tables/rdf/shipped/ (none in an installation without the repository)."""
    return [rdf.load(path) for path in sorted(SHIPPED_TABLES.glob("*.h5"))]


def _largest(kind: str, name: str) -> tuple[float, float]:
    """Largest ``name`` ("stderr" or "binning_error") over every entry of the shipped ``kind``
    tables, and the smallest stated standard error (the tolerance of both). No table: inf."""
    tables = [getattr(t, kind) for t in shipped_tables()]
    if not tables or any(getattr(t, name) is None or t.stderr_target <= 0 for t in tables):
        return np.inf, 0.0
    return max(float(np.max(getattr(t, name))) for t in tables), min(t.stderr_target for t in tables)


for _kind, _long in (("pp", "particle-particle"), ("pw", "particle-wall")):
    case(f"rdf_table_{_kind}_stderr", f"shipped RDF tables, {_long}: largest standard error <= stated", "RDF")(
        functools.partial(_largest, _kind, "stderr")
    )
    case(f"rdf_table_{_kind}_binning", f"shipped RDF tables, {_long}: largest binning error <= stated stderr", "RDF")(
        functools.partial(_largest, _kind, "binning_error")
    )


@case("rdf_table_samples", "shipped RDF tables: stated emitters / fewest emitters behind an entry", "ratio")
def table_samples():
    tables = [table for t in shipped_tables() for table in (t.pp, t.pw)]
    if not tables or any(t.samples is None for t in tables):
        return np.inf, 1.0
    return max(t.min_samples / max(int(t.samples.min()), 1) for t in tables), 1.0


@case("rdf_table_pinned_emitters", "PW RDF from pinned spheres = from free particles where both exist", "standard errors")
def pinned_emitters():
    """Near-wall solid fraction 0.5: the contact layer (1.0-1.05 R) and the second layer
    (2.6-2.8 R) hold free particles; spheres pinned at those distances in other slabs must give
    the same mean wall RDF. Error: the largest difference in combined standard errors."""
    phi, rays = 0.5, 1000
    slab = packing.pack(2500, phi, aspect=rdf_build.SLAB_ASPECT, wall_axis=2, seed=8, match="near_wall")
    free = rdf_build.pw_slab_samples(slab, 0.65, 0.6, rays, 2500, seed=1)
    rng = np.random.default_rng(2)
    pinned = None
    for k in range(2):
        distances = rng.permutation(np.r_[rng.uniform(1.0, 1.05, 25), rng.uniform(2.6, 2.8, 25)])
        bed = rdf_build.pinned_slab(phi, distances, 20 + k)
        more = rdf_build.pinned_samples(bed, 0.65, 0.6, rays, seed=30 + k)
        pinned = more if pinned is None else pinned + more
    edges = np.array([1.0, 1.05, 2.6, 2.8])
    a = rdf_build.binned_mean(free.cluster, free.distance, free.value, edges, free.n_clusters)
    b = rdf_build.binned_mean(pinned.cluster, pinned.distance, pinned.value, edges, pinned.n_clusters)
    return max(abs(a[0][k] - b[0][k]) / np.hypot(a[1][k], b[1][k]) for k in (0, 2)), 4.0
