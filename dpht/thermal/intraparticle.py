"""Resolved intra-particle conduction: each particle a 1-D sphere of n shells (ParScale, Eqs. 1-3).

ParScale (Radl et al. 2015) solves rho c_p dT/dt = div(lambda grad T) (Eq. 1), for constant lambda
dT/dt = a (T_rr + 2 T_r / r) (Eq. 3), on equidistant radial points with second-order central
differences. Here the same equation is discretised to fourth order in the spacing, conservatively:

- **Nodes.** Node k sits at r_k = (k + 1) h, h = a / n, k = 0 .. n - 1: node n - 1 on the surface
  (its temperature is the one the six surface modes of the DPHT paper see), no node at the centre.
- **Scheme.** With u = r T, Eq. 3 is the Cartesian u_t = D u_rr with u = 0 at the centre. The
  compact (Pade) scheme (u_t,k-1 + 10 u_t,k + u_t,k+1) h / 12 = D (u_k+1 - 2 u_k + u_k-1) / h is
  fourth order; at the surface node, whose half cell takes the surface heat, the fourth-order
  closure (7 u_t,N + 6 u_t,N-1 - u_t,N-2) h / 24 = D u_r(a) - D (u_N - u_N-1) / h follows from
  Taylor series (u_rt and u_rrt one-sided from the three outer nodes; it needs nothing of the
  surface condition, so the surface heat can come from any mode). Multiplying row k by 4 pi r_k
  turns it into a balance of energy (W) in T: the conduction between nodes k and k + 1 is
  K (T_k+1 - T_k) with K = lambda 4 pi r_k r_k+1 / h (the steady conductance of the shell between
  them), and the capacities form a matrix C_kj = rho 4 pi r_k r_j c_kj (c the compact weights above
  times h), tridiagonal but for one entry (n - 1, n - 3). Its column sums, the nodes' shares of the
  particle's mass (:attr:`ShellGrid.weight`), add up to the sphere's mass exactly.
- **State.** The specific enthalpy h_k (J/kg) of every node; temperatures come from the same
  enthalpy table as the lumped particles (:mod:`dpht.closures.heat_capacity`), so c_p(T) enters
  through h(T) (the capacity matrix acts on enthalpy changes), and lambda(T) at the mean of two
  node temperatures (a table in T, as for contact conduction). With either temperature dependent
  the scheme stays conservative and second order; the fourth order is that of constant properties.
- **Surface.** A given heat rate q (W, from the surface modes) and an optional Robin condition
  h_conv A (T_gas - T_surface) (ParScale's convective cooling; A = 4 pi a^2) act on the surface node.
- **Time.** Backward Euler per particle: sum_j C_kj (h_j' - h_j) = dt (conduction + surface heat) at
  the new temperatures, linearised about an iterate (c_p and lambda at the iterate; ``iterations``
  > 1 repeats the solve about the new iterate, Newton for c_p, Picard for lambda). One elimination
  per particle from the centre outwards leaves one equation for the surface node
  (:func:`_eliminate`), which is solved directly, or, with the implicit integrator, joined to the
  frame's network (:func:`condense`, a Schur complement per particle: the network keeps its
  sparsity, only its diagonal and right-hand side change), then the interior follows by back
  substitution.
- **Energy.** The enthalpies are then updated in flux form: writing C = diag(column sums) + E, each
  off-diagonal capacity entry moves C_kj dh_j / dt (W) from node k to node j and the conduction
  moves K (T_k+1 - T_k) from k + 1 to k, every flux added to one node and taken from the other, so
  the particle's energy change, sum_k m w_k dh_k, equals dt (q + Robin heat) to round-off whether or
  not the iteration has converged (and it equals the solve's increments when it has).

Stability and the maximum principle: the elimination needs no pivoting (the matrix is strictly
diagonally dominant by rows) and backward Euler is unconditionally stable. The capacity matrix's
positive off-diagonal entries make the step an M-matrix (so every node stays inside the range of
its old values and the surface temperatures) only for dt >= h^2 / (4 D) (D = lambda / (rho c_p));
shorter steps can undershoot transiently, by about 1% of a sudden jump of the surface temperature
(README, "Resolved intra-particle conduction"). Energy stays exact either way.

Kernels take plain arrays and the typed record :class:`ShellGrid`; parallel over particles, each
particle's arithmetic in a fixed order, so results are bit-identical for any thread count.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from dpht.closures.heat_capacity import temperature_at
from dpht.util.interp import table_1d

# Compact weights of one node's row, times h (module docstring): interior (neighbour, own), and the
# surface node's own, inner neighbour's and second neighbour's.
INTERIOR = (1.0 / 12.0, 10.0 / 12.0)
SURFACE = (7.0 / 24.0, 6.0 / 24.0, -1.0 / 24.0)


class ShellGrid(NamedTuple):
    """Geometry and capacities of the n nodes of a sphere of radius a (module docstring); the
    capacities are fractions of the particle's mass (kg/kg): C_kj / m."""

    radius: float  # m, a
    weight: np.ndarray  # (n,) node k's share of the particle's mass in the energy books (column sums of C / m)
    diagonal: np.ndarray  # (n,) C_kk / m
    upper: np.ndarray  # (n - 1,) C_k,k+1 / m
    lower: np.ndarray  # (n - 1,) C_k+1,k / m
    corner: float  # C_n-1,n-3 / m (0 for n = 2)
    face: np.ndarray  # (n - 1,) m, 4 pi r_k r_k+1 / h: times lambda, the conductance between nodes k, k+1
    surface_area: float  # m2, 4 pi a^2
    outer: float  # 1 / (m C^-1)_n-1,n-1: the surface node's effective share of the mass for a short step

    @property
    def n(self) -> int:
        return self.weight.size

    @property
    def nodes(self) -> np.ndarray:
        """r_k (m) of the nodes."""
        return self.radius * np.arange(1, self.n + 1) / self.n

    def capacity_matrix(self) -> np.ndarray:
        """C / m as a dense (n, n) array (for tests and checks; the kernels use the diagonals)."""
        n = self.n
        C = np.diag(self.diagonal) + np.diag(self.upper, 1) + np.diag(self.lower, -1)
        if n > 2:
            C[n - 1, n - 3] = self.corner
        return C


