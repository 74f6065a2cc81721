"""The frame's geometry and heat rates, and the explicit integrator (DPHT paper, Eq. 1, in enthalpy form).

Each particle's specific enthalpy h advances by ``q dt / m``; temperatures follow from h (see
:mod:`dpht.closures.heat_capacity`), so the change of particle energy equals the wall heat to round-off.
The other integrators (:mod:`dpht.thermal.integrators`, the registry) share :class:`Frame`,
:class:`StepReport` and :class:`Start` with this one.

Explicit stability: with every mode written as a conductance, one step is a convex combination of
temperatures when ``dt * sum_j G_ij <= m c_p,min`` for every particle, which also guarantees the
maximum principle. Each frame is split into the fewest equal sub-steps meeting that bound,
re-checked at every sub-step; a frame needing more than ``max_substeps`` stops the run with a
message naming the limit, never silently producing garbage.

Resolved particles (``model.shells``, :mod:`dpht.thermal.intraparticle`): the surface modes are
evaluated with each particle's surface-node temperature and their heat q enters the surface node;
the nodes then take one implicit step per sub-step, and the mean enthalpy h still advances by
exactly ``q dt / m``, so the energy bookkeeping is the lumped one. The sub-steps keep the bound
above with the surface node's effective heat capacity in place of the particle's,
``dt * sum_j G_ij <= m w_outer c_p,min`` (w_outer = :attr:`ShellGrid.outer`, the node's share of
the mass that a short step's surface heat sees: 0.080 at 10 nodes), so a frame that sub-steps takes
up to 1 / w_outer times more sub-steps than with uniform particles; the implicit integrator takes
resolved particles at any step.

Particle-gas convection (``model.convection``, h_conv A (T_gas - T)): implicit per particle in
every sub-step (backward Euler; for uniform particles linearised with the enthalpy table's slope,
for resolved ones a Robin condition solved with the nodes), the other modes explicit, so the gas
does not bound the sub-step and uniform and resolved particles share one time discretisation; its
heat is reported as ``StepReport.convected`` (J), so the books read particle energy change = wall
heat + convected heat (+ recycling). The implicit integrator
advances both too; multirate neither (:data:`dpht.thermal.integrators.SHELLS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numba as nb
import numpy as np

from dpht.thermal import intraparticle, neighbors, wall_distance as walls
from dpht.closures.heat_capacity import specific_heat_at
from dpht.errors import DPHTError
from dpht.thermal.kernels import pair_side, wall_side
from dpht.thermal.model import ThermalModel


@dataclass
class Frame:
    """Geometry of one DEM frame, fixed while the frame's sub-steps run."""

    particles: np.ndarray  # (Na,) original index of each active particle, in cell-sorted order
    cells: neighbors.CellList | None  # None when no particle-particle mode is enabled
    wall_element: np.ndarray  # (S, Na) int32 element at the nearest point of each wall surface, -1: no contact
    wall_distance: np.ndarray  # (S, Na) m, to that point
    # Which geometry of the run this is, the same in a run resumed from a checkpoint: the thermal
    # frame it was prepared for (a frozen bed's one geometry: frame 0); None where nobody resumes.
    key: int | None = None


def prepare_frame(model: ThermalModel, positions: np.ndarray, box_lo, box_hi, periodic, key: int | None = None) -> Frame:
    """Cell list and wall contacts (one per wall surface, see :mod:`dpht.thermal.model`) for the
    finite positions of one frame; ``key`` is the Frame's.

    ``periodic`` (3 bools) are the axes across which heat flows through the box boundary: the
    physically periodic ones, never an axis the DEM only recycles particles across (see
    :class:`dpht.thermal.stage.Schedule`). Wall distances are taken in the cell list's
    coordinates, where positions on a periodic axis are wrapped into the box (DEM codes write them
    so anyway).
    """
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    cutoff = model.pair_cutoff
    if cutoff > 0:
        cells = neighbors.build(positions, cutoff, box_lo=box_lo, box_hi=box_hi, periodic=periodic)
        order, coords, axes = cells.order, cells.coords, cells.axes
    else:
        cells, order = None, np.flatnonzero(np.all(np.isfinite(positions), axis=1))
        coords, axes = np.ascontiguousarray(positions[order].T), np.arange(3)
    element = np.empty((len(model.surfaces), order.size), dtype=np.int32)
    distance = np.empty((len(model.surfaces), order.size))
    for s, surface in enumerate(model.surfaces):
        walls.surface_contacts(surface, coords, axes, element[s], distance[s])
    return Frame(order, cells, element, distance, key)


