"""Sparse linear solves that give the same bits on any number of threads: flexible GMRES with an
algebraic-multigrid V-cycle, in numba.

The implicit integrator (:mod:`dpht.thermal.implicit`) solves one sparse system per Newton
iteration. scipy's Krylov solvers and pyamg's cycles run on one thread (and reduce through a
threaded BLAS whose summation order is its own); these kernels run the products in parallel over
rows, each row summed in its stored order, and every dot product in fixed blocks of
:data:`BLOCK` entries summed block by block in order, so the result does not depend on the thread
count.

- :func:`fgmres`: restarted flexible GMRES (Saad 1993, right preconditioning, modified
  Gram-Schmidt, Givens rotations) for a general (non-symmetric) matrix; it stops when the residual
  ``|b - A x|`` falls below ``rtol |b|``.
- :class:`Multigrid`: one V-cycle of a pyamg multilevel hierarchy as the preconditioner: per level a
  forward Gauss-Seidel sweep (serial: it is one pass over the level's matrix, a small fraction of
  the Krylov product's cost), the residual restricted, the coarser levels, the correction
  prolonged, a backward sweep; the coarsest level solved by its dense pseudo-inverse (as pyamg's
  ``pinv`` coarse solver). Only pyamg's setup (aggregation, smoothed prolongators, Galerkin
  products) is used.

Matrices are :class:`CSR` records: ``indptr`` int64, ``indices`` int32, ``data`` float64.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numba as nb
import numpy as np

BLOCK = 4096  # entries per partial sum of a dot product: fixed, so the order of the sum does not depend on the thread count


class CSR(NamedTuple):
    indptr: np.ndarray  # (n + 1,) int64
    indices: np.ndarray  # (nnz,) int32
    data: np.ndarray  # (nnz,) float64

    @classmethod
    def of(cls, matrix) -> CSR:
        """A scipy sparse matrix as a CSR record (a copy when its index types differ)."""
        m = matrix.tocsr()
        return cls(m.indptr.astype(np.int64), m.indices.astype(np.int32), np.ascontiguousarray(m.data, dtype=np.float64))


@nb.njit(cache=True, parallel=True)
def multiply(indptr, indices, data, x, out, scale=1.0, accumulate=False):
    """``out = scale A x`` (``out += scale A x`` when ``accumulate``), in parallel over rows, each row
    summed in its stored order."""
    for i in nb.prange(indptr.size - 1):
        s = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            s += data[k] * x[indices[k]]
        out[i] = out[i] + scale * s if accumulate else scale * s


def _residual(A: CSR, x: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = b - A x``."""
    np.copyto(out, b)
    multiply(*A, x, out, -1.0, True)


@nb.njit(cache=True, parallel=True)
def dot(x, y):
    """``x . y`` as fixed blocks of :data:`BLOCK` entries, each summed in order, then summed in block order."""
    n = x.size
    blocks = (n + BLOCK - 1) // BLOCK
    partial = np.empty(blocks)
    for b in nb.prange(blocks):
        s = 0.0
        for k in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            s += x[k] * y[k]
        partial[b] = s
    total = 0.0
    for b in range(blocks):
        total += partial[b]
    return total


@nb.njit(cache=True, parallel=True)
def _scaled(x, scale, out):
    for k in nb.prange(x.size):
        out[k] = x[k] * scale


@nb.njit(cache=True, parallel=True)
def _subtract(c, v, w):
    """``w -= c v``."""
    for k in nb.prange(w.size):
        w[k] -= c * v[k]


@nb.njit(cache=True)
def _orthogonalise(V, j, w, h):
    """Modified Gram-Schmidt of ``w`` against ``V[0..j]`` (coefficients into ``h[0..j]``); ``h[j + 1]
    = |w|`` and ``V[j + 1] = w / |w|`` (left as is when ``w`` vanishes: the Krylov space is exhausted)."""
    for i in range(j + 1):
        h[i] = dot(V[i], w)
        _subtract(h[i], V[i], w)
    h[j + 1] = math.sqrt(dot(w, w))
    if h[j + 1] > 0.0:
        _scaled(w, 1.0 / h[j + 1], V[j + 1])


@nb.njit(cache=True, parallel=True)
def _combine(Z, y, k, x):
    """``x += sum_{i < k} y_i Z[i]``, each entry summed in the order of i."""
    for m in nb.prange(x.size):
        s = 0.0
        for i in range(k):
            s += y[i] * Z[i, m]
        x[m] += s


@nb.njit(cache=True)
def _gauss_seidel(indptr, indices, data, x, b, forward):
    """One Gauss-Seidel sweep over the rows, first to last or last to first (serial)."""
    n = indptr.size - 1
    for r in range(n):
        i = r if forward else n - 1 - r
        s = b[i]
        d = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if j == i:
                d += data[k]
            else:
                s -= data[k] * x[j]
        if d != 0.0:
            x[i] = s / d


