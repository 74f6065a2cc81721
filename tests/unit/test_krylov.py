"""dpht.util.krylov: flexible GMRES with the AMG V-cycle or Jacobi reaches the residual it states on
a non-symmetric system, the V-cycle is the symmetric operator of a symmetric hierarchy, and the
bits do not depend on the thread count."""

import numpy as np
import pyamg
import pytest
import scipy.sparse as sparse

from dpht.util import krylov
from dpht.verification import scenes


def grid_system(nx=100, ny=200, drift=0.2):
    """A 2-D five-point Laplacian with an upwind drift along x (non-symmetric, an M-matrix) plus a
    small diagonal, its symmetric part, and a right-hand side (20,000 unknowns: several dot blocks)."""
    def line(n, left):
        return sparse.diags([np.full(n - 1, -1.0 - left), np.full(n, 2.0 + left), np.full(n - 1, -1.0)], [-1, 0, 1])

    A = sparse.kronsum(line(nx, drift), line(ny, 0.0)) + 1e-3 * sparse.identity(nx * ny)
    b = np.random.default_rng(0).uniform(-1.0, 1.0, nx * ny)
    return A.tocsr(), (0.5 * (A + A.T)).tocsr(), b


def multigrid(symmetric):
    return krylov.Multigrid(pyamg.smoothed_aggregation_solver(symmetric, symmetry="symmetric"))


def test_gmres_reaches_the_residual_it_states():
    """With either preconditioner, to 1e-8 and 1e-2 of |b| (the true residual, computed by scipy);
    the V-cycle takes a fraction of Jacobi's iterations."""
    A, symmetric, b = grid_system()
    iterations = {}
    for name, M in (("amg", multigrid(symmetric)), ("jacobi", krylov.Jacobi(A.diagonal()))):
        for rtol in (1e-8, 1e-2):
            result = krylov.fgmres(krylov.CSR.of(A), b, M, rtol=rtol, maxiter=5000)
            assert result.converged and np.linalg.norm(b - A @ result.x) <= rtol * np.linalg.norm(b), (name, rtol)
            iterations[name, rtol] = result.iterations
    assert iterations["amg", 1e-2] < iterations["amg", 1e-8] < iterations["jacobi", 1e-8] / 5


def test_the_v_cycle_of_a_symmetric_hierarchy_is_symmetric():
    _, symmetric, _ = grid_system()
    M = multigrid(symmetric)
    rng = np.random.default_rng(1)
    u, v = rng.standard_normal((2, symmetric.shape[0]))
    Mu, Mv = np.empty_like(u), np.empty_like(v)
    M(u, Mu)
    M(v, Mv)
    assert v @ Mu == pytest.approx(u @ Mv, rel=1e-12)
    assert u @ Mu > 0 and v @ Mv > 0


def test_one_and_two_threads_give_identical_bits():
    A, symmetric, b = grid_system()
    M = multigrid(symmetric)
    results = scenes.on_threads(lambda: krylov.fgmres(krylov.CSR.of(A), b, M, rtol=1e-10, restart=8).x)
    assert np.array_equal(results[0], results[1])
