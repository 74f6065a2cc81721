"""Small synthetic scenes for verification, tests and benchmarks: specs, walls, tables, packings.

Not used by the workflow, which builds everything from the config.
"""

from __future__ import annotations

import copy

import numpy as np

from dpht import config
from dpht.closures import gas, htc, rdf
from dpht.thermal import integrate, model as thermal_model, modes
from dpht.geometry.walls import Walls

RADIUS = 5e-4

BASE_SPEC = {
    "particles": {
        "diameter": 2 * RADIUS,
        "density": 3560.0,
        "youngs_modulus_dem": 5.0e6,
        "youngs_modulus_real": 205.0e9,
        "poisson_ratio": 0.3,
        "conductivity": 2.0,
        "specific_heat": 1000.0,
        "emissivity": 0.65,
    },
    "wall": {
        "youngs_modulus_dem": 5.0e6,
        "youngs_modulus_real": 200.0e9,
        "poisson_ratio": 0.3,
        "conductivity": 14.5,
        "emissivity": 0.6,
    },
    "thermal": {
        "gas": "air",
        "gas_pressure": gas.ATMOSPHERE,  # the config's default
        "solid_fraction": 0.6,
        "modes": {m: False for m in modes.NAMES},
        "initial_temperature": 300.0,
        "inlet_temperature": 800.0,  # with the initial temperature, the range the enthalpy table covers
        "walls": {"hot": {"temperature": 600.0}},
        "pfp_cutoff": 3.0,
        "pfw_cutoff": 1.5,
        "radiation_cutoff": 7.0,
        "htc_table": {"distances": 200, "temperatures": 64, "temperature_range": [250.0, 1400.0]},
        "frame_stride": 1,
        "max_substeps": 1000,
    },
}


def spec(modes=(), **thermal):
    """A thermal spec with the given modes enabled and thermal keys overridden."""
    s = copy.deepcopy(BASE_SPEC)
    for m in modes:
        s["thermal"]["modes"][m] = True
    s["thermal"].update(thermal)
    return s


