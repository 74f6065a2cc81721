"""Interpolation on uniform grids, as scalar numba functions for the compiled kernels.

Uniform grids make a look-up one multiply and one floor; values outside the grid are clamped to
its edges (the kernels apply their cutoffs before looking up).
"""

import numba as nb
import numpy as np


@nb.njit(cache=True)
def table_1d(x0, dx, values, x):
    """Linear interpolation on a uniform grid, clamped at both ends."""
    u = min(max((x - x0) * (1.0 / dx), 0.0), values.size - 1.0)  # 1/dx is hoisted out of pair loops
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
def table_2d(x0, dx, y0, dy, values, x, y):
    """Bilinear interpolation on a uniform grid ``values[x, y]``, clamped at the edges."""
    u = min(max((x - x0) * (1.0 / dx), 0.0), values.shape[0] - 1.0)
    v = min(max((y - y0) * (1.0 / dy), 0.0), values.shape[1] - 1.0)
    i, n = min(int(u), values.shape[0] - 2), min(int(v), values.shape[1] - 2)
    f, g = u - i, v - n
    k, m = np.uint64(i), np.uint64(n)
    one = np.uint64(1)
    low = values[k, m] + g * (values[k, m + one] - values[k, m])
    high = values[k + one, m] + g * (values[k + one, m + one] - values[k + one, m])
    return low + f * (high - low)


@nb.njit(cache=True)
def table_2d_many(x0, dx, y0, dy, values, x, y, out):
    """:func:`table_2d` at every point of the 1-D arrays ``x``, ``y`` into ``out``."""
    for k in range(x.size):
        out[k] = table_2d(x0, dx, y0, dy, values, x[k], y[k])
