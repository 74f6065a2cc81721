"""Implicit integration on the frame's fixed geometry: backward Euler and TR-BDF2 (registry name ``implicit``).

Each step solves, for the temperatures T at the end of a stage,

    m (h(T) - h_known) - c dt q(T) = 0,        q_i(T) = sum_j G_ij(T) (T_j - T_i) + sum_w G_iw(T) (T_w - T_i),

with c = 1 and h_known = h^n for backward Euler. The conductances G (k(T), the HTC tables'
temperature dependence, the radiation secant ``eps A sigma D (T_i^2 + T_j^2)(T_i + T_j)``) come from
the frame's stored geometry (:mod:`dpht.thermal.network`). The iteration starts with a Picard step,
the conductances frozen at the iterate: ``(diag(m c_p(T)) + c dt L(G(T))) dT = -residual``, Newton on
the enthalpy, a symmetric, diagonally dominant M-matrix, robust from any start (far from the answer
Newton overshoots: linearised at 300 K, a 1,000 K wall's radiation sends a particle to 9,000 K).
It continues with Newton steps while the corrections shrink (one that grows sends it back to
Picard for a step): Newton's matrix is the residual's Jacobian, the conductances' slopes in each
end's temperature added (radiation's exactly, the mean-temperature modes' - k(T), the gas gap -
by a forward difference; :class:`dpht.thermal.network.Slopes`), which makes it non-symmetric.
Each linear system is solved by flexible GMRES (:mod:`dpht.util.krylov`, in parallel and the same
bits on any thread count) preconditioned with one V-cycle of smoothed-aggregation algebraic
multigrid (pyamg's setup, from the Picard matrix with its weak couplings lumped, built once per
frame geometry and reused) or with Jacobi, until the largest temperature correction is below
``tolerance`` (K). Near the answer Newton converges quadratically: on the benchmark's stiff bed
(benchmarks/integrators.py) two steps take 8 iterations where Picard alone took 17.

Energy is conserved by construction, whatever the iteration residual: the enthalpies are updated
in flux form, ``h = h^n + dt/m sum_s w_s q(T_s)``, from the converged stage temperatures T_s, each q
made of one antisymmetric set of pair fluxes and the wall fluxes; the wall heat reported is the
same weighted sum of the wall fluxes. So the change of particle energy equals the wall heat to
round-off, not to the tolerance. The price: the update turns the iteration's remaining error e
into an end-temperature error of about ``c dt/(m c_p) L e``, e's mode amplified by up to its ``dt``
over its time constant - on the benchmark's bed, at 50 time constants per step, Picard stopped at
0.01 K ended 6.9e-4 of the temperature range from the converged solution, Newton (whose error
after its last correction is far below it) 2.8e-4, its time discretisation alone.

Schemes (``thermal.implicit.scheme``):

- ``backward_euler``: first order, L-stable, and it keeps the maximum principle: with constant
  conductances the matrix is an M-matrix, and for any G(T) >= 0 and increasing h(T) the hottest
  particle cannot heat beyond its hottest neighbour or wall (to the iteration tolerance).
- ``tr_bdf2``: second order, L-stable (Bank et al. 1985; Hosea and Shampine 1996, gamma = 2 - sqrt 2):
  a trapezoidal stage to t + gamma dt, then BDF2 to t + dt, weights ``w = (1, 1, 2 (1 - gamma)) /
  (2 (2 - gamma))`` on q at t, t + gamma dt and t + dt. It does not keep the maximum principle
  for stiff particles: its amplification factor R(z) for dT/dt = -lambda T, z = lambda dt, is
  negative for z > 1 + sqrt 2 (R(10) = -0.20), so a particle with dt G/(m c_p) > 1 + sqrt 2 next to
  a wall overshoots the wall temperature. It keeps it for z <= 1 + sqrt 2 (tested both ways).

Resolved intra-particle conduction would add nodes (shells) to the same matrix with the solver
unchanged; not done yet: a model with shells or particle-gas convection runs explicit
(:data:`dpht.thermal.integrators.SHELLS`).
"""

from __future__ import annotations

import logging
import math

import numba as nb
import numpy as np
import pyamg
import scipy.sparse as sparse

from dpht.closures.heat_capacity import enthalpy_at, specific_heat_at
from dpht.errors import DPHTError
from dpht.thermal import network
from dpht.thermal.integrate import Frame, Start, StepReport
from dpht.thermal.model import ThermalModel
from dpht.util import krylov

log = logging.getLogger("dpht")

