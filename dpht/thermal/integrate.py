"""Time integration of particle enthalpy over one DEM frame (DPHT paper, Eq. 1, in enthalpy form).

Each particle's specific enthalpy h advances by ``q dt / m``; temperatures follow from h (see
:mod:`dpht.closures.heat_capacity`), so the change of particle energy equals the wall heat to round-off.

Explicit stability: with every mode written as a conductance, one step is a convex combination of
temperatures when ``dt * sum_j G_ij <= m c_p,min`` for every particle, which also guarantees the
maximum principle. Each frame is split into the fewest equal sub-steps meeting that bound,
re-checked at every sub-step; a frame needing more than ``max_substeps`` stops the run with a
message naming the limit, never silently producing garbage.

Resolved particles (``model.shells``, :mod:`dpht.thermal.intraparticle`): the surface modes are
evaluated with each particle's outer-shell temperature and their heat q enters the outer shell; the
shells then take one implicit step per sub-step, and the mean enthalpy h still advances by exactly
``q dt / m``, so the energy bookkeeping is the lumped one. The convexity bound above then holds with
the outer shell's heat capacity in place of the particle's (the interior solve is an M-matrix, so
``dt * sum_j G_ij <= m w_outer c_p,min`` keeps every shell inside the neighbours' range).

Particle-gas convection (``model.convection``, h_conv A (T_gas - T)): for uniform particles one
more conductance in the explicit step (and its bound), for resolved ones a Robin condition solved
implicitly with the shells; its heat is reported as ``StepReport.convected`` (J), so the books read
particle energy change = wall heat + convected heat (+ recycling).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from dpht.thermal import intraparticle, neighbors, wall_distance as walls
from dpht.errors import DPHTError
from dpht.thermal.kernels import pair_kernel, wall_kernel
from dpht.thermal.modes import PP_MODES, PW_MODES
from dpht.thermal.model import ThermalModel


@dataclass
class Frame:
    """Geometry of one DEM frame, fixed while the frame's sub-steps run."""

    particles: np.ndarray  # (Na,) original index of each active particle, in cell-sorted order
    cells: neighbors.CellList | None  # None when no particle-particle mode is enabled
    wall_element: np.ndarray  # (Z, Na) int32 nearest element per Dirichlet zone, -1 if none
    wall_distance: np.ndarray  # (Z, Na) m


def prepare_frame(model: ThermalModel, positions: np.ndarray, box_lo, box_hi, periodic) -> Frame:
    """Cell list and wall contacts for the finite positions of one frame.

    Wall distances are taken in the cell list's coordinates, where positions on a periodic axis
    are wrapped into the box (DEM codes write them so anyway).
    """
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    cutoff = model.pair_cutoff
    if cutoff > 0:
        cells = neighbors.build(positions, cutoff, box_lo=box_lo, box_hi=box_hi, periodic=periodic)
        order, coords, axes = cells.order, cells.coords, cells.axes
    else:
        cells, order = None, np.flatnonzero(np.all(np.isfinite(positions), axis=1))
        coords, axes = np.ascontiguousarray(positions[order].T), np.arange(3)
    element = np.empty((len(model.zones), order.size), dtype=np.int32)
    distance = np.empty((len(model.zones), order.size))
    for z, index in enumerate(model.zones):
        walls.nearest_elements(index, coords, axes, element[z], distance[z])
    return Frame(order, cells, element, distance)


@dataclass
class Rates:
    """Work arrays for one evaluation of the heat rates (reused across frames)."""

    q: np.ndarray  # W into each active particle (sorted order)
    g: np.ndarray  # W/K, sum of conductances per particle
    element_heat: np.ndarray  # (M, len(PW_MODES)) W per wall element and PW mode

    @classmethod
    def for_frame(cls, model: ThermalModel, frame: Frame) -> Rates:
        n = frame.particles.size
        return cls(np.zeros(n), np.zeros(n), np.zeros((model.n_elements, len(PW_MODES))))


