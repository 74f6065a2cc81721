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
  (:func:`_assemble`), which is solved directly, or, with the implicit integrator, joined to the
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
shorter steps can undershoot transiently inside the particle, by 0.01% to 1.6% of a sudden jump
of the surface temperature at Bi 0.16 to 32 (README, "Resolved intra-particle conduction").
Energy stays exact either way.

Kernels take plain arrays and the typed records :class:`ShellGrid`, :class:`Surface` and
:class:`Work`; parallel over chunks of particles and within a chunk in batches (:data:`BATCH`),
each particle's arithmetic in a fixed order, so results are bit-identical for any thread count.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from dpht.closures.heat_capacity import temperature_and_slope_at, temperature_at
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
    inverse_weight: np.ndarray  # (n,) 1 / weight
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
        inverse_weight=np.ascontiguousarray(1.0 / weight),
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
# One solve of a particle's nodes (a step of :func:`advance`, or :func:`condense` with the back
# substitution) costs about this many lumped rate evaluations per node (all six modes;
# benchmarks/thermal_step.py --shells: about 0.03 at 5 to 20 nodes), for auto's cost estimates.
COST_PER_NODE = 0.03
CHUNK = 256  # particles per parallel task (work arrays are allocated once per task)
# Particles solved together: every node loop runs over the batch, so the CPU has independent work
# while one particle's elimination waits on its last division and one row of H on memory.
BATCH = 8


class Work(NamedTuple):
    """Work arrays of one batch of particles, (n, BATCH): node k of the batch's particle b at [k, b]."""

    T: np.ndarray  # K, the iterate
    slope: np.ndarray  # J/(kg K), dh/dT at the iterate
    excess: np.ndarray  # J/kg, h(iterate) - H (H the enthalpy the step starts from)
    K: np.ndarray  # W/K, conductance of the face to node k + 1 at the iterate
    pivot: np.ndarray  # K/J, reciprocal pivots of the elimination
    upper: np.ndarray  # J/K, super-diagonal of the Jacobian (row k, column k + 1)
    rhs: np.ndarray  # J, eliminated right-hand side; the correction (K) after the back substitution


@nb.njit(cache=True)
def _work(n):
    shape = (n, BATCH)
    return Work(np.zeros(shape), np.zeros(shape), np.zeros(shape), np.zeros(shape), np.zeros(shape), np.zeros(shape),
                np.zeros(shape))  # fmt: skip


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
        work = _work(n)
        end = min((c + 1) * CHUNK, rows.size)
        for start in range(c * CHUNK, end, BATCH):
            for _ in range(steps):
                _step(H, rows, start, min(BATCH, end - start), q, dt, mass, shells, surface, T0, dT, h_table, guide,
                      guide_step, k_table, iterations, convected, work)  # fmt: skip


@nb.njit(cache=True, fastmath={"contract"})
def _step(H, rows, start, m, q, dt, mass, shells, surface, T0, dT, h_table, guide, guide_step, k_table, iterations,
          convected, work):  # fmt: skip
    """One step of the ``m`` particles ``rows[start:start + m]`` (:func:`advance`)."""
    n = H.shape[1]
    T, slope, excess, rhs = work.T, work.slope, work.excess, work.rhs
    for b in range(m):  # the first iterate is the state: h(T) - H = 0
        row = rows[start + b]
        for k in range(n):
            T[k, b], slope[k, b] = temperature_and_slope_at(H[row, k], T0, dT, h_table, guide, guide_step)
            excess[k, b] = 0.0
    for it in range(iterations):
        if it > 0:
            _linearise(H, rows, start, m, T0, dT, h_table, work)
        _assemble(H, rows, start, m, q, dt, mass, shells, surface, k_table, work)
        _back_substitute(m, work)
        for k in range(n):
            for b in range(m):
                T[k, b] += rhs[k, b]
    for k in range(n):  # the linearised enthalpy increments the solve stands for
        for b in range(m):
            excess[k, b] += slope[k, b] * rhs[k, b]
    _conservative_update(H, rows, start, m, q, dt, mass, shells, surface, convected, work)


@nb.njit(cache=True, fastmath={"contract"})
def _linearise(H, rows, start, m, T0, dT, h_table, work):
    """Slopes dh/dT and h(T) - H (J/kg) at the iterate ``work.T`` (the table's interval there)."""
    T, slope, excess = work.T, work.slope, work.excess
    inv_dT = 1.0 / dT
    for b in range(m):
        row = rows[start + b]
        for k in range(T.shape[0]):
            x = (T[k, b] - T0) * inv_dT
            j = min(max(int(x), 0), h_table.size - 2)
            f = min(max(x - j, 0.0), 1.0)
            dh = h_table[j + 1] - h_table[j]
            slope[k, b] = dh * inv_dT
            excess[k, b] = h_table[j] + f * dh - H[row, k]


