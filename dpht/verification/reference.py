"""Brute-force reference of the heat rates: every particle pair, every wall element, plain numpy.

Independent of the compiled path (no cell list, no wall index, its own point-triangle distance),
for tests and benchmarks. It evaluates the same model (:class:`dpht.thermal.model.ThermalModel`, the same
tables), so the two agree to round-off; it is O(N^2) and only for small N.
"""

from __future__ import annotations

import numpy as np

from dpht.thermal.modes import PW_MODES, wall_column


def point_triangle_distance(p, tri):
    """Distance from point ``p`` (3,) to each triangle ``tri`` (M, 3, 3), vectorised.

    Inside the triangle's prism the distance is the plane distance; outside, the nearest of the
    three edge segments.
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    height = np.einsum("ij,ij->i", p - a, n)
    foot = p - height[:, None] * n
    inside = np.ones(len(tri), dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, foot - u), n) >= 0
    edges = np.min([_segment_distance(p, u, v) for u, v in ((a, b), (b, c), (c, a))], axis=0)
    return np.where(inside, np.abs(height), edges)


def _segment_distance(p, u, v):
    d = v - u
    t = np.clip(np.einsum("ij,ij->i", p - u, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    return np.linalg.norm(p - (u + t[:, None] * d), axis=1)


def heat_rates(model, positions, T, walls):
    """Heat into each particle (W) and wall heat per PW mode (W, columns of PW_MODES) for
    temperatures ``T`` (K).

    ``walls`` is the :class:`geometry.walls.Walls` the model was built with (or None).
    """
    R = model.radius
    pos = np.asarray(positions, dtype=np.float64)
    n = len(pos)
    q = np.zeros(n)
    on = model.modes
    pp, pp_tables = model.pair, model.pair_tables
    for i in range(n - 1):
        j = np.arange(i + 1, n)
        d = np.linalg.norm(pos[j] - pos[i], axis=1)
        Tm = 0.5 * (T[i] + T[j])
        overlap = np.maximum(R**2 - d**2 / 4, 0.0)
        G = np.zeros(d.size)
        if "pp_contact" in on:
            G += 2 * pp.softening * _k(pp_tables.pp_contact, Tm) * np.sqrt(overlap)  # Eqs. 2-4
        if "pfp" in on:
            d_real = np.where(overlap > 0, 2 * np.sqrt(R**2 - pp.softening**2 * overlap), d)  # Eq. 17
            G += np.where(d < model.cutoffs["pfp"], interpolate_uniform(pp_tables.pfp, d_real, Tm), 0.0)
        if "pp_radiation" in on:
            D = _rdf(pp_tables.pp_radiation, (d / R) ** 2)
            radiating = d < model.cutoffs["pp_radiation"]
            G += np.where(radiating, pp.radiation_coefficient * D * (T[i] ** 2 + T[j] ** 2) * (T[i] + T[j]), 0.0)
        flux = G * (T[j] - T[i])
        q[i] += flux.sum()
        q[j] -= flux
    wall_heat = np.zeros(len(PW_MODES))
    if walls is None or not model.zones:
        return q, wall_heat
    pw, pw_tables = model.wall, model.wall_tables
    element_T = model.element_temperature
    for zone in range(len(walls.zone_names)):
        members = np.flatnonzero((walls.zone == zone) & np.isfinite(element_T))
        if members.size == 0:
            continue
        for i in range(n):
            distances = point_triangle_distance(pos[i], walls.vertices[members])
            k = int(np.argmin(distances))
            d = distances[k]
            if d >= model.wall_cutoff:
                continue
            Tw = element_T[members[k]]
            parts = np.zeros(len(PW_MODES))
            overlap = max(R**2 - d**2, 0.0)
            Tm = 0.5 * (T[i] + Tw)
            if "pw_contact" in on:
                parts[wall_column("pw_contact")] = _k(pw_tables.pw_contact, Tm) * pw.softening * np.sqrt(overlap)  # Eqs. 5-6
            if "pfw" in on and d < model.cutoffs["pfw"]:
                d_real = np.sqrt(R**2 - pw.softening**2 * overlap) if overlap > 0 else d  # Eq. 24
                parts[wall_column("pfw")] = interpolate_uniform(pw_tables.pfw, d_real, Tm)
            if "pw_radiation" in on and d < model.cutoffs["pw_radiation"]:
                D = _rdf(pw_tables.pw_radiation, (d / R) ** 2)
                parts[wall_column("pw_radiation")] = pw.radiation_coefficient * D * (T[i] ** 2 + Tw**2) * (T[i] + Tw)
            q[i] += parts.sum() * (Tw - T[i])
            wall_heat += parts * (Tw - T[i])
    return q, wall_heat


def interpolate_uniform(table, x, y):
    """Bilinear interpolation in a :class:`dpht.util.interp.Table2D` with numpy, clamped at the edges."""
    x0, dx, y0, dy, values = table
    u = np.clip((np.asarray(x, float) - x0) / dx, 0, values.shape[0] - 1)
    v = np.clip((np.asarray(y, float) - y0) / dy, 0, values.shape[1] - 1)
    k = np.minimum(u.astype(int), values.shape[0] - 2)
    m = np.minimum(v.astype(int), values.shape[1] - 2)
    f, g = u - k, v - m
    return (1 - f) * ((1 - g) * values[k, m] + g * values[k, m + 1]) + f * ((1 - g) * values[k + 1, m] + g * values[k + 1, m + 1])


def _k(table, T):
    """Conductivity from a uniform temperature table (:class:`dpht.util.interp.Table1D`)."""
    T0, dT, values = table
    return np.interp(T, T0 + dT * np.arange(values.size), values)


def _rdf(table, u):
    """RDF at squared distances ``u`` (radii^2) from the model's table."""
    x0, dx, values = table
    return np.interp(u, x0 + dx * np.arange(values.size), values)
