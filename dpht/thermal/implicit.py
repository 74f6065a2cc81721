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
after its last correction is far below it) 2.9e-4, its time discretisation alone.

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

Resolved particles (``model.shells``, :mod:`dpht.thermal.intraparticle`, backward Euler only): the
unknowns are every particle's node temperatures, its surface node the one in the network. Each
iterate linearises every particle's node equations (Newton on the enthalpy, Picard on lambda) and
eliminates its interior onto its surface node (:func:`dpht.thermal.intraparticle.condense`, a Schur
complement per particle), so the network matrix keeps its sparsity (and Picard's its symmetry) with
the Schur complements (J/K) on its diagonal in place of m c_p, the network's conductances taken
Picard then Newton as above; after the network solve the interiors follow
by back substitution, and the iteration stops when the largest correction of any node is below the
tolerance. The update is in flux form again (:func:`dpht.thermal.intraparticle.commit`): the
particle's energy changes by exactly dt (network heat + gas heat) of the converged temperatures.

Particle-gas convection (``model.convection``): h_conv A (T_gas - T) is one more Dirichlet
conductance on each particle's diagonal (for resolved particles, on the surface node inside the
condensed block); its heat is reported as ``StepReport.convected``.
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
from dpht.thermal import intraparticle, network
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
        if model.shells is not None and o["scheme"] != "backward_euler":
            raise DPHTError(f"thermal.implicit.scheme: {o['scheme']!r} cannot advance resolved particles; "
                            "use backward_euler")  # fmt: skip
        super().__init__(model)
        self.scheme, self.tolerance = o["scheme"], float(o["tolerance"])
        self.preconditioner, self.max_iterations = o["preconditioner"], int(o["max_iterations"])
        self.stats = {"steps": 0, "iterations": 0, "newton_iterations": 0, "krylov_iterations": 0, "unconverged": 0, "amg_setups": 0}
        self._source = None  # (Frame.key, T, c dt, diagonal capacity) of the matrix the AMG hierarchy was built from
        self._resumed = None  # the source saved in a checkpoint, until the first frame after it
        gas = model.convection
        self.hA = gas.coefficient * 4.0 * math.pi * model.radius**2  # W/K, particle-gas convection

    def prepare(self, net: network.Network) -> None:
        self.matrix, self._amg, self._source = network.Matrix(net), None, None  # the AMG hierarchy is per frame geometry
        self.slopes = network.Slopes.of(net)
        self.q, self.g, self.h_T, self.cp = (np.empty(net.n) for _ in range(4))
        if self.model.shells is not None:  # the eliminations of the particles' interiors
            n = self.model.shells.n
            self.pivot, self.upper, self.rhs = np.empty((net.n, n)), np.empty((net.n, n - 1)), np.empty((net.n, n))

    def checkpoint(self) -> dict:
        """The counts and, with an AMG hierarchy, the key of its geometry (:attr:`Frame.key`) and
        the temperatures, scale and diagonal capacities of the matrix it was built from: a frozen
        bed reuses it for the whole run, so a resumed run rebuilds the same one for that geometry."""
        saved = super().checkpoint()
        if self._source is not None and self._source[0] is not None:
            key, T, scale, capacity = self._source
            saved.update({"implicit/amg_key": key, "implicit/amg_T": T, "implicit/amg_scale": scale,
                          "implicit/amg_capacity": capacity})  # fmt: skip
        return saved

    def restore(self, saved: dict) -> None:
        super().restore(saved)
        if "implicit/amg_key" in saved:
            self._resumed = (int(saved["implicit/amg_key"]), np.asarray(saved["implicit/amg_T"], dtype=np.float64),
                             float(saved["implicit/amg_scale"]), np.asarray(saved["implicit/amg_capacity"], dtype=np.float64))  # fmt: skip

    def advance(self, frame: Frame, h: np.ndarray, dt: float, frame_number: int = 0, start: Start | None = None, *,
                shells: np.ndarray | None = None) -> StepReport:  # fmt: skip
        """Advance ``h`` (and a resolved model's node enthalpies ``shells``) over ``dt``
        (:mod:`dpht.thermal.integrators`)."""
        model, idx = self.model, frame.particles
        if (shells is None) != (model.shells is None):
            raise DPHTError("implicit: node enthalpies (shells) are given exactly for a resolved model")
        before = dict(self.stats)
        if self._resumed is not None:  # its first frame after a resume: the geometry the hierarchy was built on?
            (key, *source), self._resumed = self._resumed, None
            if key == frame.key and self.preconditioner == "amg":
                self.network(frame)
                with network.threads_for(frame.particles.size):  # the same setup again: not counted
                    self._build(self._filled(*source), source)
        net, T0, heat, clamped = self.begin(frame, h, start, shells)
        mean = start.mean_T if start is not None else (T0 if shells is None else model.enthalpy.temperature_rows(h, idx))
        if dt == 0.0:
            network.element_heat(model, net, T0, 1.0, heat)
            return StepReport(0, heat, mean, self.name, {"clamped": clamped})
        with network.threads_for(net.n):
            if shells is None:
                h[idx], convected = self.step(h[idx], dt, heat, T0, frame_number)
            else:
                convected = self._resolved_step(h, shells, idx, dt, heat, frame_number)
        self.stats["steps"] += 1
        return StepReport(1, heat, mean, self.name, {**{k: self.stats[k] - before[k] for k in self.stats}, "clamped": clamped},
                          convected=convected)  # fmt: skip

    def step(self, h_n: np.ndarray, dt: float, heat: np.ndarray, T_n: np.ndarray, frame_number: int = 0) -> tuple[np.ndarray, float]:
        """Specific enthalpies (J/kg, frame order) one step of ``dt`` (s) after ``h_n`` (at
        temperatures ``T_n``) and the heat from the gas (J); adds the step's mean wall heat (W) to ``heat``."""
        model, net, m = self.model, self.net, self.model.mass
        if self.scheme == "backward_euler":
            T, q = self._solve(h_n, dt, T_n, frame_number)
            network.element_heat(model, net, T, 1.0, heat)
            return h_n + (dt / m) * q, dt * self._convected(T)
        network.conductances(model, net, T_n)
        q_n = np.empty(net.n)
        self._rates(T_n, q_n, self.g)
        network.element_heat(model, net, T_n, WEIGHTS[0], heat)
        c = 0.5 * GAMMA * dt
        T_g, q_g = self._solve(h_n + (c / m) * q_n, c, T_n, frame_number)
        network.element_heat(model, net, T_g, WEIGHTS[1], heat)
        h_g = h_n + (c / m) * (q_n + q_g)
        T_1, q_1 = self._solve(_A * h_g - (_A - 1.0) * h_n, _B * dt, T_g, frame_number)
        network.element_heat(model, net, T_1, WEIGHTS[2], heat)
        convected = dt * (WEIGHTS[0] * self._convected(T_n) + WEIGHTS[1] * self._convected(T_g) + WEIGHTS[2] * self._convected(T_1))
        return h_n + (dt / m) * (WEIGHTS[0] * q_n + WEIGHTS[1] * q_g + WEIGHTS[2] * q_1), convected

    def _rates(self, T: np.ndarray, q: np.ndarray, g: np.ndarray) -> None:
        """Heat into each node (W) and its conductance sum (W/K) with the network's conductances,
        the gas included for uniform particles (resolved ones take it in their condensed block)."""
        network.rates(self.model, self.net, T, q, g)
        if self.hA > 0.0 and self.model.shells is None:
            q += self.hA * (self.model.convection.gas_temperature - T)
            g += self.hA

    def _convected(self, T: np.ndarray) -> float:
        """Heat rate (W) from the gas into uniform particles at ``T``."""
        return self.hA * math.fsum(self.model.convection.gas_temperature - T) if self.hA > 0.0 else 0.0

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
            correction = self._linear(-residual, (T, c_dt, m * self.cp))
            T += correction
            if not np.all(np.isfinite(T)):
                raise DPHTError(f"frame {frame_number}: the implicit iteration produced non-finite temperatures")
            size = float(np.max(np.abs(correction), initial=0.0))
            if size <= self.tolerance:
                break
            newton, previous = size < previous, size  # Newton while the corrections shrink, else Picard
        else:
            self._unconverged(frame_number, size)
        self.stats["iterations"] += iteration
        network.conductances(model, net, T)
        self._rates(T, self.q, self.g)
        return T, self.q.copy()

    def _resolved_step(self, h: np.ndarray, shells: np.ndarray, idx: np.ndarray, dt: float, heat: np.ndarray,
                       frame_number: int) -> float:  # fmt: skip
        """Backward Euler of resolved particles (module docstring): advances ``shells[idx]`` and
        ``h[idx]``, adds the mean wall heat (W) to ``heat``; returns the heat from the gas (J)."""
        model, net, m, grid, table = self.model, self.net, self.model.mass, self.model.shells, self.model.enthalpy
        k_table = model.conductivity  # lambda(T) of the particles
        T = intraparticle.temperatures(shells, idx, *table.arrays)  # (Na, n) K, frame order
        newton, previous = False, math.inf
        for iteration in range(1, self.max_iterations + 1):
            self.stats["newton_iterations"] += newton
            surface = np.ascontiguousarray(T[:, -1])
            slopes = self.slopes if newton else None
            network.conductances(model, net, surface, slopes)
            schur, own = intraparticle.condense(shells, idx, T, dt, m, grid, model.convection, table.T0, table.dT, table.h,
                                                k_table, self.pivot, self.upper, self.rhs)  # fmt: skip
            self._fill(surface, schur, dt, slopes)
            delta = self._linear(own + dt * self.q, (surface, dt, schur))
            largest = intraparticle.back_substitute(T, delta, self.pivot, self.upper, self.rhs)
            if not np.isfinite(largest):
                raise DPHTError(f"frame {frame_number}: the implicit iteration produced non-finite temperatures")
            if largest <= self.tolerance:
                break
            newton, previous = largest < previous, largest  # as in _solve
        else:
            self._unconverged(frame_number, largest)
        self.stats["iterations"] += iteration
        surface = np.ascontiguousarray(T[:, -1])
        network.conductances(model, net, surface)
        self._rates(surface, self.q, self.g)
        network.element_heat(model, net, surface, 1.0, heat)
        convected = np.zeros(idx.size)
        intraparticle.commit(shells, idx, T, self.q, dt, m, grid, model.convection, table.T0, table.dT, table.h, k_table,
                             convected)  # fmt: skip
        h[idx] += (dt * self.q + convected) / m
        return math.fsum(convected)

    def _unconverged(self, frame_number: int, last: float) -> None:
        self.stats["unconverged"] += 1
        log.warning("frame %d: implicit iteration not converged to %.1e K in %d iterations (last correction %.3g K); "
                    "energy stays conserved", frame_number, self.tolerance, self.max_iterations, last)  # fmt: skip

    def _matrix_at(self, T: np.ndarray, c_dt: float, newton: bool = False) -> None:
        """Fill the iteration matrix ``m c_p(T) - c_dt dq/dT`` (W/K) at ``T``: Picard's (the conductances
        frozen) or Newton's (their slopes too); ``q(T)``, ``h(T)`` and ``c_p(T)`` into the work arrays
        and the conductances left at ``T``."""
        model, net, table = self.model, self.net, self.model.enthalpy
        slopes = self.slopes if newton else None
        network.conductances(model, net, T, slopes)
        _enthalpy_and_capacity(T, table.T0, table.dT, table.h, self.h_T, self.cp)
        self._fill(T, model.mass * self.cp, c_dt, slopes)

    def _fill(self, T: np.ndarray, capacity: np.ndarray, c_dt: float, slopes: network.Slopes | None = None) -> None:
        """The matrix ``capacity - c_dt dq/dT`` (W/K) from the network's conductances at ``T`` (and
        their slopes for Newton), and ``q(T)`` (W) into ``self.q``: the gas's conductance joins the
        diagonal of uniform particles and its heat their ``q`` (resolved ones take it in their
        condensed block, ``capacity``)."""
        gas = self.hA > 0.0 and self.model.shells is None
        self.matrix.fill(self.model, T, capacity + c_dt * self.hA if gas else capacity, c_dt, self.q, slopes)
        if gas:
            self.q += self.hA * (self.model.convection.gas_temperature - T)

    def _filled(self, T: np.ndarray, c_dt: float, capacity: np.ndarray) -> network.Matrix:
        """The Picard matrix of a saved source (``T``, ``c_dt``, diagonal ``capacity``), rebuilt after a resume."""
        network.conductances(self.model, self.net, T)
        self._fill(T, capacity, c_dt)
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
        T, scale, capacity = source
        self._source = (self._frame.key, T.copy(), scale, np.array(capacity, dtype=np.float64))

    def _linear(self, b: np.ndarray, source) -> np.ndarray:
        """Solve ``A x = b`` with the matrix just filled; ``source`` (T, c dt, diagonal capacity) is
        what it was made from (a Picard matrix when the AMG hierarchy is built from it)."""
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
        solve of about 4 + 16 r / (r + 10) GMRES iterations (~0.25 each); resolved particles add
        their node solve to every iteration and once more for the update (:data:`intraparticle.COST_PER_NODE`)."""
        r = max(stiffness.typical, 0.0)
        stages = 1 if self.scheme == "backward_euler" else 2
        iterations = 4.0 + math.log10(1.0 + r)
        krylov_iterations = 4.0 + 16.0 * r / (r + 10.0)
        nodes = intraparticle.COST_PER_NODE * (self.model.shells.n if self.model.shells is not None else 0)
        return (0.0 if stiffness.reused else 30.0) + nodes + stages * iterations * (4.0 + 0.25 * krylov_iterations + nodes)