def grid(radius: float, n: int) -> ShellGrid:
    """The nodes of a sphere of ``radius`` (m) with ``n`` >= 2 nodes."""
    if n < 2:
        raise ValueError(f"intra-particle conduction needs at least 2 shells, got {n}")
    k = np.arange(1, n + 1, dtype=float)  # r_k / h
    c = np.zeros((n, n))  # compact weights (times h) of the rows, in u = r T
    for i in range(n - 1):
        c[i, i] = INTERIOR[1]
        c[i, i + 1] = INTERIOR[0]
        if i > 0:
            c[i, i - 1] = INTERIOR[0]
    c[n - 1, n - 1], c[n - 1, n - 2] = SURFACE[0], SURFACE[1]
    if n > 2:  # for n = 2 the second neighbour is the centre, where u = 0
        c[n - 1, n - 3] = SURFACE[2]
    # C_kj / m = rho 4 pi r_k r_j c_kj h / (rho 4 pi a^3 / 3) = 3 k j c_kj / n^3 (r in units of h)
    C = 3.0 * np.outer(k, k) * c / n**3
    weight = C.sum(axis=0)
    step = radius / n
    return ShellGrid(
        radius=float(radius),
        weight=np.ascontiguousarray(weight),
        diagonal=np.ascontiguousarray(np.diag(C)),
        upper=np.ascontiguousarray(np.diag(C, 1)),
        lower=np.ascontiguousarray(np.diag(C, -1)),
        corner=float(C[n - 1, n - 3]) if n > 2 else 0.0,
        face=np.ascontiguousarray(4.0 * math.pi * k[:-1] * k[1:] * step),
        surface_area=4.0 * math.pi * radius**2,
        outer=float(1.0 / np.linalg.inv(C)[n - 1, n - 1]),
    )


class Surface(NamedTuple):
    """The Robin condition on the surface: h_conv A (T_gas - T_surface) W into the particle."""

    coefficient: float  # W/(m2 K), h_conv; 0 for none
    gas_temperature: float  # K


NO_CONVECTION = Surface(0.0, 0.0)
CHUNK = 256  # particles per parallel task (work arrays are allocated once per task)


class Work(NamedTuple):
    """Per-particle work arrays of one linearised solve (n = nodes)."""

    slope: np.ndarray  # (n,) J/(kg K), dh/dT at the iterate
    excess: np.ndarray  # (n,) J/kg, h(iterate) - h (the enthalpy the step starts from)
    K: np.ndarray  # (n - 1,) W/K, face conductances at the iterate
    pivot: np.ndarray  # (n,) J/K, of the elimination
    upper: np.ndarray  # (n - 1,) J/K, super-diagonal of the Jacobian
    rhs: np.ndarray  # (n,) J, eliminated right-hand side
    delta: np.ndarray  # (n,) K, the correction


