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
    pw, pw_tables = model.wall, model.wall_tables
    element_T = model.element_temperature
    for i, e, d in zip(*wall_contacts(model, pos, walls)):
        Tw = element_T[e]
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


def wall_contacts(model, positions, walls):
    """Each particle's contact with each wall surface of the model, by brute force: at the nearest
    point of the surface over all its elements (adiabatic ones included), kept if that element is
    Dirichlet and the point within the wall cutoff; ``(particle, element, distance)`` arrays.

    Mesh surfaces: every triangle. Surfaces the DEM saw as primitives: the distance from the point
    (rho, z) to each piece's segment in the half-plane (a closed form of its own here), and the
    element the nearest triangle of the nearest piece's zone.
    """
    out = ([], [], [])
    element_T = model.element_temperature
    pos = np.asarray(positions, dtype=np.float64)
    for surface in model.surfaces:
        on = np.flatnonzero(walls.surface == walls.surface_names.index(surface.name))
        if surface.mesh is not None:
            for i, p in enumerate(pos):
                distances = point_triangle_distance(p, walls.vertices[on])
                k = int(np.argmin(distances))
                if distances[k] < model.wall_cutoff and np.isfinite(element_T[on[k]]):
                    for a, v in zip(out, (i, on[k], distances[k])):
                        a.append(v)
            continue
        pieces = [q for q in walls.primitives if walls.primitive_surface(q) == walls.surface_names.index(surface.name)]
        rho, z = np.hypot(pos[:, 0], pos[:, 1]), pos[:, 2]
        to_piece = np.array([_segment_distance_2d(rho, z, *q.segment) for q in pieces])  # (K, N)
        nearest = np.argmin(to_piece, axis=0)
        for i, p in enumerate(pos):
            d = to_piece[nearest[i], i]
            members = on[walls.zone[on] == walls.zone_names.index(pieces[nearest[i]].zone)]
            e = members[int(np.argmin(point_triangle_distance(p, walls.vertices[members])))]
            if d < model.wall_cutoff and np.isfinite(element_T[e]):
                for a, v in zip(out, (i, e, d)):
                    a.append(v)
    return np.array(out[0], dtype=int), np.array(out[1], dtype=int), np.array(out[2], dtype=float)


def _segment_distance_2d(rho, z, r0, z0, r1, z1):
    """Distance (m) from the points (rho, z) of the half-plane to the segment (r0, z0)-(r1, z1)."""
    d = np.array([r1 - r0, z1 - z0])
    t = np.clip(((rho - r0) * d[0] + (z - z0) * d[1]) / (d @ d), 0.0, 1.0)
    return np.hypot(rho - (r0 + t * d[0]), z - (z0 + t * d[1]))


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
