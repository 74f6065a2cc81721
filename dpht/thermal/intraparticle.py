"""Resolved intra-particle conduction: each particle a 1-D sphere of n shells (ParScale, Eqs. 1-3).

ParScale (Radl et al. 2015) solves rho c_p dT/dt = div(lambda grad T) (Eq. 1) in every particle on
equidistant radial grid points. Here it is a conservative finite-volume scheme in enthalpy form:

- **Shells.** Node k sits at r_k = k a / (n - 1), k = 0 .. n - 1 (ParScale's equidistant points):
  node 0 at the centre, node n - 1 on the surface. Its control volume runs between the midpoints
  r_{k +- 1/2} (clipped to [0, a]): a small sphere at the centre, n - 2 full shells, a half shell at
  the surface. So the outer node's temperature *is* the surface temperature, which the six surface
  modes of the DPHT paper see, and profiles are compared with a reference at the nodes themselves.
- **Fluxes.** Between nodes k and k + 1 the conductance is K = lambda(T_face) 4 pi r_{k+1/2}^2 /
  Delta r (W/K), with lambda at the mean of the two node temperatures (a table in T, as for contact
  conduction). Second order in Delta r.
- **State.** The specific enthalpy h_k (J/kg) of every shell, with the temperature from the same
  enthalpy table as the lumped particles (:mod:`dpht.closures.heat_capacity`), so c_p(T) enters
  through h(T) and energy is conserved exactly.
- **Surface.** A given heat rate q (W, from the surface modes, evaluated with the outer shell's
  temperature) and an optional Robin condition h_conv A (T_gas - T_surface) (ParScale's convective
  cooling; A = 4 pi a^2) act on the outer shell.
- **Time.** Backward Euler per particle, one tridiagonal (Thomas) solve per particle and step,
  linearised about the current state (c_p and lambda at the iterate; ``iterations`` > 1 repeats the
  solve about the new iterate, Newton for c_p, Picard for lambda). The enthalpies are then updated
  from the fluxes of the solved temperatures, face by face, so the particle's energy change equals
  dt (q + Robin heat) to round-off whether or not the iteration has converged: every face flux is
  added to one shell and taken from the other. Backward Euler on this M-matrix keeps the maximum
  principle for constant properties; the shell update is unconditionally stable.

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


class ShellGrid(NamedTuple):
    """Geometry of the n shells of a sphere of radius a (see the module docstring)."""

    radius: float  # m, a
    volume_fraction: np.ndarray  # (n,) of the particle's volume (and mass) in each node's shell
    face: np.ndarray  # (n - 1,) m, 4 pi r_{k+1/2}^2 / Delta r: times lambda, the conductance between nodes k, k+1
    surface_area: float  # m2, 4 pi a^2

    @property
    def n(self) -> int:
        return self.volume_fraction.size

    @property
    def nodes(self) -> np.ndarray:
        """r_k (m) of the nodes."""
        return np.linspace(0.0, self.radius, self.n)


def grid(radius: float, n: int) -> ShellGrid:
    """The shells of a sphere of ``radius`` (m) with ``n`` >= 2 nodes."""
    if n < 2:
        raise ValueError(f"intra-particle conduction needs at least 2 shells, got {n}")
    step = radius / (n - 1)
    edges = np.concatenate([[0.0], (np.arange(n - 1) + 0.5) * step, [radius]])  # r_{k -+ 1/2}, clipped
    volume = edges[1:] ** 3 - edges[:-1] ** 3
    return ShellGrid(
        radius=float(radius),
        volume_fraction=np.ascontiguousarray(volume / radius**3),
        face=np.ascontiguousarray(4.0 * math.pi * edges[1:-1] ** 2 / step),
        surface_area=4.0 * math.pi * radius**2,
    )


class Surface(NamedTuple):
    """The Robin condition on the surface: h_conv A (T_gas - T_surface) W into the particle."""

    coefficient: float  # W/(m2 K), h_conv; 0 for none
    gas_temperature: float  # K


NO_CONVECTION = Surface(0.0, 0.0)
CHUNK = 256  # particles per parallel task of advance (work arrays are allocated once per task)


@nb.njit(cache=True, parallel=True)
def advance(H, rows, q, dt, steps, mass, shells, surface, T0, dT, h_table, guide, guide_step, k_table, iterations,
            convected):  # fmt: skip
    """Advance the shell enthalpies ``H[rows[i]]`` (J/kg, an (N, n) array) over ``steps`` steps of
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
        T_new = np.empty(n)
        cap = np.empty(n)
        K = np.empty(n - 1)
        lower = np.empty(n)
        diag = np.empty(n)
        rhs = np.empty(n)
        for i in range(c * CHUNK, min((c + 1) * CHUNK, rows.size)):
            row = rows[i]
            heat = 0.0
            for _ in range(steps):
                for k in range(n):
                    T[k] = temperature_at(H[row, k], T0, dT, h_table, guide, guide_step)
                    T_new[k] = T[k]
                for _it in range(iterations):
                    _linearised_solve(H, row, T_new, q[i], dt, mass, shells, surface, T0, dT, h_table, k_table,
                                      cap, K, lower, diag, rhs)  # fmt: skip
                heat += dt * _conservative_update(H, row, T_new, q[i], dt, mass, shells, surface, K)
            convected[i] += heat