@nb.njit(cache=True)
def _work(n):
    return Work(np.empty(n), np.empty(n), np.empty(n - 1), np.empty(n), np.empty(n - 1), np.empty(n), np.empty(n))


@nb.njit(cache=True)
def _work_rows(work, P, U, Y, i):
    """:class:`Work` whose pivots, super-diagonal and right-hand side are row ``i`` of ``P, U, Y``
    (kept for the back substitution after the network solve)."""
    return Work(work.slope, work.excess, work.K, P[i], U[i], Y[i], work.delta)


@nb.njit(cache=True, parallel=True)
def advance(H, rows, q, dt, steps, mass, shells, surface, T0, dT, h_table, guide, guide_step, k_table, iterations,
            convected):  # fmt: skip
    """Advance the node enthalpies ``H[rows[i]]`` (J/kg, an (N, n) array) over ``steps`` steps of
    ``dt`` (s) with the surface heat ``q[i]`` (W) held constant.

    ``mass`` (kg) of one particle; ``shells`` a :class:`ShellGrid`, ``surface`` a :class:`Surface`;
    ``T0, dT, h_table, guide, guide_step`` the enthalpy table (``EnthalpyTable.arrays``); ``k_table`` a
    :class:`dpht.util.interp.Table1D` of lambda (W/(m K)) over T (K). ``convected[i]`` gains the
    Robin heat (J) into particle i over the call.
    """
    n = H.shape[1]
    chunks = (rows.size + CHUNK - 1) // CHUNK
    for c in nb.prange(chunks):  # work arrays once per chunk of particles, not per particle
        T = np.empty(n)
        work = _work(n)
        for i in range(c * CHUNK, min((c + 1) * CHUNK, rows.size)):
            heat = 0.0
            for _ in range(steps):
                heat += _step(H, rows[i], T, q[i], dt, mass, shells, surface, T0, dT, h_table, guide, guide_step, k_table,
                              iterations, work)  # fmt: skip
            convected[i] += heat


@nb.njit(cache=True)
def _step(H, row, T, q, dt, mass, shells, surface, T0, dT, h_table, guide, guide_step, k_table, iterations, work):
    """One step of particle ``row`` (:func:`advance`); returns the Robin heat (J)."""
    n = T.size
    for k in range(n):
        T[k] = temperature_at(H[row, k], T0, dT, h_table, guide, guide_step)
    for _ in range(iterations):
        _assemble(H, row, T, q, dt, mass, shells, surface, T0, dT, h_table, k_table, work)
        work.delta[n - 1] = work.rhs[n - 1] / work.pivot[n - 1]
        _back_substitute(work)
        for k in range(n):
            T[k] += work.delta[k]
    for k in range(n):  # the linearised enthalpy increments the solve stands for
        work.excess[k] += work.slope[k] * work.delta[k]
    return dt * _conservative_update(H, row, T, work.excess, q, dt, mass, shells, surface, work.K)


@nb.njit(cache=True, fastmath={"contract"})
def _assemble(H, row, T, q, dt, mass, shells, surface, T0, dT, h_table, k_table, work):
    """The backward-Euler step of particle ``row`` linearised about the iterate ``T`` (K), in
    correction form J delta = -R (J/K and J), eliminated from the centre outwards (:func:`_eliminate`).

    R_k = sum_j m C_kj (h(T_j) - H_j) - dt (conduction into k + [surface] (q + h_conv A (T_gas - T_k))),
    J = m C diag(dh/dT) + dt (conductance matrix + [surface] h_conv A), lambda at the iterate.
    Leaves the slopes, h(T) - H, the face conductances and the elimination in ``work``.
    """
    n = T.size
    K, slope, excess, rhs = work.K, work.slope, work.excess, work.rhs
    for f in range(n - 1):
        K[f] = table_1d(k_table, 0.5 * (T[f] + T[f + 1])) * shells.face[f]
    inv_dT = 1.0 / dT
    for k in range(n):  # h(T) and its slope from one interval of the table (as enthalpy_at, clamped)
        x = (T[k] - T0) * inv_dT
        j = min(max(int(x), 0), h_table.size - 2)
        f = min(max(x - j, 0.0), 1.0)
        dh = h_table[j + 1] - h_table[j]
        slope[k] = dh * inv_dT
        excess[k] = h_table[j] + f * dh - H[row, k]
    hA = surface.coefficient * shells.surface_area
    for k in range(n):  # -R: capacities times h(T) - H, then the conduction
        r = shells.diagonal[k] * excess[k]
        if k > 0:
            r += shells.lower[k - 1] * excess[k - 1]
        if k < n - 1:
            r += shells.upper[k] * excess[k + 1]
        rhs[k] = -mass * r
    if n > 2:
        rhs[n - 1] -= mass * shells.corner * excess[n - 3]
    for f in range(n - 1):
        flow = dt * K[f] * (T[f + 1] - T[f])  # J into node f
        rhs[f] += flow
        rhs[f + 1] -= flow
    rhs[n - 1] += dt * (q + hA * (surface.gas_temperature - T[n - 1]))
    _eliminate(mass, dt, shells, hA, work)