class Rates(NamedTuple):
    """Work arrays for one evaluation of the heat rates (reused across frames): the rate kernels'
    output record (``rates`` of :func:`dpht.thermal.kernels.pair_side` and ``wall_side``), filled in place."""

    q: np.ndarray  # W into each active particle (sorted order)
    g: np.ndarray  # W/K, sum of conductances per particle
    element_heat: np.ndarray  # (M, P) W per wall element and PW mode (the model's PW modes in order)
    clamped_pairs: np.ndarray  # (Na,) int64, PFP look-ups below the table's first distance, per particle
    clamped_walls: np.ndarray  # (1,) int64, the same for PFW

    @classmethod
    def for_frame(cls, model: ThermalModel, frame: Frame) -> Rates:
        n = frame.particles.size
        return cls(np.zeros(n), np.zeros(n), np.zeros((model.n_elements, len(model.names("pw")))), np.zeros(n, np.int64),
                   np.zeros(1, np.int64))  # fmt: skip

    def clamped(self) -> dict:
        """Look-ups clamped below a table's first distance in the last evaluation."""
        return {"pfp_distance": int(self.clamped_pairs.sum()), "pfw_distance": int(self.clamped_walls[0])}


def evaluate(model: ThermalModel, frame: Frame, T: np.ndarray, rates: Rates) -> None:
    """Heat rates for temperatures ``T`` (K, sorted order) into ``rates``."""
    rates.q[:] = 0.0
    rates.g[:] = 0.0
    rates.element_heat[:] = 0.0
    rates.clamped_pairs[:] = 0
    rates.clamped_walls[:] = 0
    m = model
    if frame.cells is not None and m.modes & set(m.names("pp")):
        pair_side(m.side_laws("pp")).rates(frame.cells.grid, frame.cells.coords, T, rates, m.state("pp"))
    if m.surfaces and m.modes & set(m.names("pw")):
        wall_side(m.side_laws("pw")).rates(T, frame.wall_element, frame.wall_distance, m.element_temperature, rates, m.state("pw"))


@dataclass
class StepReport:
    """What an integrator reports for one frame."""

    substeps: int  # time steps taken in the interval (explicit: sub-steps; multirate: finest steps)
    element_heat: np.ndarray  # (M, P) W per PW mode, time mean over the frame interval
    temperature: np.ndarray  # (Na,) K at the start of the frame, in the frame's (sorted) order
    integrator: str = "explicit"
    stats: dict = field(default_factory=dict)  # integrator-specific counts (iterations, levels, ...)
    convected: float = 0.0  # J into the particles from the gas (thermal.convection) over the interval


@dataclass
class Start:
    """The rates evaluated at the start of a frame (``rates`` at temperatures ``T``, frame order: the
    surface nodes' of resolved particles), handed from the automatic choice to the integrator it
    picks so no work is repeated; ``mean`` the particles' mean temperatures (``T`` when uniform)."""

    T: np.ndarray
    rates: Rates
    mean: np.ndarray | None = None

    @property
    def mean_T(self) -> np.ndarray:
        return self.T if self.mean is None else self.mean


def temperatures(model: ThermalModel, h: np.ndarray, idx: np.ndarray, shells: np.ndarray | None = None,
                 mean: bool = True) -> tuple[np.ndarray, np.ndarray | None]:  # fmt: skip
    """(the temperatures the surface modes see, the particles' mean temperatures) (K) of the
    particles ``idx`` (frame order) from their enthalpies ``h`` (J/kg) and, when resolved, the
    node enthalpies ``shells``; the mean is None for resolved particles unless ``mean``."""
    T_mean = model.enthalpy.temperature_rows(h, idx) if mean or shells is None else None
    if shells is None:
        return T_mean, T_mean
    return intraparticle.surface_temperature(shells, idx, *model.enthalpy.arrays), T_mean