@nb.njit(cache=True, fastmath={"contract"})
def _conductances(m, shells, k_table, work):
    """Face conductances (W/K) at the iterate, lambda at the mean of the two node temperatures."""
    T, K, face = work.T, work.K, shells.face
    for f in range(T.shape[0] - 1):
        for b in range(m):
            K[f, b] = table_1d(k_table, 0.5 * (T[f, b] + T[f + 1, b])) * face[f]


@nb.njit(cache=True, fastmath={"contract"})
def _assemble(H, rows, start, m, q, dt, mass, shells, surface, k_table, work):
    """The backward-Euler step of the batch linearised about the iterate (slopes and h(T) - H in
    ``work``), in correction form J delta = -R (J/K and J), eliminated from the centre outwards:

    R_k = sum_j m C_kj (h(T_j) - H_j) - dt (conduction into k + [surface] (q + h_conv A (T_gas - T_k))),
    J = m C diag(dh/dT) + dt (conductance matrix + [surface] h_conv A), lambda at the iterate
    (``q[start + b]`` W on particle b). The surface row ends as ``delta = rhs * pivot``, 1 / pivot
    the Schur complement of the interior (J/K); the corner entry (n - 1, n - 3) is eliminated with
    the reduced row n - 3 before the last step, so rows 0 .. n - 2 stay upper bidiagonal for
    :func:`_back_substitute`. ``work`` keeps the conductances, reciprocal pivots, super-diagonal and
    the eliminated right-hand side.
    """
    _conductances(m, shells, k_table, work)
    T, slope, excess, K, pivot, upper, rhs = work
    n = T.shape[0]
    diagonal, c_lower, c_upper = shells.diagonal, shells.lower, shells.upper
    hA = surface.coefficient * shells.surface_area
    for k in range(n):  # -R: the capacities times h(T) - H ...
        for b in range(m):
            r = diagonal[k] * excess[k, b]
            if k > 0:
                r += c_lower[k - 1] * excess[k - 1, b]
            if k < n - 1:
                r += c_upper[k] * excess[k + 1, b]
            rhs[k, b] = -mass * r
    for b in range(m):
        if n > 2:
            rhs[n - 1, b] -= mass * shells.corner * excess[n - 3, b]
        rhs[n - 1, b] += dt * (q[start + b] + hA * (surface.gas_temperature - T[n - 1, b]))
    for f in range(n - 1):  # ... and the conduction
        for b in range(m):
            flow = dt * K[f, b] * (T[f + 1, b] - T[f, b])  # J into node f
            rhs[f, b] += flow
            rhs[f + 1, b] -= flow
    for b in range(m):
        pivot[0, b] = 1.0 / (mass * diagonal[0] * slope[0, b] + dt * K[0, b])
    for k in range(1, n):
        for b in range(m):
            upper[k - 1, b] = mass * c_upper[k - 1] * slope[k, b] - dt * K[k - 1, b]
            sub = mass * c_lower[k - 1] * slope[k - 1, b] - dt * K[k - 1, b]
            diag = mass * diagonal[k] * slope[k, b] + dt * K[k - 1, b]
            if k < n - 1:
                diag += dt * K[k, b]
            else:
                diag += dt * hA
                if n > 2:  # the corner, with row n - 3 (pivot and upper entry into n - 2)
                    factor = mass * shells.corner * slope[n - 3, b] * pivot[n - 3, b]
                    sub -= factor * upper[n - 3, b]
                    rhs[k, b] -= factor * rhs[n - 3, b]
            factor = sub * pivot[k - 1, b]
            pivot[k, b] = 1.0 / (diag - factor * upper[k - 1, b])
            rhs[k, b] -= factor * rhs[k - 1, b]


@nb.njit(cache=True, fastmath={"contract"})
def _back_substitute(m, work):
    """The corrections (K), into ``work.rhs``: the surface node's from its eliminated row, then
    the interior's."""
    pivot, upper, rhs = work.pivot, work.upper, work.rhs
    n = rhs.shape[0]
    for b in range(m):
        rhs[n - 1, b] *= pivot[n - 1, b]
    for k in range(n - 2, -1, -1):
        for b in range(m):
            rhs[k, b] = (rhs[k, b] - upper[k, b] * rhs[k + 1, b]) * pivot[k, b]


