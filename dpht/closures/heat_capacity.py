"""Specific heat c_p(T) and its enthalpy, so particle energy is conserved exactly.

The thermal stage advances each particle's enthalpy ``H = m h(T)`` (J) by ``q dt`` and derives the
temperature from it, instead of updating ``T`` with ``q dt / (m c_p(T))`` (DPHT paper, Eq. 1). With a
temperature-dependent ``c_p`` the latter does not conserve energy; the enthalpy form does, to
round-off, while reducing to Eq. 1 for constant ``c_p``.

``h(T) = integral of c_p from T_lo to T`` is tabulated on a fine uniform temperature grid (exact at
the nodes to quadrature precision) and interpolated linearly; ``T(h)`` is the exact inverse of
that piecewise-linear interpolant, so the pair round-trips to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from dpht.errors import ConfigError
from dpht.util.expr import parse

# Gauss-Legendre nodes/weights on [0, 1] for the enthalpy integral per grid interval.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(6)
_GL_X, _GL_W = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W

CELSIUS = 273.15


def specific_heat(value, key: str = "particles.specific_heat"):
    """Return c_p(T) [J/(kg K)] from a config value: a number, or an expression of ``T`` (K) / ``T_C`` (deg C)."""
    expression = parse(value, ("T", "T_C"), key)
    return lambda T: expression(T=T, T_C=np.asarray(T, dtype=np.float64) - CELSIUS)


@dataclass(frozen=True)
class EnthalpyTable:
    """Specific enthalpy h (J/kg) at uniform temperatures ``T0 + k dT`` (K), with h(T0) = 0."""

    T0: float
    dT: float
    h: np.ndarray
    cp_min: float  # smallest c_p over the table range, for the explicit stability bound
    guide: np.ndarray  # guide[m]: the interval of h holding m * guide_step, so inversion needs no search
    guide_step: float  # J/kg

    @property
    def T_max(self) -> float:
        return self.T0 + self.dT * (self.h.size - 1)

    def enthalpy(self, T) -> np.ndarray:
        return tabulate(np.asarray(T, dtype=np.float64), self, False)

    def temperature(self, h) -> np.ndarray:
        return tabulate(np.asarray(h, dtype=np.float64), self, True)

    def temperature_rows(self, h, rows) -> np.ndarray:
        """Temperatures (K) of ``h[rows]``, gathered and converted in parallel."""
        return _temperature_rows(h, rows, *self.arrays)

    @property
    def arrays(self) -> tuple:
        """``(T0, dT, h, guide, guide_step)`` for the compiled functions."""
        return self.T0, self.dT, self.h, self.guide, self.guide_step


def build(cp, T_low: float, T_high: float, *, step: float = 0.25, key: str = "particles.specific_heat") -> EnthalpyTable:
    """Tabulate h(T) for c_p function ``cp`` over [T_low, T_high] K (widened by 5 K each side)."""
    T0 = T_low - 5.0
    n = int(np.ceil((T_high + 5.0 - T0) / step)) + 1
    nodes = T0 + step * np.arange(n)
    samples = nodes[:-1, None] + step * _GL_X[None, :]
    values = cp(np.concatenate([nodes, samples.ravel()]))
    if not np.all(np.isfinite(values)) or np.any(values <= 0):
        bad = np.concatenate([nodes, samples.ravel()])[~(np.isfinite(values) & (values > 0))]
        raise ConfigError(
            f"{key}: specific heat must be finite and > 0 for every temperature the scene reaches "
            f"({T0:.2f}-{nodes[-1]:.2f} K), but is {float(cp(bad[:1])[0])!r} at T = {bad[0]:.2f} K"
        )
    increments = step * (values[n:].reshape(n - 1, _GL_X.size) @ _GL_W)
    h = np.concatenate([[0.0], np.cumsum(increments)])
    guide_step = h[-1] / (h.size - 1)
    guide = np.maximum(np.searchsorted(h, guide_step * np.arange(h.size + 1)) - 1, 0)
    return EnthalpyTable(T0=float(T0), dT=float(step), h=h, cp_min=float(values.min()), guide=guide, guide_step=float(guide_step))


@nb.njit(cache=True)
def enthalpy_at(T, T0, dT, h):
    """h(T) by linear interpolation, clamped to the table."""
    x = (T - T0) / dT
    k = min(max(int(np.floor(x)), 0), h.size - 2)
    f = min(max(x - k, 0.0), 1.0)
    return h[k] + f * (h[k + 1] - h[k])


@nb.njit(cache=True)
def specific_heat_at(T, T0, dT, h):
    """c_p (J/(kg K)) of the interpolant :func:`enthalpy_at` at ``T``: the slope of its interval
    (the exact derivative of the enthalpy the integrators conserve), clamped to the table."""
    k = min(max(int(np.floor((T - T0) / dT)), 0), h.size - 2)
    return (h[k + 1] - h[k]) / dT


@nb.njit(cache=True)
def temperature_at(value, T0, dT, h, guide, guide_step):
    """Inverse of :func:`enthalpy_at` (h is strictly increasing), clamped to the table.

    The guide puts the search within a step or two of the answer: a guide step is the mean enthalpy
    step of the table, and c_p varies little over a few grid intervals.
    """
    return temperature_and_slope_at(value, T0, dT, h, guide, guide_step)[0]


@nb.njit(cache=True)
def temperature_and_slope_at(value, T0, dT, h, guide, guide_step):
    """(:func:`temperature_at`, the slope dh/dT (J/(kg K)) of the table's interval there): one search.

    The guide's interval is the answer or one or two below it (a guide cell is one mean table step
    wide): two steps without branches (a branch here mispredicts about every other call, and costs
    more than the look-up), then a loop for tables whose c_p varies more, which rarely turns.
    """
    last = h.size - 2
    k = min(guide[min(max(int(value / guide_step), 0), guide.size - 1)], last)
    k = min(k + (h[k + 1] < value), last)
    k = min(k + (h[k + 1] < value), last)
    while k < last and h[k + 1] < value:
        k += 1
    dh = h[k + 1] - h[k]
    f = min(max((value - h[k]) / dh, 0.0), 1.0)
    return T0 + (k + f) * dT, dh / dT


def tabulate(values: np.ndarray, table: EnthalpyTable, inverse: bool) -> np.ndarray:
    """:func:`enthalpy_at` (or with ``inverse``, :func:`temperature_at`) of every element."""
    out = np.empty(values.shape)
    _tabulate(values.ravel(), out.ravel(), *table.arrays, inverse)
    return out


@nb.njit(cache=True)
def _tabulate(flat, out, T0, dT, h, guide, guide_step, inverse):
    for i in range(flat.size):
        out[i] = temperature_at(flat[i], T0, dT, h, guide, guide_step) if inverse else enthalpy_at(flat[i], T0, dT, h)


@nb.njit(cache=True, parallel=True)
def _temperature_rows(values, rows, T0, dT, h, guide, guide_step):
    out = np.empty(rows.size)
    for i in nb.prange(rows.size):
        out[i] = temperature_at(values[rows[i]], T0, dT, h, guide, guide_step)
    return out