SCHEMES = ("backward_euler", "tr_bdf2")
PRECONDITIONERS = ("amg", "jacobi")
DEFAULTS = {"scheme": "backward_euler", "tolerance": 1e-8, "preconditioner": "amg", "max_iterations": 50}
GAMMA = 2.0 - math.sqrt(2.0)
_A = 1.0 / (GAMMA * (2.0 - GAMMA))  # BDF2 stage: h = A h_gamma - (A - 1) h_n + B dt q
_B = (1.0 - GAMMA) / (2.0 - GAMMA)
WEIGHTS = (1.0 / (2.0 * (2.0 - GAMMA)), 1.0 / (2.0 * (2.0 - GAMMA)), _B)  # of q at t, t + gamma dt, t + dt
# Relative residual of each linear solve (inexact Newton): once Newton's own error is below it, the
# iteration gains about this factor per step instead of converging quadratically; the tolerance of
# the outer loop, not this, sets the final accuracy.
KRYLOV_RTOL = 1e-3
RESTART = 20  # GMRES vectors kept before a restart (with AMG a solve takes about 10)
# Prolongation smoothing of the AMG hierarchy's finest level and (the last entry) of every coarser
# one: pyamg's Jacobi smoother, omega 4/3 (see Implicit._build).
SMOOTH = [("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}), ("jacobi", {"omega": 4.0 / 3.0})]
WEAK = 0.03  # the AMG hierarchy drops couplings weaker than this times sqrt(a_ii a_jj) (see _lumped;
# on the benchmark's bed 0.03 keeps 68% of the nonzeros 0.01 keeps, halves the V-cycle, same GMRES iterations)


def _lumped(A):
    """``A`` without its weak couplings, each dropped entry added to its row's diagonal.

    The AMG preconditioner is built from this. With radiation the network couples each particle
    to ~100 others, mostly weakly (the RDF decays with distance): the hierarchy of the full matrix
    costs ten times more to smooth for little gain. Lumping keeps the row sums, so the matrix stays
    a symmetric, diagonally dominant M-matrix and the preconditioner symmetric positive definite;
    the Krylov solver still iterates on the matrix itself.
    """
    indptr, data, indices = _lump(A.indptr, A.indices, A.data, A.diagonal())
    return sparse.csr_matrix((data, indices, indptr), shape=A.shape)


@nb.njit(cache=True, inline="always")
def _strong(value, d_i, d_j):
    return abs(value) >= WEAK * math.sqrt(d_i * d_j)


@nb.njit(cache=True, parallel=True)
def _lump(indptr, indices, values, d):
    """Rows of ``A`` keeping the diagonal and the strong couplings, in order (a counting pass and a
    filling pass, parallel over rows)."""
    n = indptr.size - 1
    kept = np.zeros(n + 1, dtype=np.int64)
    for i in nb.prange(n):
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            kept[i + 1] += j == i or _strong(values[k], d[i], d[j])
    for i in range(n):
        kept[i + 1] += kept[i]
    data = np.empty(kept[n])
    columns = np.empty(kept[n], dtype=indices.dtype)
    for i in nb.prange(n):
        weak = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if j != i and not _strong(values[k], d[i], d[j]):
                weak += values[k]
        out = kept[i]
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if j == i:
                data[out], columns[out] = values[k] + weak, j
            elif _strong(values[k], d[i], d[j]):
                data[out], columns[out] = values[k], j
            else:
                continue
            out += 1
    return kept, data, columns


@nb.njit(cache=True, parallel=True)
def _enthalpy_and_capacity(T, T0, dT, h, out_h, out_cp):
    for i in nb.prange(T.size):
        out_h[i] = enthalpy_at(T[i], T0, dT, h)
        out_cp[i] = specific_heat_at(T[i], T0, dT, h)


class Implicit(network.OnNetwork):
    """Backward Euler or TR-BDF2 over each frame (one step per frame interval)."""

    name = "implicit"

    def __init__(self, model: ThermalModel, options: dict | None = None):
        o = {**DEFAULTS, **(options or {})}
        if o["scheme"] not in SCHEMES or o["preconditioner"] not in PRECONDITIONERS:
            raise DPHTError(f"thermal.implicit: scheme must be one of {SCHEMES} and preconditioner one of "
                            f"{PRECONDITIONERS}, got {o['scheme']!r} and {o['preconditioner']!r}")  # fmt: skip
        super().__init__(model)
        self.scheme, self.tolerance = o["scheme"], float(o["tolerance"])
        self.preconditioner, self.max_iterations = o["preconditioner"], int(o["max_iterations"])
        self.stats = {"steps": 0, "iterations": 0, "newton_iterations": 0, "krylov_iterations": 0, "unconverged": 0, "amg_setups": 0}
        self._source = None  # (DEM frame, T, c dt) of the matrix the AMG hierarchy was built from
        self._resumed = None  # the source saved in a checkpoint, until the first frame after it

    def prepare(self, net: network.Network) -> None:
        self.matrix, self._amg, self._source = network.Matrix(net), None, None  # the AMG hierarchy is per frame geometry
        self.slopes = network.Slopes.of(net)
        self.q, self.g, self.h_T, self.cp = (np.empty(net.n) for _ in range(4))

    def checkpoint(self) -> dict:
        """The counts and, with an AMG hierarchy, the temperatures and scale of the matrix it was
        built from: a frozen bed reuses it for the whole run, so a resumed run rebuilds the same one."""
        saved = super().checkpoint()
        if self._source is not None:
            frame_number, T, scale = self._source
            saved.update({"implicit/amg_frame": frame_number, "implicit/amg_T": T, "implicit/amg_scale": scale})
        return saved

    def restore(self, saved: dict) -> None:
        super().restore(saved)
        if "implicit/amg_frame" in saved:
            self._resumed = (int(saved["implicit/amg_frame"]), np.asarray(saved["implicit/amg_T"], dtype=np.float64),
                             float(saved["implicit/amg_scale"]))  # fmt: skip

    def advance(self, frame: Frame, h: np.ndarray, dt: float, frame_number: int = 0, start: Start | None = None) -> StepReport:
        model, idx = self.model, frame.particles
        before = dict(self.stats)
        if self._resumed is not None:  # the first frame after a resume: the geometry the hierarchy was built on?
            source, self._resumed = self._resumed, None
            if source[0] == frame_number and self.preconditioner == "amg":
                self.network(frame)
                with network.threads_for(frame.particles.size):  # the same setup again: not counted
                    self._build(self._matrix_at(source[1], source[2]), source)
        net, T0, heat, clamped = self.begin(frame, h, start)
        if dt == 0.0:
            network.element_heat(model, net, T0, 1.0, heat)
            return StepReport(0, heat, T0, self.name, {"clamped": clamped})
        with network.threads_for(net.n):
            h[idx] = self.step(h[idx], dt, heat, T0, frame_number)
        self.stats["steps"] += 1
        return StepReport(1, heat, T0, self.name, {**{k: self.stats[k] - before[k] for k in self.stats}, "clamped": clamped})

    def step(self, h_n: np.ndarray, dt: float, heat: np.ndarray, T_n: np.ndarray, frame_number: int = 0) -> np.ndarray:
        """Specific enthalpies (J/kg, frame order) one step of ``dt`` (s) after ``h_n`` (at
        temperatures ``T_n``); adds the step's mean wall heat (W) to ``heat``."""
        model, net, m = self.model, self.net, self.model.mass
        if self.scheme == "backward_euler":
            T, q = self._solve(h_n, dt, T_n, frame_number)
            network.element_heat(model, net, T, 1.0, heat)
            return h_n + (dt / m) * q
        network.conductances(model, net, T_n)
        q_n = np.empty(net.n)
        network.rates(model, net, T_n, q_n, self.g)
        network.element_heat(model, net, T_n, WEIGHTS[0], heat)
        c = 0.5 * GAMMA * dt
        T_g, q_g = self._solve(h_n + (c / m) * q_n, c, T_n, frame_number)
        network.element_heat(model, net, T_g, WEIGHTS[1], heat)
        h_g = h_n + (c / m) * (q_n + q_g)
        T_1, q_1 = self._solve(_A * h_g - (_A - 1.0) * h_n, _B * dt, T_g, frame_number)
        network.element_heat(model, net, T_1, WEIGHTS[2], heat)
        return h_n + (dt / m) * (WEIGHTS[0] * q_n + WEIGHTS[1] * q_g + WEIGHTS[2] * q_1)

    def _solve(self, h_known: np.ndarray, c_dt: float, T: np.ndarray, frame_number: int) -> tuple[np.ndarray, np.ndarray]:
        """Temperatures T* with m (h(T*) - h_known) = c_dt q(T*) to the tolerance, and q(T*) (W),
        its conductances left in the network for the wall heat."""
        model, net, m = self.model, self.net, self.model.mass
        T = T.copy()
        newton, previous = False, math.inf
        for iteration in range(1, self.max_iterations + 1):
            self.stats["newton_iterations"] += newton
            self._matrix_at(T, c_dt, newton)
            residual = m * (self.h_T - h_known) - c_dt * self.q  # J
            correction = self._linear(-residual, (frame_number, T, c_dt))
            T += correction
            if not np.all(np.isfinite(T)):
                raise DPHTError(f"frame {frame_number}: the implicit iteration produced non-finite temperatures")
            size = float(np.max(np.abs(correction), initial=0.0))
            if size <= self.tolerance:
                break
            newton, previous = size < previous, size  # Newton while the corrections shrink, else Picard
        else:
            self.stats["unconverged"] += 1
            log.warning("frame %d: implicit iteration not converged to %.1e K in %d iterations (last correction %.3g K); "
                        "energy stays conserved", frame_number, self.tolerance, self.max_iterations, size)  # fmt: skip
        self.stats["iterations"] += iteration
        network.conductances(model, net, T)
        network.rates(model, net, T, self.q, self.g)
        return T, self.q.copy()

    def _matrix_at(self, T: np.ndarray, c_dt: float, newton: bool = False) -> network.Matrix:
        """The iteration matrix ``m c_p(T) - c_dt dq/dT`` (W/K) at ``T``: Picard's (the conductances
        frozen) or Newton's (their slopes too); ``q(T)``, ``h(T)`` and ``c_p(T)`` into the work arrays
        and the conductances left at ``T``."""
        model, net, table = self.model, self.net, self.model.enthalpy
        slopes = self.slopes if newton else None
        network.conductances(model, net, T, slopes)
        _enthalpy_and_capacity(T, table.T0, table.dT, table.h, self.h_T, self.cp)
        self.matrix.fill(model, T, model.mass * self.cp, c_dt, self.q, slopes)
        return self.matrix

    def _build(self, matrix: network.Matrix, source) -> None:
        # The finest level's prolongator is smoothed with Jacobi weighted row by row (Gershgorin),
        # the coarser ones with pyamg's spectral-radius estimate: its random start is seeded here
        # (numpy's global generator, restored after), so the hierarchy and so the result are
        # reproducible. (The estimate on the finest level costs ten times the rest of the setup,
        # and pyamg's row-wise weights on the coarser levels' block matrices run a Python loop.)
        saved = np.random.get_state()
        np.random.seed(0)
        try:
            solver = pyamg.smoothed_aggregation_solver(_lumped(matrix.csr), symmetry="symmetric", smooth=SMOOTH)
        finally:
            np.random.set_state(saved)
        self._amg = krylov.Multigrid(solver)
        self._source = (source[0], source[1].copy(), source[2])

    def _linear(self, b: np.ndarray, source) -> np.ndarray:
        """Solve ``A x = b`` with the matrix just filled; ``source`` (DEM frame, T, c dt) is what it
        was made from (a Picard matrix when the AMG hierarchy is built from it)."""
        if not np.any(b):
            return np.zeros_like(b)
        if self.preconditioner == "amg":
            if self._amg is None:
                self._build(self.matrix, source)
                self.stats["amg_setups"] += 1
            M = self._amg
        else:
            M = krylov.Jacobi(self.matrix.diagonal())
        result = krylov.fgmres(self.matrix.arrays, b, M, rtol=KRYLOV_RTOL, restart=RESTART)
        self.stats["krylov_iterations"] += result.iterations
        if not result.converged:
            log.warning("implicit: GMRES stopped after %d iterations above its tolerance", result.iterations)
        return result.x

    def cost(self, stiffness) -> float:
        """Rate-evaluation equivalents of a frame, from measurements on dense beds of 9,000 and 1e5
        particles (all modes, one thread): listing the pairs, the matrix structure and the AMG setup
        (~30, not when the frame is reused), and per stage about 4 + log10(1 + r) iterations (r the
        median stiffness; from a cold start at large r up to 8, near a steady state 3), each a
        conductance evaluation with its slopes and the matrix refill (~4) and a preconditioned
        solve of about 4 + 16 r / (r + 10) GMRES iterations (~0.25 each)."""
        r = max(stiffness.typical, 0.0)
        stages = 1 if self.scheme == "backward_euler" else 2
        iterations = 4.0 + math.log10(1.0 + r)
        krylov_iterations = 4.0 + 16.0 * r / (r + 10.0)
        return (0.0 if stiffness.reused else 30.0) + stages * iterations * (4.0 + 0.25 * krylov_iterations)