@nb.njit(cache=True, fastmath={"contract"})
def _conservative_update(H, rows, start, m, q, dt, mass, shells, surface, convected, work):
    """H_k += (heat into k over the step) / (m w_k) with every flux between two nodes added to one
    and taken from the other (module docstring): conduction dt K (T_k+1 - T_k) at ``work.T``,
    capacity exchanges m C_kj dh_j from the enthalpy increments dh (J/kg, ``work.excess``) the
    solve stands for, dt q and the Robin heat on the surface node; ``convected[start + b]`` gains
    the Robin heat (J)."""
    T, K, dh = work.T, work.K, work.excess
    n = T.shape[0]
    c_upper, c_lower, inverse_weight = shells.upper, shells.lower, shells.inverse_weight
    hA = surface.coefficient * shells.surface_area
    scale = 1.0 / mass
    for b in range(m):
        row = rows[start + b]
        robin = dt * hA * (surface.gas_temperature - T[n - 1, b])
        inflow = 0.0  # J into node k through its inner face
        corner = -mass * shells.corner * dh[n - 3, b] if n > 2 else 0.0  # J from node n - 3 into the surface node
        for k in range(n - 1):
            outflow = dt * K[k, b] * (T[k + 1, b] - T[k, b]) - mass * (c_upper[k] * dh[k + 1, b] - c_lower[k] * dh[k, b])
            net = inflow + outflow
            if k == n - 3:
                net -= corner
            H[row, k] += scale * net * inverse_weight[k]
            inflow = -outflow
        H[row, n - 1] += scale * (inflow + corner + dt * q[start + b] + robin) * inverse_weight[n - 1]
        convected[start + b] += robin


@nb.njit(cache=True, parallel=True)
def condense(H, rows, T, dt, mass, shells, surface, T0, dT, h_table, k_table, pivot, upper, rhs):
    """For the implicit integrator: the backward-Euler step of every particle ``rows[i]`` linearised
    about its node temperatures ``T[i]`` (K, (N, n), frame order) with no surface heat but the
    Robin condition, eliminated onto the surface node (:func:`_assemble`). Returns, per particle,
    the Schur complement (J/K) and the eliminated right-hand side (J) of the surface row, which the
    network adds to its own; keeps the elimination in ``pivot, upper, rhs`` ((N, n), (N, n - 1),
    (N, n); reciprocal pivots) for :func:`back_substitute`."""
    n = T.shape[1]
    schur = np.empty(rows.size)
    own = np.empty(rows.size)
    none = np.zeros(rows.size)  # no surface heat: the network adds its own
    chunks = (rows.size + CHUNK - 1) // CHUNK
    for c in nb.prange(chunks):
        work = _work(n)
        end = min((c + 1) * CHUNK, rows.size)
        for start in range(c * CHUNK, end, BATCH):
            m = min(BATCH, end - start)
            _iterate_at(T, H, rows, start, m, T0, dT, h_table, work)
            _assemble(H, rows, start, m, none, dt, mass, shells, surface, k_table, work)
            _give(work.pivot, start, m, pivot)
            _give(work.upper, start, m, upper)
            _give(work.rhs, start, m, rhs)
            for b in range(m):
                schur[start + b] = 1.0 / work.pivot[n - 1, b]
                own[start + b] = work.rhs[n - 1, b]
    return schur, own


@nb.njit(cache=True)
def _iterate_at(T, H, rows, start, m, T0, dT, h_table, work):
    """The batch's iterate: node temperatures ``T[start + b]`` (K, particle-major), linearised."""
    for b in range(m):
        for k in range(T.shape[1]):
            work.T[k, b] = T[start + b, k]
    _linearise(H, rows, start, m, T0, dT, h_table, work)


@nb.njit(cache=True)
def _give(batch, start, m, A):
    """Batch array ``batch`` (node-major) into rows ``start .. start + m - 1`` of ``A`` (particle-major)."""
    for b in range(m):
        for k in range(A.shape[1]):
            A[start + b, k] = batch[k, b]


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
            d = (rhs[i, k] - upper[i, k] * d) * pivot[i, k]
            T[i, k] += d
            big = max(big, abs(d))
        largest[i] = big
    return largest.max() if largest.size else 0.0


@nb.njit(cache=True, parallel=True)
def commit(H, rows, T, q, dt, mass, shells, surface, T0, dT, h_table, k_table, convected):
    """For the implicit integrator: the flux-form update (:func:`_conservative_update`) of every
    particle ``rows[i]`` to its solved node temperatures ``T[i]`` (K) with the network heat ``q[i]``
    (W) on its surface; the enthalpy increments are h(T) - H, the conductances at T. ``convected[i]``
    gains the Robin heat (J) over the step."""
    n = T.shape[1]
    chunks = (rows.size + CHUNK - 1) // CHUNK
    for c in nb.prange(chunks):
        work = _work(n)
        end = min((c + 1) * CHUNK, rows.size)
        for start in range(c * CHUNK, end, BATCH):
            m = min(BATCH, end - start)
            _iterate_at(T, H, rows, start, m, T0, dT, h_table, work)
            _conductances(m, shells, k_table, work)
            _conservative_update(H, rows, start, m, q, dt, mass, shells, surface, convected, work)


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