def plane_walls(z=0.0, half=0.02, zone="hot", n=8):
    """A square plane z = const of 2 n^2 triangles, normal +z, in one zone."""
    xs = np.linspace(-half, half, n + 1)
    tris = []
    for a in range(n):
        for b in range(n):
            p = [(xs[a], xs[b]), (xs[a + 1], xs[b]), (xs[a + 1], xs[b + 1]), (xs[a], xs[b + 1])]
            p = [np.array([x, y, z]) for x, y in p]
            tris += [[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
    vertices = np.array(tris)
    return Walls.from_vertices(vertices, np.zeros(len(vertices), dtype=np.int32), [zone])


def htc_tables(s):
    """The PFP and PFW tables for a thermal spec, built as the workflow's htc_table stage does."""
    return {kind: htc.table_from_spec(config.htc_spec(s, kind)) for kind in ("pfp", "pfw")}


def build_model(s, walls=None, rdf_tables=None):
    return thermal_model.build(s, walls, htc_tables(s), rdf_tables)


def random_cluster(n=400, seed=0, solid_fraction=0.45, radius=RADIUS):
    """Random (overlapping) particle centres in a cube above the plane z = 0, none below 0.95 R."""
    rng = np.random.default_rng(seed)
    side = (n * 4 / 3 * np.pi * radius**3 / solid_fraction) ** (1 / 3)
    return rng.uniform([0, 0, 0.95 * radius], [side, side, side], size=(n, 3))


def advance(model, positions, h, dt, steps, box=None):
    """Advance enthalpies ``h`` in place over ``steps`` frames of ``dt`` with fixed positions.

    Returns the frame, the work arrays of the last evaluation and one step report per frame.
    """
    lo, hi, periodic = (None, None, (False, False, False)) if box is None else box
    frame = integrate.prepare_frame(model, positions, lo, hi, periodic)
    rates = integrate.Rates.for_frame(model, frame)
    reports = [integrate.advance(model, frame, h, dt, rates) for _ in range(steps)]
    return frame, rates, reports


def on_threads(run, counts=(1, 2)) -> list:
    """``run()`` once with each numba thread count of ``counts``; their results (the thread count
    is restored afterwards)."""
    import numba

    saved = numba.get_num_threads()
    try:
        results = []
        for threads in counts:
            numba.set_num_threads(threads)
            results.append(run())
        return results
    finally:
        numba.set_num_threads(saved)


def synthetic_rdf():
    """Smooth made-up RDF tables (decaying with distance) in the dpht.closures.rdf format, for tests."""
    phi = np.array([0.45, 0.55, 0.64])
    d = np.linspace(2.0, 8.0, 13)
    pp = 0.2 * np.exp(-(d[None, :] - 2.0)) * (1 + phi[:, None])
    dw = np.linspace(1.0, 8.0, 15)
    pw = 0.4 * np.exp(-(dw[None, :] - 1.0)) * (1 + phi[:, None])
    return rdf.RDFTables(rdf.RDFTable(d, phi, pp, np.zeros_like(pp)), rdf.RDFTable(dw, phi, pw, np.zeros_like(pw)), 0.65, 0.6)


def tube_walls(radius: float, length: float, element: float, zone: str = "hot"):
    """A faceted cylinder wall r = radius, z in [0, length], triangles about ``element`` wide."""
    n_theta = max(12, int(np.ceil(2 * np.pi * radius / element)))
    vertices = cylinder_triangles(radius, 0.0, length, n_theta, max(1, int(np.ceil(length / element))))
    return Walls.from_vertices(vertices, np.zeros(len(vertices), dtype=np.int32), [zone])


def cylinder_triangles(radius: float, z0: float, z1: float, n_theta: int, n_z: int) -> np.ndarray:
    """Triangles (M, 3, 3) of the cylinder r = radius between z0 and z1, corners on the cylinder:
    ``n_theta`` facets around, ``n_z`` rows along z, two triangles each."""
    theta = np.linspace(0, 2 * np.pi, n_theta + 1)
    z = np.linspace(z0, z1, n_z + 1)
    ring = np.stack([radius * np.cos(theta), radius * np.sin(theta)], axis=1)
    tris = []
    for k in range(n_z):
        for m in range(n_theta):
            p00, p01 = (*ring[m], z[k]), (*ring[m + 1], z[k])
            p10, p11 = (*ring[m], z[k + 1]), (*ring[m + 1], z[k + 1])
            tris += [[p00, p01, p11], [p00, p11, p10]]
    return np.array(tris, dtype=np.float64)


def dense_tube_bed(n: int, *, solid_fraction=0.6, radius=RADIUS, aspect=5.0, jitter=0.05, seed=0):
    """About ``n`` particles at ``solid_fraction`` filling a periodic tube of length aspect x diameter.

    A face-centred cubic lattice diluted to the solid fraction, each centre displaced uniformly by
    up to ``jitter`` diameters per axis, so neighbour distances spread around contact as in a
    dense bed. Returns ``(positions, tube_radius, length)``.
    """
    volume = n * 4 / 3 * np.pi * radius**3 / solid_fraction
    diameter = (4 * volume / (np.pi * aspect)) ** (1 / 3)
    for _ in range(50):  # centres stay a radius from the wall: size the tube for that inner volume
        diameter = (4 * volume / (np.pi * aspect)) ** (1 / 3) * diameter / (diameter - 2 * radius) ** (2 / 3) / diameter ** (1 / 3)
    length = aspect * diameter
    spacing = (4 * 4 / 3 * np.pi * radius**3 / solid_fraction) ** (1 / 3)  # 4 particles per cubic cell
    n_cells_z = max(1, int(round(length / spacing)))
    spacing_z = length / n_cells_z  # whole cells along the periodic axis
    half = diameter / 2
    cells = np.arange(-int(half / spacing) - 1, int(half / spacing) + 2)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    a, b, c = np.meshgrid(cells, cells, np.arange(n_cells_z), indexing="ij")
    corners = np.stack([a.ravel(), b.ravel(), c.ravel()], axis=1)
    points = (corners[:, None, :] + basis[None, :, :]).reshape(-1, 3) * [spacing, spacing, spacing_z]
    rng = np.random.default_rng(seed)
    points += rng.uniform(-jitter, jitter, points.shape) * 2 * radius
    points[:, 2] %= length
    inside = np.hypot(points[:, 0], points[:, 1]) < half - radius
    return points[inside], half, length


def lattice_bed(shape=(6, 6, 4), *, radius=RADIUS, spacing=1.98, jitter=0.02, seed=0):
    """A simple cubic bed of ``shape`` particles, ``spacing`` radii apart (touching neighbours
    overlap slightly, as in a DEM bed), each centre displaced uniformly by up to ``jitter`` radii
    per axis; the lowest layer's centres lie ``spacing / 2`` radii above z = 0. Returns ``(positions,
    height)``, height the z of a wall as far above the top layer."""
    a, b, c = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    points = (np.stack([a.ravel(), b.ravel(), c.ravel()], axis=1) + 0.5) * spacing * radius
    points += np.random.default_rng(seed).uniform(-jitter, jitter, points.shape) * radius
    return points, shape[2] * spacing * radius


def slab_walls(height: float, half: float, zones=("hot", "cold"), n=4):
    """Two square planes z = 0 (zone ``zones[0]``, facing up) and z = height (``zones[1]``), each of
    2 n^2 triangles spanning [-half, half] in x and y."""
    low, high = plane_walls(0.0, half, zones[0], n), plane_walls(height, half, zones[1], n)
    vertices = np.concatenate([low.vertices, high.vertices])
    zone = np.concatenate([np.zeros(len(low.area), np.int32), np.ones(len(high.area), np.int32)])
    return Walls.from_vertices(vertices, zone, list(zones))