@nb.njit(cache=True)
def _dense_solve(inverse, b, x):
    for i in range(x.size):
        s = 0.0
        for j in range(b.size):
            s += inverse[i, j] * b[j]
        x[i] = s


class Multigrid:
    """One V-cycle of a pyamg hierarchy (``pyamg.MultilevelSolver``) as a preconditioner: a fixed
    linear operator (zero initial guess, one forward Gauss-Seidel sweep before and one backward
    sweep after each coarse-grid correction), symmetric when the hierarchy's matrices are."""

    def __init__(self, hierarchy):
        levels = hierarchy.levels
        self.A = [CSR.of(level.A) for level in levels]
        self.P = [CSR.of(level.P) for level in levels[:-1]]
        self.R = [CSR.of(level.R) for level in levels[:-1]]
        self.inverse = np.linalg.pinv(levels[-1].A.toarray())
        sizes = [a.indptr.size - 1 for a in self.A]
        self.x = [np.zeros(n) for n in sizes]  # each level's correction, its right-hand side, its residual
        self.b = [np.zeros(n) for n in sizes]
        self.r = [np.zeros(n) for n in sizes]

    def __call__(self, b: np.ndarray, out: np.ndarray) -> None:
        """``out = M^-1 b``: one V-cycle from zero."""
        last = len(self.A) - 1
        xs, bs = [out, *self.x[1:]], [b, *self.b[1:]]
        for level in range(last):
            A, x = self.A[level], xs[level]
            x[:] = 0.0
            _gauss_seidel(*A, x, bs[level], True)
            _residual(A, x, bs[level], self.r[level])
            multiply(*self.R[level], self.r[level], bs[level + 1])
        _dense_solve(self.inverse, bs[last], xs[last])
        for level in range(last - 1, -1, -1):
            multiply(*self.P[level], xs[level + 1], xs[level], 1.0, True)
            _gauss_seidel(*self.A[level], xs[level], bs[level], False)


class Jacobi:
    """The inverse of a matrix's diagonal as a preconditioner."""

    def __init__(self, diagonal: np.ndarray):
        self.inverse = 1.0 / diagonal

    def __call__(self, b: np.ndarray, out: np.ndarray) -> None:
        np.multiply(self.inverse, b, out=out)


class Result(NamedTuple):
    x: np.ndarray
    iterations: int  # matrix products (one per Krylov vector)
    converged: bool


def fgmres(A: CSR, b: np.ndarray, precondition: Callable[[np.ndarray, np.ndarray], None], rtol: float,
           restart: int = 20, maxiter: int = 400) -> Result:  # fmt: skip
    """Solve ``A x = b`` from ``x = 0`` by flexible GMRES(``restart``) with the right preconditioner
    ``precondition(v, out)`` (``out = M^-1 v``) until ``|b - A x| <= rtol |b|`` or ``maxiter``
    products. The residual is recomputed from ``A`` at each restart."""
    n = b.size
    x = np.zeros(n)
    norm_b = math.sqrt(dot(b, b))
    if norm_b == 0.0:
        return Result(x, 0, True)
    V = np.empty((restart + 1, n))
    Z = np.empty((restart, n))
    w = np.empty(n)
    r = b.copy()
    beta, total = norm_b, 0
    while True:
        _scaled(r, 1.0 / beta, V[0])
        H = np.zeros((restart + 1, restart))
        cs, sn = np.zeros(restart), np.zeros(restart)
        g = np.zeros(restart + 1)
        g[0] = beta
        k = 0
        converged = False
        while k < restart and total < maxiter:
            precondition(V[k], Z[k])
            multiply(*A, Z[k], w)
            _orthogonalise(V, k, w, H[:, k])
            total += 1
            for i in range(k):  # the previous rotations on the new column
                H[i, k], H[i + 1, k] = cs[i] * H[i, k] + sn[i] * H[i + 1, k], -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
            rho = math.hypot(H[k, k], H[k + 1, k])
            cs[k], sn[k] = (H[k, k] / rho, H[k + 1, k] / rho) if rho > 0.0 else (1.0, 0.0)
            H[k, k], H[k + 1, k] = rho, 0.0
            g[k], g[k + 1] = cs[k] * g[k], -sn[k] * g[k]
            k += 1
            if rho == 0.0:  # breakdown (M^-1 v = 0): restart from the true residual
                break
            if abs(g[k]) <= rtol * norm_b:
                converged = True
                break
        y = np.zeros(k)
        for i in range(k - 1, -1, -1):  # back substitution in the rotated Hessenberg matrix
            s = g[i]
            for m in range(i + 1, k):
                s -= H[i, m] * y[m]
            y[i] = s / H[i, i] if H[i, i] != 0.0 else 0.0
        _combine(Z, y, k, x)
        if total >= maxiter:
            _residual(A, x, b, r)
            return Result(x, total, math.sqrt(dot(r, r)) <= rtol * norm_b)
        if converged:
            return Result(x, total, True)
        _residual(A, x, b, r)
        beta = math.sqrt(dot(r, r))
        if beta <= rtol * norm_b:
            return Result(x, total, True)