def evaluate(model: ThermalModel, frame: Frame, T: np.ndarray, rates: Rates) -> None:
    """Heat rates for temperatures ``T`` (K, sorted order) into ``rates``."""
    rates.q[:] = 0.0
    rates.g[:] = 0.0
    rates.element_heat[:] = 0.0
    m = model
    if frame.cells is not None and m.modes & set(PP_MODES):
        pair_kernel(m.flags(PP_MODES))(frame.cells.grid, frame.cells.coords, T, rates.q, rates.g, m.pair, *m.pair_tables)
    if m.zones and m.modes & set(PW_MODES):
        wall_kernel(m.flags(PW_MODES))(
            T, frame.wall_element, frame.wall_distance, m.element_temperature, rates.q, rates.g, rates.element_heat, 1.0,
            m.wall, *m.wall_tables,
        )  # fmt: skip


@dataclass
class StepReport:
    substeps: int
    element_heat: np.ndarray  # (M, len(PW_MODES)) W, time mean over the frame interval
    temperature: np.ndarray  # (Na,) K at the start of the frame, in the frame's (sorted) order
    convected: float = 0.0  # J into the particles from the gas (thermal.convection) over the interval


def advance(model: ThermalModel, frame: Frame, h: np.ndarray, dt: float, rates: Rates, frame_number: int = 0, *,
            shells: np.ndarray | None = None) -> StepReport:  # fmt: skip
    """Advance specific enthalpies ``h`` (J/kg, original order) over ``dt`` (s) with this frame's positions.

    ``dt == 0`` only evaluates the rates (the report then holds the instantaneous wall heat). A
    resolved model also advances ``shells`` ((N, n) J/kg, the shell enthalpies; module docstring).
    """
    grid = model.shells
    # J/K, lower bound over the scene's range of the capacity the surface heat enters
    capacity = model.mass * model.enthalpy.cp_min * (grid.volume_fraction[-1] if grid is not None else 1.0)
    idx = frame.particles
    mean_heat = np.zeros((model.n_elements, len(PW_MODES)))
    remaining, substeps = dt, 0
    start = None
    gas = model.convection
    hA = gas.coefficient * 4.0 * math.pi * model.radius**2  # W/K of the particle-gas convection
    convected = 0.0
    while True:
        T = model.enthalpy.temperature_rows(h, idx)
        start = T if start is None else start
        if grid is not None:  # the surface modes see the outer shell
            T = intraparticle.surface_temperature(shells, idx, *model.enthalpy.arrays)
        evaluate(model, frame, T, rates)
        if hA > 0.0 and grid is None:  # uniform particles: the gas is one more explicit conductance
            gained = hA * (gas.gas_temperature - T)
            rates.q += gained
            rates.g += hA
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
                f"{' (its outer shell)' if grid is not None else ''}, so dt <= {1 / rate:.3g} s "
                f"against a frame step of {dt:.3g} s). Raise thermal.max_substeps or dump DEM frames more often."
            )
        step = remaining / n
        _add_rows(h, idx, rates.q, step / model.mass)
        if grid is not None:  # resolved: the gas acts on the surface, implicitly (Robin) in the shell solve
            robin = np.zeros(idx.size)  # J per particle over the sub-step
            intraparticle.advance(shells, idx, rates.q, step, 1, model.mass, grid, gas, *model.enthalpy.arrays,
                                  model.pair_tables.pp_contact, 1, robin)  # fmt: skip
            if hA > 0.0:
                _add_rows(h, idx, robin, 1.0 / model.mass)
                convected += math.fsum(robin)
        elif hA > 0.0:
            convected += step * math.fsum(gained)
        mean_heat += rates.element_heat * (step / dt)
        substeps += 1
        remaining -= step
        if n == 1:
            break
    return StepReport(substeps, mean_heat, start, convected)


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
    rates.g += model.convection.coefficient * 4.0 * math.pi * model.radius**2  # particle-gas convection
    k = model.pair_tables.pp_contact
    k_p = float(np.interp(T, k.x0 + k.dx * np.arange(k.values.size), k.values))
    return rates.g / (math.pi * 2.0 * model.radius * k_p), k_p


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
