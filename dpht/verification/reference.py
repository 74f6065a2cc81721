"""Brute-force reference of the heat rates: every particle pair, every wall element, plain numpy.

Independent of the compiled path (no cell list, no wall index, its own point-triangle distance)
and of its physics: each mode's conductance is written out again here from the DPHT paper's
equations, in numpy, rather than calling the registry's closures (:mod:`dpht.closures.conductance`)
that the explicit kernel, the network and the screening share, so an error in those is caught
against this. It evaluates the same model (:class:`dpht.thermal.model.ThermalModel`, the same
tables), so the two agree to round-off; it is O(N^2) and only for small N. It knows the six modes
of the paper (default styles) and refuses a model with any other.
"""

from __future__ import annotations

import numpy as np

from dpht.errors import DPHTError
from dpht.thermal.modes import NAMES, PW_MODES, wall_column


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

    ``walls`` is the :class:`dpht.geometry.walls.Walls` the model was built with (or None).
    """
    known(model)
    q = np.zeros(len(positions))
    i, j, d = all_pairs(model, positions)
    flux = pair_conductance(model, d, T[i], T[j]) * (T[j] - T[i])
    np.add.at(q, i, flux)
    np.add.at(q, j, -flux)
    wall_heat = np.zeros(len(PW_MODES))
    for k, e, dw in zip(*wall_contacts(model, positions, walls)):
        Tw = model.element_temperature[e]
        parts = wall_conductance(model, dw, T[k], Tw)
        q[k] += parts.sum() * (Tw - T[k])
        wall_heat += parts * (Tw - T[k])
    return q, wall_heat


def known(model) -> None:
    """Refuse a model this reference cannot check: a mode or style not written out here."""
    unknown = sorted(m for m in model.modes if m not in NAMES or model.laws[m] is not model.registry[m].style().resolve())
    if unknown:
        raise DPHTError(f"the brute-force reference writes out the default styles of {list(NAMES)}, not {unknown}")


def all_pairs(model, positions):
    """Every pair (i < j) closer than the model's largest PP cutoff and its distance (m), by brute force."""
    pos = np.asarray(positions, dtype=np.float64)
    first, second, dist = [], [], []
    for i in range(len(pos) - 1):
        j = np.arange(i + 1, len(pos))
        d = np.linalg.norm(pos[j] - pos[i], axis=1)
        close = d < model.pair_cutoff
        first.append(np.full(np.count_nonzero(close), i))
        second.append(j[close])
        dist.append(d[close])
    if not first or not model.modes & {"pp_contact", "pfp", "pp_radiation"}:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    return np.concatenate(first), np.concatenate(second), np.concatenate(dist)


def pair_conductance(model, d, Ti, Tj):
    """Conductance (W/K) of pairs at centre distance ``d`` (m) and temperatures ``Ti``, ``Tj`` (K)."""
    R = model.radius
    on, tables, c = model.modes, model.tables, model.pair.softening
    Tm = 0.5 * (Ti + Tj)
    overlap = np.maximum(R**2 - d**2 / 4, 0.0)
    G = np.zeros(np.shape(d))
    if "pp_contact" in on:
        G += 2 * c * _k(tables["pp_contact"], Tm) * np.sqrt(overlap)  # Eqs. 2-4
    if "pfp" in on:
        d_real = np.where(overlap > 0, 2 * np.sqrt(R**2 - c**2 * overlap), d)  # Eq. 17
        G += np.where(d < model.cutoffs["pfp"], interpolate_uniform(tables["pfp"], d_real, Tm), 0.0)
    if "pp_radiation" in on:
        D = _rdf(tables["pp_radiation"], (d / R) ** 2)
        radiating = d < model.cutoffs["pp_radiation"]
        G += np.where(radiating, model.parameters["pp_radiation"].coefficient * D * (Ti**2 + Tj**2) * (Ti + Tj), 0.0)  # Eq. 25
    return G


def wall_conductance(model, d, Ti, Tw):
    """Conductances (W/K) of one particle-wall contact per PW mode (columns of PW_MODES)."""
    R, on = model.radius, model.modes
    tables, c = model.tables, model.wall.softening
    parts = np.zeros(len(PW_MODES))
    overlap = max(R**2 - d**2, 0.0)
    Tm = 0.5 * (Ti + Tw)
    if "pw_contact" in on:
        parts[wall_column("pw_contact")] = _k(tables["pw_contact"], Tm) * c * np.sqrt(overlap)  # Eqs. 5-6
    if "pfw" in on and d < model.cutoffs["pfw"]:
        d_real = np.sqrt(R**2 - c**2 * overlap) if overlap > 0 else d  # Eq. 24
        parts[wall_column("pfw")] = interpolate_uniform(tables["pfw"], d_real, Tm)
    if "pw_radiation" in on and d < model.cutoffs["pw_radiation"]:
        D = _rdf(tables["pw_radiation"], (d / R) ** 2)
        parts[wall_column("pw_radiation")] = model.parameters["pw_radiation"].coefficient * D * (Ti**2 + Tw**2) * (Ti + Tw)  # Eq. 26
    return parts


def steady_state(model, positions, walls, T_guess, tolerance=1e-11, max_iterations=50):
    """The steady temperatures (K) of a bed's conductance network, q(T) = 0, by Newton's method.

    Brute-force pairs and wall contacts, every conductance at its temperatures (k(T), the HTC
    tables' temperature dependence through the gas conductivity, the radiation of Eqs. 25-26); the
    Jacobian of each pair's and contact's heat by central differences (1e-3 K), each Newton step a
    direct sparse solve (scipy's SuperLU). Needs at least one Dirichlet wall contact. Returns the
    temperatures and the last Newton correction's largest magnitude (K).
    """
    import scipy.sparse as sparse
    from scipy.sparse.linalg import spsolve

    known(model)
    i, j, d = all_pairs(model, positions)
    k, e, dw = wall_contacts(model, positions, walls)
    Tw = model.element_temperature[e]
    n, eps = len(positions), 1e-3
    T = np.array(T_guess, dtype=float)

    def pair_flux(Ti, Tj):
        return pair_conductance(model, d, Ti, Tj) * (Tj - Ti)

    def wall_flux(Ti):
        return np.array([wall_conductance(model, a, b, c).sum() for a, b, c in zip(dw, Ti, Tw)]) * (Tw - Ti)

    for _ in range(max_iterations):
        f = pair_flux(T[i], T[j])
        q = np.zeros(n)
        np.add.at(q, i, f)
        np.add.at(q, j, -f)
        np.add.at(q, k, wall_flux(T[k]))
        dfi = (pair_flux(T[i] + eps, T[j]) - pair_flux(T[i] - eps, T[j])) / (2 * eps)  # d f / d T_i
        dfj = (pair_flux(T[i], T[j] + eps) - pair_flux(T[i], T[j] - eps)) / (2 * eps)
        dw_i = (wall_flux(T[k] + eps) - wall_flux(T[k] - eps)) / (2 * eps)
        rows = np.concatenate([i, i, j, j, k])
        cols = np.concatenate([i, j, i, j, k])
        values = np.concatenate([dfi, dfj, -dfi, -dfj, dw_i])
        J = sparse.csr_matrix((values, (rows, cols)), shape=(n, n))
        step = spsolve(J.tocsc(), -q)
        T += step
        if np.max(np.abs(step)) <= tolerance:
            break
    return T, float(np.max(np.abs(step)))


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
