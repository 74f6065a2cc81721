"""Interpolation on uniform grids, as scalar numba functions for the compiled kernels.

A table is a small typed record numba passes by value: :class:`Table1D` ``(x0, dx, values)`` with
``values[k]`` at ``x0 + k dx``, and :class:`Table2D` ``(x0, dx, y0, dy, values)`` with
``values[k, m]`` at ``(x0 + k dx, y0 + m dy)``. Uniform grids make a look-up one multiply and one
floor; values outside the grid are clamped to its edges (the kernels apply their cutoffs before
looking up). Units are the caller's (named where each table is built).
"""

from typing import NamedTuple

import numba as nb
import numpy as np


class Table1D(NamedTuple):
    x0: float
    dx: float
    values: np.ndarray  # (n,) float64, C-contiguous, n >= 2


class Table2D(NamedTuple):
    x0: float
    dx: float
    y0: float
    dy: float
    values: np.ndarray  # (nx, ny) float64, C-contiguous, nx, ny >= 2


@nb.njit(cache=True)
def table_1d(table, x):
    """Linear interpolation in a :class:`Table1D` at ``x``, clamped at both ends."""
    values = table.values
    u = min(max((x - table.x0) * (1.0 / table.dx), 0.0), values.size - 1.0)  # 1/dx is hoisted out of pair loops
    i = min(int(u), values.size - 2)
    f = u - i
    k = np.uint64(i)  # unsigned: no negative-index wrap-around in the pair loops
    return values[k] + f * (values[k + np.uint64(1)] - values[k])


@nb.njit(cache=True)
def table_1d_inside(values, x):
    """Linear interpolation at ``x`` in grid steps from ``values[0]``, unclamped: the caller
    guarantees ``0 <= x <= values.size - 2`` (the pair loop's hottest look-up)."""
    i = int(x)
    f = x - i
    k = np.uint64(i)
    return values[k] + f * (values[k + np.uint64(1)] - values[k])


@nb.njit(cache=True)
def table_2d(table, x, y):
    """Bilinear interpolation in a :class:`Table2D` at ``(x, y)``, clamped at the edges."""
    values = table.values
    u = min(max((x - table.x0) * (1.0 / table.dx), 0.0), values.shape[0] - 1.0)
    v = min(max((y - table.y0) * (1.0 / table.dy), 0.0), values.shape[1] - 1.0)
    i, n = min(int(u), values.shape[0] - 2), min(int(v), values.shape[1] - 2)
    f, g = u - i, v - n
    k, m = np.uint64(i), np.uint64(n)
    one = np.uint64(1)
    low = values[k, m] + g * (values[k, m + one] - values[k, m])
    high = values[k + one, m] + g * (values[k + one, m + one] - values[k + one, m])
    return low + f * (high - low)


@nb.njit(cache=True)
def table_2d_many(table, x, y, out):
    """:func:`table_2d` at every point of the 1-D arrays ``x``, ``y`` into ``out``."""
    for k in range(x.size):
        out[k] = table_2d(table, x[k], y[k])
