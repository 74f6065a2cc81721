"""What enters a segment of a chain (docs/theory/chain.md): the hand-over fields of the segment
upstream (:mod:`dpht.chain.field`) given to the thermal stage instead of one temperature.

- ``initial``: every particle of the first frame starts at the field's temperature at its position
  in the cross-section (a travelling slice entering the stretch below the previous segment), its
  enthalpies shifted so that the bed's mean enthalpy is the field's mixing-cup enthalpy
  (:func:`dpht.chain.field.assign`, the shift reported); a particle without a position in that
  frame (lost by the DEM) keeps ``thermal.initial_temperature``;
- ``inlet``: a particle re-entering at the top of a recycled tube takes the field's temperature at
  its cross-section position, instead of ``thermal.inlet_temperature`` (a resolved segment fed
  by the segment above). With an inlet ``plane`` (a resolved segment's top in its DEM, below where
  particles re-enter: :mod:`dpht.chain.scenes`), a re-entering particle takes the field's mixing
  cup instead, and each particle crossing the plane downwards the field at its position where it
  crossed: the field is given where the flow enters the segment, not where the DEM's periodic
  boundary (below a plate that turns the flow) puts it. Entering particles are taken as they come,
  a few per frame, so no shift is applied to them: the stage's books (``energy/recycled``) hold
  exactly what entered, and the summary how far their mean enthalpy was from the field's mixing
  cup (:meth:`Inflow.entered`).

Resolved particles take the field's node temperatures where the field has as many nodes as the
model, else every node starts at the particle's mean. Without fields the stage is unchanged, bit
for bit; a uniform field at the configured temperature gives the same run bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dpht.chain.field import Field, Handed, assign
from dpht.chain.files import load_field
from dpht.chain.outlet import crossed
from dpht.closures.heat_capacity import specific_heat_at
from dpht.errors import DPHTError
from dpht.thermal import integrate
from dpht.thermal.model import ThermalModel


@dataclass(frozen=True)
class Inflow:
    """The fields a run is handed (module docstring); either may be None; ``plane``: m, the inlet
    plane (None: the field is given at the periodic boundary)."""

    initial: Field | None = None
    inlet: Field | None = None
    plane: float | None = None

    @classmethod
    def of(cls, initial_field=None, inlet_field=None, plane: float | None = None) -> Inflow | None:
        """The fields in the files given (hand-over field files, :mod:`dpht.chain.files`), None without either."""
        if initial_field is None and inlet_field is None:
            return None
        return cls(*(None if path is None else load_field(path) for path in (initial_field, inlet_field)),
                   None if plane is None else float(plane))  # fmt: skip

    def check(self, model: ThermalModel) -> None:
        """DPHTError unless every field lies within the scene's temperatures (initial, inlet, walls:
        the range its enthalpy table covers, so that no hand-over is clamped)."""
        lo, hi = model.temperature_range
        for role, field in (("initial", self.initial), ("inlet", self.inlet)):
            if field is not None and not (lo <= field.temperature.min() and field.temperature.max() <= hi):
                raise DPHTError(f"the {role} hand-over field spans {field.temperature.min():.2f}-{field.temperature.max():.2f} K, "
                                f"outside the scene's temperatures {lo:.2f}-{hi:.2f} K (thermal.initial_temperature, "
                                "inlet_temperature and the walls'): set them to bound the field")

    def summary(self, started: Handed | None, entered: dict | None = None) -> dict:
        """The hand-over's books for the run's summary: each field's mixing-cup temperature and
        cells without samples, the initial field's shift (:meth:`dpht.chain.field.Handed.summary`)
        and what entered through the inlet field (:meth:`entered`)."""
        out = {}
        for role, field in (("initial", self.initial), ("inlet", self.inlet)):
            if field is not None:
                out[role] = {"cup_temperature_K": field.cup_temperature, "rings": field.grid.rings,
                             "sectors": field.grid.sectors, "filled_cells": field.filled}  # fmt: skip
        if started is not None:
            out["initial"].update(started.summary())
        if entered is not None:
            out["inlet"].update(entered)
        return out

    def entered(self, model: ThermalModel, schedule, dem) -> dict | None:
        """What entered through the inlet field over the run (``schedule``'s frames of the positions
        file ``dem``), the hand-over's books of a recycled segment: the particles that re-entered and
        their mean enthalpy's deviation from the field's mixing cup (J/kg, and K at the cup
        temperature). Re-entering particles are not shifted, so this is the imbalance the run
        carries: the receiving segment's particles cross its inlet elsewhere than the upstream
        segment's crossed its outlet, and their number is finite. None without an inlet field or
        a recycled axis."""
        if self.inlet is None or schedule.flow_axis is None:
            return None
        target = self.inlet.cup_enthalpy(model.enthalpy)
        deviations, previous = [], dem.frame(schedule.frames[0])
        for index in schedule.frames[1:]:
            current = dem.frame(index)
            if self.plane is None:
                wrapped = integrate.wrapped(previous.image, current.image, previous.positions, current.positions,
                                            schedule.box_lo, schedule.box_hi, schedule.flow_axis)  # fmt: skip
                entering = self.reentering(model, np.asarray(current.positions[wrapped], dtype=np.float64))
            else:
                entering = self.crossing(model, np.asarray(previous.positions, dtype=np.float64),
                                         np.asarray(current.positions, dtype=np.float64), schedule)[1]  # fmt: skip
            deviations.append(entering[:, 0] - target)
            previous = current
        deviation = np.concatenate(deviations) if deviations else np.zeros(0)
        mean = math.fsum(deviation) / deviation.size if deviation.size else 0.0
        cp = specific_heat_at(self.inlet.cup_temperature, model.enthalpy.T0, model.enthalpy.dT, model.enthalpy.h)
        return {"entered": int(deviation.size), "entered_deviation_J_kg": mean, "entered_deviation_K": mean / cp}

    def start(self, model: ThermalModel, positions: np.ndarray) -> tuple[np.ndarray, Handed] | None:
        """The particles of the first frame (``positions`` (N, 3) m) with a finite position, and the
        initial field given to them, or None without an initial field."""
        if self.initial is None:
            return None
        placed = np.flatnonzero(np.all(np.isfinite(positions[:, :2]), axis=1))
        return placed, assign(self.initial, positions[placed, :2], model.radius, model.enthalpy)

    def reentering(self, model: ThermalModel, positions: np.ndarray) -> np.ndarray:
        """(M, 1 + K) J/kg: the inlet field's enthalpies (mean, then its nodes) at the re-entering
        particles' ``positions`` (M, 3) m; ``thermal.inlet_temperature``'s where a position is not
        finite. With an inlet plane: the field's mixing cup (the particles take the field where they
        cross the plane, :meth:`feed`)."""
        if self.plane is not None:
            T = np.broadcast_to(_cup(self.inlet), (positions.shape[0], self.inlet.temperature.shape[1])).copy()
        else:
            T = self.inlet.sample(positions[:, :2])
        T[~np.isfinite(T)] = model.inlet_temperature
        return model.enthalpy.enthalpy(T)

    def crossing(self, model: ThermalModel, previous: np.ndarray, positions: np.ndarray, schedule) -> tuple:
        """(indices, (M, 1 + K) J/kg): the particles crossing the inlet plane downwards between two
        frames' positions (N, 3) m and the inlet field's enthalpies at their positions where they crossed."""
        length = float(schedule.box_hi[2] - schedule.box_lo[2])
        down, _, xy = crossed(previous, positions, self.plane, length)
        T = self.inlet.sample(xy)
        T[~np.isfinite(T)] = model.inlet_temperature
        return down, model.enthalpy.enthalpy(T)

    def feed(self, model: ThermalModel, schedule, state, previous: np.ndarray, positions: np.ndarray) -> None:
        """Give the particles crossing the inlet plane since the ``previous`` frame the field at their
        position where they crossed (nothing without an inlet plane), booked in ``state.recycled_energy``."""
        if self.inlet is None or self.plane is None:
            return
        down, h = self.crossing(model, previous, positions, schedule)
        state.recycled_energy += model.mass * float(np.sum(h[:, 0] - state.h[down]))
        state.h[down] = h[:, 0]
        if state.shells is not None:
            state.shells[down] = node_enthalpies(model, h)


def _cup(field: Field) -> np.ndarray:
    """(1 + K,) K: the field's mixing-cup temperature of the particles' mean and of each node (the
    cells' weighted mean temperature for the nodes: they are given only where a plane feeds)."""
    nodes = field.temperature[:, 1:].T @ field.weight if field.shells else np.zeros(0)
    return np.concatenate([[field.cup_temperature], nodes])


def node_enthalpies(model: ThermalModel, enthalpy: np.ndarray) -> np.ndarray:
    """(M, n) J/kg of the model's nodes from a field's (M, 1 + K) enthalpies: the field's nodes
    where it has as many as the model, else every node at the particle's mean."""
    if enthalpy.shape[1] - 1 == model.shells.n:
        return enthalpy[:, 1:]
    return np.repeat(enthalpy[:, :1], model.shells.n, axis=1)