@nb.njit(cache=True, fastmath={"contract"})
def _eliminate(mass, dt, shells, hA, work):
    """Forward elimination of the Jacobian (from the slopes and conductances in ``work``) and of
    ``work.rhs`` from the centre outwards; the surface row ends as ``pivot[n-1] delta[n-1] =
    rhs[n-1]``: its pivot is the Schur complement of the interior (J/K).

    The corner entry (n - 1, n - 3) is eliminated with the already reduced row n - 3 before the
    last step, so rows 0 .. n - 2 stay upper bidiagonal for :func:`_back_substitute`.
    """
    slope, K, pivot, upper, rhs = work.slope, work.K, work.pivot, work.upper, work.rhs
    n = slope.size
    diag = mass * shells.diagonal[0] * slope[0] + dt * K[0]
    pivot[0] = diag
    for k in range(1, n):
        upper[k - 1] = mass * shells.upper[k - 1] * slope[k] - dt * K[k - 1]
        sub = mass * shells.lower[k - 1] * slope[k - 1] - dt * K[k - 1]
        diag = mass * shells.diagonal[k] * slope[k] + dt * K[k - 1]
        if k < n - 1:
            diag += dt * K[k]
        else:
            diag += dt * hA
            if n > 2:  # the corner, with row n - 3 (pivot and upper entry into n - 2)
                factor = mass * shells.corner * slope[n - 3] / pivot[n - 3]
                sub -= factor * upper[n - 3]
                rhs[k] -= factor * rhs[n - 3]
        factor = sub / pivot[k - 1]
        pivot[k] = diag - factor * upper[k - 1]
        rhs[k] -= factor * rhs[k - 1]


@nb.njit(cache=True, fastmath={"contract"})
def _back_substitute(work):
    """The interior corrections from the surface node's (``delta[n-1]``, set by the caller)."""
    pivot, upper, rhs, delta = work.pivot, work.upper, work.rhs, work.delta
    for k in range(delta.size - 2, -1, -1):
        delta[k] = (rhs[k] - upper[k] * delta[k + 1]) / pivot[k]


@nb.njit(cache=True, fastmath={"contract"})
def _conservative_update(H, row, T, dh, q, dt, mass, shells, surface, K) -> float:
    """H_k += dt (fluxes into k) / (m w_k) with every flux between two nodes added to one and taken
    from the other (module docstring): conduction K (T_k+1 - T_k) at ``T``, capacity exchanges
    m C_kj dh_j / dt from the enthalpy increments ``dh`` (J/kg) the solve stands for, ``q`` and the
    Robin heat on the surface node. Returns the Robin heat rate (W)."""
    n = T.size
    scale = mass / dt
    robin = surface.coefficient * shells.surface_area * (surface.gas_temperature - T[n - 1])
    inflow = 0.0  # W into node k through its inner face
    corner = 0.0  # W from node n - 3 into the surface node
    if n > 2:
        corner = -scale * shells.corner * dh[n - 3]
    factor = dt / mass
    for k in range(n - 1):
        outflow = K[k] * (T[k + 1] - T[k]) - scale * (shells.upper[k] * dh[k + 1] - shells.lower[k] * dh[k])  # W into k through its outer face
        net = inflow + outflow
        if k == n - 3:
            net -= corner
        H[row, k] += factor * net / shells.weight[k]
        inflow = -outflow
    H[row, n - 1] += factor * (inflow + corner + q + robin) / shells.weight[n - 1]
    return robin