@nb.njit(cache=True, fastmath={"contract"})
def _linearised_solve(H, row, T, q, dt, mass, shells, surface, T0, dT, h_table, k_table, cap, K, lower, diag, rhs):
    """One backward-Euler solve linearised about the iterate ``T`` (K), which it replaces.

    Shell k: m_k [h(T*_k) + c_k (T_k - T*_k) - h_k] / dt = sum of face conductances K (T_nb - T_k)
    (+ q + h_conv A (T_gas - T_k) on the surface), c_k the enthalpy table's slope at T*_k; K (left in
    ``K``) is lambda at T*. Tridiagonal, symmetric, diagonally dominant: Thomas without pivoting.
    """
    n = T.size
    w = shells.volume_fraction
    for f in range(n - 1):
        K[f] = table_1d(k_table, 0.5 * (T[f] + T[f + 1])) * shells.face[f]
    inv_dT, scale = 1.0 / dT, mass / dt
    for k in range(n):  # h(T*) and its slope from one interval of the table (as enthalpy_at, clamped)
        x = (T[k] - T0) * inv_dT
        j = min(max(int(x), 0), h_table.size - 2)
        f = min(max(x - j, 0.0), 1.0)
        dh = h_table[j + 1] - h_table[j]
        m_k = scale * w[k]
        cap[k] = m_k * dh * inv_dT
        diag[k] = cap[k]
        rhs[k] = cap[k] * T[k] - m_k * (h_table[j] + f * dh - H[row, k])
    hA = surface.coefficient * shells.surface_area
    diag[n - 1] += hA
    rhs[n - 1] += q + hA * surface.gas_temperature
    for f in range(n - 1):
        diag[f] += K[f]
        diag[f + 1] += K[f]
    # Forward elimination (sub- and super-diagonal are both -K[f]), then back substitution.
    lower[0] = diag[0]
    for k in range(1, n):
        factor = -K[k - 1] / lower[k - 1]
        lower[k] = diag[k] + factor * K[k - 1]
        rhs[k] -= factor * rhs[k - 1]
    T[n - 1] = rhs[n - 1] / lower[n - 1]
    for k in range(n - 2, -1, -1):
        T[k] = (rhs[k] + K[k] * T[k + 1]) / lower[k]


@nb.njit(cache=True, fastmath={"contract"})
def _conservative_update(H, row, T, q, dt, mass, shells, surface, K) -> float:
    """h_k += dt (face fluxes at ``T`` + surface terms) / m_k; returns the Robin heat rate (W)."""
    n = T.size
    w = shells.volume_fraction
    scale = dt / mass
    robin = surface.coefficient * shells.surface_area * (surface.gas_temperature - T[n - 1])
    inflow = 0.0  # W into shell k through its inner face
    for k in range(n - 1):
        outflow = K[k] * (T[k + 1] - T[k])  # W into shell k through its outer face
        H[row, k] += scale * (inflow + outflow) / w[k]
        inflow = -outflow
    H[row, n - 1] += scale * (inflow + q + robin) / w[n - 1]
    return robin


@nb.njit(cache=True, parallel=True)
def surface_temperature(H, rows, T0, dT, h_table, guide, guide_step):
    """Temperature (K) of the outer shell of each particle ``rows[i]``."""
    out = np.empty(rows.size)
    n = H.shape[1]
    for i in nb.prange(rows.size):
        out[i] = temperature_at(H[rows[i], n - 1], T0, dT, h_table, guide, guide_step)
    return out


@nb.njit(cache=True, parallel=True)
def mean_enthalpy(H, volume_fraction):
    """Mass-weighted mean specific enthalpy (J/kg) of every particle, shells summed in order."""
    out = np.empty(H.shape[0])
    for i in nb.prange(H.shape[0]):
        s = 0.0
        for k in range(H.shape[1]):
            s += volume_fraction[k] * H[i, k]
        out[i] = s
    return out