def advance(model: ThermalModel, frame: Frame, h: np.ndarray, dt: float, rates: Rates, frame_number: int = 0,
            start: Start | None = None, *, shells: np.ndarray | None = None) -> StepReport:  # fmt: skip
    """Advance specific enthalpies ``h`` (J/kg, original order) over ``dt`` (s) with this frame's positions.

    ``dt == 0`` only evaluates the rates (the report then holds the instantaneous wall heat). With
    ``start``, its rates (in ``rates``) are those of the first sub-step. A resolved model also
    advances ``shells`` ((N, n) J/kg, the node enthalpies; module docstring).
    """
    grid = model.shells
    # J/K, lower bound over the scene's range of the capacity the surface heat enters
    capacity = model.mass * model.enthalpy.cp_min * (grid.outer if grid is not None else 1.0)
    idx = frame.particles
    mean_heat = np.zeros((model.n_elements, len(model.names("pw"))))
    remaining, substeps = dt, 0
    T_start = None
    gas = model.convection
    hA = gas.coefficient * 4.0 * math.pi * model.radius**2  # W/K of the particle-gas convection
    convected = 0.0
    while True:
        check_finite(h[idx], idx, frame_number, substeps, lambda i: f"enthalpy {float(h[idx[i]])!r} J/kg")
        if start is not None:  # the first sub-step's rates are given
            T, mean = start.T, start.mean_T
            start = None
        else:  # the surface modes see the surface nodes of resolved particles
            T, mean = temperatures(model, h, idx, shells, mean=T_start is None)
            evaluate(model, frame, T, rates)
        for values in (rates.q, rates.g):
            check_finite(values, idx, frame_number, substeps, lambda i: (
                f"heat rate {float(rates.q[i])!r} W, conductance sum {float(rates.g[i])!r} W/K at {T[i]:.6g} K"))
        if T_start is None:  # the particles' mean temperatures, the ones the energy books use
            T_start, clamped = mean, rates.clamped()
        rate = float(rates.g.max()) / capacity if rates.g.size else 0.0  # 1/s
        if dt == 0.0:
            mean_heat += rates.element_heat
            break
        n = max(1, math.ceil(remaining * rate * (1 - 1e-12)))
        if substeps + n > model.max_substeps:
            stiffest = int(np.argmax(rates.g))
            raise DPHTError(
                f"frame {frame_number}: the explicit stability limit needs {substeps + n} sub-steps, more than "
                f"thermal.max_substeps = {model.max_substeps} (particle {int(idx[stiffest])}: sum of conductances "
                f"{rates.g[stiffest]:.3g} W/K, heat capacity >= {capacity:.3g} J/K"
                f"{' (its surface node)' if grid is not None else ''}, so dt <= {1 / rate:.3g} s "
                f"against a frame step of {dt:.3g} s). Raise thermal.max_substeps or dump DEM frames more often."
            )
        step = remaining / n
        if hA > 0.0 or grid is not None:
            robin = np.zeros(idx.size)  # J from the gas per particle over the sub-step
        if grid is not None:  # resolved: the gas acts on the surface, implicitly (Robin) in the shell solve
            intraparticle.advance(shells, idx, rates.q, step, 1, model.mass, grid, gas, *model.enthalpy.arrays,
                                  model.conductivity, 1, robin)  # fmt: skip
        elif hA > 0.0:  # uniform: the gas implicitly too, particle by particle
            _gas_step(rates.q, T, step, model.mass, hA, gas.gas_temperature, model.enthalpy.T0,
                      model.enthalpy.dT, model.enthalpy.h, robin)  # fmt: skip
        _add_rows(h, idx, rates.q, step / model.mass)
        if hA > 0.0:
            _add_rows(h, idx, robin, 1.0 / model.mass)
            convected += math.fsum(robin)
        mean_heat += rates.element_heat * (step / dt)
        substeps += 1
        remaining -= step
        if n == 1:
            break
    check_finite(h[idx], idx, frame_number, substeps, lambda i: f"enthalpy {float(h[idx[i]])!r} J/kg at the end of the frame")
    return StepReport(substeps, mean_heat, T_start, stats={"clamped": clamped}, convected=convected)


def biot_numbers(model: ThermalModel, frame: Frame, T: float) -> tuple[np.ndarray, float]:
    """Biot number of every active particle (frame order) with all particles at ``T`` (K), and the
    particle conductivity (W/(m K)) at ``T``.

    ParScale's Eq. 8, Bi = alpha d_p / k_p, with alpha = G_i / (pi d_p^2) from the sum G_i (W/K) of
    the particle's surface conductances (every enabled mode: contact, gas gap, radiation, and the
    particle-gas convection h_conv pi d_p^2 of ``thermal.convection``), so
    Bi = G_i / (pi d_p k_p).
    """
    rates = Rates.for_frame(model, frame)
    evaluate(model, frame, np.full(frame.particles.size, float(T)), rates)
    np.add(rates.g, model.convection.coefficient * 4.0 * math.pi * model.radius**2, out=rates.g)  # particle-gas convection
    k = model.conductivity
    k_p = float(np.interp(T, k.x0 + k.dx * np.arange(k.values.size), k.values))
    return rates.g / (math.pi * 2.0 * model.radius * k_p), k_p


