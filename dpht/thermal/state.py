"""What the thermal stage carries from one frame to the next (:class:`State`) and the two steps
that change it each frame: :func:`recycle` (particles re-entering at the inlet) and :func:`step`
(one call of the time integrator over the frame's interval).

The State after any frame plus the rows written so far is the whole run (:mod:`dpht.thermal.stage`),
so a checkpoint of the State (:mod:`dpht.thermal.checkpoint`) is all a resumed run needs. With
resolved intra-particle conduction (``thermal.intraparticle``, :mod:`dpht.thermal.intraparticle`)
it also holds every particle's shell enthalpies; the written temperature is the particle's mean
(from h), the one the energy books use.

Energy bookkeeping (J): between consecutive rows, the change of ``energy_particles`` equals the
change of ``energy_wall`` (the interval's mean wall heat times its length) plus those of
``energy_recycled`` and ``energy_convected`` (particle-gas convection, ``thermal.convection``),
to round-off.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from dpht.thermal import integrate, integrators
from dpht.thermal.inflow import node_enthalpies
from dpht.thermal.model import ThermalModel
from dpht.thermal.output import Row
from dpht.thermal.schedule import Schedule

log = logging.getLogger("dpht")

# Look-ups clamped at a table's edge, counted per frame at its start and summed over the run: PFP and
# PFW distances below their HTC table (deep overlaps without softening), and particles whose
# temperature lies outside a temperature table (ThermalModel.lookup_range).
CLAMPED = ("pfp_distance", "pfw_distance", "temperature")


@dataclass
class State:
    """Everything the run carries from one frame to the next (what a checkpoint must hold)."""

    count: int  # thermal frames taken so far (the index of the next one)
    h: np.ndarray  # (N,) J/kg, specific enthalpy of every particle, in the positions file's order
    wall_energy: float  # J received from the walls since the first frame
    recycled_energy: float  # J, enthalpy change from resetting re-entering particles
    previous: tuple | None  # (positions, image flags) of the last frame taken, to detect re-entry
    frames_by: dict = field(default_factory=lambda: dict.fromkeys(integrators.NAMES, 0))  # frames each integrator ran
    clamped: dict = field(default_factory=lambda: dict.fromkeys(CLAMPED, 0))  # look-ups clamped so far, by kind
    integrator: dict = field(default_factory=dict)  # the integrator's checkpoint, taken when the State is saved
    shells: np.ndarray | None = None  # (N, n) J/kg, shell enthalpies of resolved particles (mean: h)
    convected_energy: float = 0.0  # J received from the gas (thermal.convection) since the first frame

    @classmethod
    def initial(cls, model: ThermalModel, n: int) -> State:
        h0 = model.enthalpy.enthalpy(model.initial_temperature)[()]
        shells = np.full((n, model.shells.n), h0) if model.shells is not None else None
        return cls(0, np.full(n, h0), 0.0, 0.0, None, shells=shells)

    def particle_energy(self, model: ThermalModel) -> float:
        """Total particle enthalpy (J, relative to the enthalpy table's T0)."""
        return model.mass * math.fsum(self.h)


def recycle(model: ThermalModel, schedule: Schedule, state: State, positions: np.ndarray, image, inflow=None) -> None:
    """Reset particles that re-entered at the inlet since the last frame to the inlet temperature,
    or with an ``inflow`` holding an inlet field (:class:`dpht.thermal.inflow.Inflow`) to the
    field's temperature at their cross-section position.

    A re-entry is a downward crossing of the recycled flow axis (from the image flags, or a jump of
    more than half the box); its enthalpy change is booked in ``state.recycled_energy``, as is that
    of the particles an inflow with an inlet plane feeds (:meth:`dpht.thermal.inflow.Inflow.feed`).
    """
    if state.previous is not None and schedule.flow_axis is not None:
        last_positions, last_image = state.previous
        crossed = integrate.wrapped(last_image, image, last_positions, positions, schedule.box_lo, schedule.box_hi,
                                    schedule.flow_axis)  # fmt: skip
        if inflow is None or inflow.inlet is None:
            h_inlet = nodes = model.enthalpy.enthalpy(model.inlet_temperature)[()]
        else:
            entering = inflow.reentering(model, positions[crossed])
            h_inlet = entering[:, 0]
            nodes = node_enthalpies(model, entering) if state.shells is not None else None
        state.recycled_energy += model.mass * float(np.sum(h_inlet - state.h[crossed]))
        state.h[crossed] = h_inlet
        if state.shells is not None:
            state.shells[crossed] = nodes
        if inflow is not None:  # a segment of a chain fed at its inlet plane (dpht.thermal.inflow)
            inflow.feed(model, schedule, state, last_positions, positions)
    state.previous = (positions, image)


def step(model: ThermalModel, schedule: Schedule, state: State, positions: np.ndarray, integrator,
         frame: integrate.Frame | None = None) -> tuple[Row, integrate.StepReport]:  # fmt: skip
    """Advance the enthalpies over the interval that starts at this frame (held fixed meanwhile)
    with ``integrator`` (see :mod:`dpht.thermal.integrators`); ``frame`` is the frame's prepared
    geometry when the caller keeps it (a frozen bed), else it is prepared from ``positions``.

    Returns the frame's output row and the integrator's report.
    """
    count = state.count
    energy_particles = state.particle_energy(model)
    if frame is None:
        frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic, key=count)
    dt = schedule.interval(count)
    if model.wall_temperature_at is not None:  # a travelling slice: the wall where it is mid-interval
        model.element_temperature[:] = model.wall_temperature_at(schedule.times[count] + 0.5 * dt)
    report = integrator.advance(frame, state.h, dt, frame_number=schedule.frames[count],
                                **({} if state.shells is None else {"shells": state.shells}))  # fmt: skip
    integrate.check_finite(state.h[frame.particles], frame.particles, schedule.frames[count], report.substeps,
                           lambda i: f"enthalpy {float(state.h[frame.particles[i]])!r} J/kg after the {report.integrator} step")  # fmt: skip
    if report.substeps:
        state.frames_by[report.integrator] += 1
    lo, hi = model.lookup_range()
    outside = {**report.stats.get("clamped", {}),
               "temperature": int(np.count_nonzero((report.temperature < lo) | (report.temperature > hi)))}  # fmt: skip
    if any(outside.values()) and not any(state.clamped.values()):
        log.warning("thermal: frame %d has table look-ups outside their range, clamped to the table's edge "
                    "(%s; counted in the summary's clamped_lookups)", schedule.frames[count],
                    ", ".join(f"{k} {v}" for k, v in outside.items()))  # fmt: skip
    for key, value in outside.items():
        state.clamped[key] += value
    temperature = np.full(state.h.size, np.nan, dtype=np.float32)  # lost particles stay NaN
    temperature[frame.particles] = report.temperature
    row = Row(schedule.times[count], temperature, report.element_heat, report.substeps, energy_particles,
              state.wall_energy, state.recycled_energy, state.convected_energy)  # fmt: skip
    state.wall_energy += dt * math.fsum(report.element_heat.ravel())
    state.convected_energy += report.convected
    state.count += 1
    return row, report