@nb.njit(cache=True, parallel=True)
def condense(H, rows, T, dt, mass, shells, surface, T0, dT, h_table, k_table, pivot, upper, rhs):
    """For the implicit integrator: the backward-Euler step of every particle ``rows[i]`` linearised
    about its node temperatures ``T[i]`` (K, (N, n), frame order) with no surface heat but the
    Robin condition, eliminated onto the surface node (:func:`_assemble`). Returns, per particle,
    the Schur complement (J/K) and the eliminated right-hand side (J) of the surface row, which the
    network adds to its own; keeps the elimination in ``pivot, upper, rhs`` ((N, n), (N, n - 1),
    (N, n)) for :func:`back_substitute`."""
    n = T.shape[1]
    schur = np.empty(rows.size)
    own = np.empty(rows.size)
    chunks = (rows.size + CHUNK - 1) // CHUNK
    for c in nb.prange(chunks):
        work = _work(n)
        for i in range(c * CHUNK, min((c + 1) * CHUNK, rows.size)):
            rows_i = _work_rows(work, pivot, upper, rhs, i)
            _assemble(H, rows[i], T[i], 0.0, dt, mass, shells, surface, T0, dT, h_table, k_table, rows_i)
            schur[i] = pivot[i, n - 1]
            own[i] = rhs[i, n - 1]
    return schur, own


@nb.njit(cache=True, parallel=True)
def back_substitute(T, surface_delta, pivot, upper, rhs) -> float:
    """Add the surface corrections ``surface_delta`` (K) and the interior ones that follow from
    them (the eliminations of :func:`condense`) to ``T`` ((N, n), K); returns the largest |correction|."""
    n = T.shape[1]
    largest = np.zeros(T.shape[0])
    for i in nb.prange(T.shape[0]):
        d = surface_delta[i]
        T[i, n - 1] += d
        big = abs(d)
        for k in range(n - 2, -1, -1):
            d = (rhs[i, k] - upper[i, k] * d) / pivot[i, k]
            T[i, k] += d
            big = max(big, abs(d))
        largest[i] = big
    return largest.max() if largest.size else 0.0


@nb.njit(cache=True, parallel=True)
def commit(H, rows, T, q, dt, mass, shells, surface, T0, dT, h_table, k_table, convected):
    """For the implicit integrator: the flux-form update (:func:`_conservative_update`) of every
    particle ``rows[i]`` to its solved node temperatures ``T[i]`` (K) with the network heat ``q[i]``
    (W) on its surface; the enthalpy increments are h(T) - H, the conductances at T. ``convected[i]``
    gets the Robin heat (J) over the step."""
    n = T.shape[1]
    chunks = (rows.size + CHUNK - 1) // CHUNK
    for c in nb.prange(chunks):
        K = np.empty(n - 1)
        dh = np.empty(n)
        for i in range(c * CHUNK, min((c + 1) * CHUNK, rows.size)):
            row = rows[i]
            for f in range(n - 1):
                K[f] = table_1d(k_table, 0.5 * (T[i, f] + T[i, f + 1])) * shells.face[f]
            for k in range(n):
                x = (T[i, k] - T0) / dT
                j = min(max(int(x), 0), h_table.size - 2)
                f = min(max(x - j, 0.0), 1.0)
                dh[k] = h_table[j] + f * (h_table[j + 1] - h_table[j]) - H[row, k]
            convected[i] = dt * _conservative_update(H, row, T[i], dh, q[i], dt, mass, shells, surface, K)


@nb.njit(cache=True, parallel=True)
def temperatures(H, rows, T0, dT, h_table, guide, guide_step):
    """Node temperatures (K, (N, n)) of each particle ``rows[i]``."""
    n = H.shape[1]
    out = np.empty((rows.size, n))
    for i in nb.prange(rows.size):
        for k in range(n):
            out[i, k] = temperature_at(H[rows[i], k], T0, dT, h_table, guide, guide_step)
    return out


@nb.njit(cache=True, parallel=True)
def surface_temperature(H, rows, T0, dT, h_table, guide, guide_step):
    """Temperature (K) of the surface node of each particle ``rows[i]``."""
    out = np.empty(rows.size)
    n = H.shape[1]
    for i in nb.prange(rows.size):
        out[i] = temperature_at(H[rows[i], n - 1], T0, dT, h_table, guide, guide_step)
    return out


@nb.njit(cache=True, parallel=True)
def mean_enthalpy(H, weight):
    """Mass-weighted mean specific enthalpy (J/kg) of every particle, nodes summed in order."""
    out = np.empty(H.shape[0])
    for i in nb.prange(H.shape[0]):
        s = 0.0
        for k in range(H.shape[1]):
            s += weight[k] * H[i, k]
        out[i] = s
    return out