class Explicit:
    """The explicit integrator (registry name ``explicit``): :func:`advance`, with the work arrays
    kept from frame to frame."""

    name = "explicit"

    def __init__(self, model: ThermalModel, options: dict | None = None):
        self.model = model
        self.rates: Rates | None = None

    def work(self, frame: Frame) -> Rates:
        """Work arrays sized for ``frame`` (reused while the particle count stays)."""
        if self.rates is None or self.rates.q.size != frame.particles.size:
            self.rates = Rates.for_frame(self.model, frame)
        return self.rates

    def advance(self, frame: Frame, h: np.ndarray, dt: float, frame_number: int = 0, start: Start | None = None, *,
                shells: np.ndarray | None = None) -> StepReport:  # fmt: skip
        """:func:`advance`; ``shells`` are a resolved model's shell enthalpies (the only integrator taking them)."""
        rates = start.rates if start is not None else self.work(frame)
        return advance(self.model, frame, h, dt, rates, frame_number, start, shells=shells)

    def checkpoint(self) -> dict:
        """Nothing carried from frame to frame (the work arrays are refilled)."""
        return {}

    def restore(self, saved: dict) -> None:
        pass

    def cost(self, stiffness) -> float:
        """Rate evaluations of one frame: one per sub-step (and a resolved model's node solve)."""
        nodes = self.model.shells.n if self.model.shells is not None else 0
        return float(max(1, math.ceil(stiffness.largest * (1 - 1e-12)))) * (1.0 + intraparticle.COST_PER_NODE * nodes)


class NonFiniteTemperature(DPHTError):
    """A particle's temperature became NaN or infinite; ``particle`` is its row in the positions file."""

    def __init__(self, message: str, particle: int):
        super().__init__(message)
        self.particle = particle


def check_finite(values, particles, frame_number: int, substep: int, what) -> None:
    """Stop with :class:`NonFiniteTemperature` naming the frame and the first particle whose value
    is not finite: ``values[i]`` belongs to particle ``particles[i]`` (the frame's sorted order), and
    ``what(i)`` describes it. A NaN enthalpy would otherwise turn into a clamped, finite-looking
    temperature, and a NaN rate into a bare ValueError from the sub-step count."""
    i = _first_non_finite(values)
    if i >= 0:
        row = int(particles[i])
        raise NonFiniteTemperature(
            f"frame {frame_number}, sub-step {substep}: particle {row} (row of the positions file) has a non-finite "
            f"temperature: {what(i)}. Check the tables and expressions it reads (particles.specific_heat, "
            f"particles.conductivity, thermal.walls temperatures) at the scene's temperatures.",
            row,
        )


@nb.njit(cache=True)
def _first_non_finite(values):
    for i in range(values.size):
        if not np.isfinite(values[i]):
            return i
    return -1


@nb.njit(cache=True, parallel=True)
def _gas_step(q, T, dt, mass, hA, T_gas, T0, dT, h_table, gained):
    """The gas's heat (J) into uniform particle i over ``dt``, backward Euler linearised with the
    enthalpy table's slope c at ``T[i]``: with dh = dt (q + hA (T_gas - T - dh / c)) / m (``q[i]``
    the other modes' heat, explicit), it is m dh - dt q = dt hA (T_gas - T - dh / c)."""
    for i in nb.prange(q.size):
        c = specific_heat_at(T[i], T0, dT, h_table)
        dh = dt * (q[i] + hA * (T_gas - T[i])) / (mass + dt * hA / c)  # J/kg
        gained[i] = mass * dh - dt * q[i]


@nb.njit(cache=True, parallel=True)
def _add_rows(h, rows, q, factor):
    """``h[rows] += factor * q`` in parallel (rows are distinct)."""
    for i in nb.prange(rows.size):
        h[rows[i]] += factor * q[i]


def wrapped(previous_image, image, previous_positions, positions, box_lo, box_hi, axis: int) -> np.ndarray:
    """Particles that crossed the periodic boundary of ``axis`` downwards (towards lower coordinate).

    Uses image flags when given; otherwise a jump of more than half the box upwards between frames.
    """
    if image is not None and previous_image is not None:
        return image[:, axis] < previous_image[:, axis]
    length = box_hi[axis] - box_lo[axis]
    with np.errstate(invalid="ignore"):
        return positions[:, axis] - previous_positions[:, axis] > 0.5 * length
