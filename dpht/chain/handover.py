"""A segment's hand-over (docs/theory/chain.md): what left it (its thermal run's outlet record,
:mod:`dpht.chain.outlet`) mapped on the cross-section as the next segment's field
(:mod:`dpht.chain.field`), and the numbers the chain's summary adds up.

A resolved segment hands over the particles that crossed its outlet plane within its steady window
(``figures.steady_window``, fractions of its run), each counted once per crossing (flux factor 1);
whether that window is steady is measured by its two halves (their mixing-cup temperatures and
mean wall heat). A travelling slice hands over its particles at the end of its stretch; they move
as a plug at one velocity, so each carries the same flux (factor 1).

Its wall heat in the chain's terms (W at the chain's mass flow m): a resolved segment's is its mean
wall heat over the window (its DEM runs at that flow); a slice's is m times the heat the slice took
from the wall per kilogram of its particles over its stretch, as each kilogram of the tube's flow
takes it over the same stretch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import h5py
import numpy as np

from dpht.chain.field import CrossSection, Field, Stream, build
from dpht.closures.heat_capacity import EnthalpyTable
from dpht.errors import DPHTError
from dpht.chain.outlet import BED, Record

STEADY_DRIFT = 0.05  # largest change of a resolved segment's mean wall heat between the halves of its window called steady


@dataclass(frozen=True)
class Spec:
    """A segment's hand-over: its field's grid (``rings``, ``sectors``, the tube's ``radius`` m), the
    steady window of a resolved segment's run (fractions), the chain's ``mass_flow`` (kg/s) and a
    particle's ``mass`` (kg)."""

    rings: int
    sectors: int
    radius: float
    window: tuple[float, float]
    mass_flow: float
    mass: float


def stream(record: Record) -> Stream:
    """The samples of ``record`` as a :class:`Stream` (flux factor 1 each)."""
    n = record.temperature.size
    if n == 0:
        raise DPHTError("hand-over: no particle left the segment (no crossing of its outlet plane in the window)")
    shells = record.shells if record.shells.shape[1] else None
    return Stream(record.xy, record.temperature, np.full(n, record.radius), None, shells,
                  record.shell_weight if shells is not None else None)  # fmt: skip


def window_of(times: np.ndarray, window) -> tuple[float, float]:
    """The steady window (s) of a run whose frames are at ``times`` (s), ``window`` in fractions of it."""
    t0, t1 = float(times[0]), float(times[-1])
    return t0 + window[0] * (t1 - t0), t0 + window[1] * (t1 - t0)


def cup_temperature(record: Record, table: EnthalpyTable) -> float:
    """The mixing-cup temperature (K) of ``record``'s samples (equal radii and flux: the mean enthalpy)."""
    h = table.enthalpy(record.temperature)
    return float(table.temperature(math.fsum(h) / h.size))


@dataclass(frozen=True)
class HandOver:
    """What a segment hands on: the ``field``, and its books (:meth:`summary`)."""

    field: Field
    kind: str
    samples: int
    window: tuple[float, float]  # s
    upward: int
    halves: tuple[float, float] | None  # K, mixing-cup temperatures of the window's halves (crossings)
    wall_heat: float  # W at the chain's mass flow
    wall_heat_halves: tuple[float, float] | None  # W, a resolved segment's mean over the window's halves

    @property
    def steady(self) -> bool | None:
        """Whether a resolved segment's wall heat changed by at most STEADY_DRIFT across its window."""
        if self.wall_heat_halves is None:
            return None
        a, b = self.wall_heat_halves
        return abs(b - a) <= STEADY_DRIFT * max(abs(a), abs(b), 1e-300)

    def summary(self) -> dict:
        return {"kind": self.kind, "samples": self.samples, "window_s": list(self.window), "upward_crossings": self.upward,
                "cup_temperature_K": self.field.cup_temperature, "filled_cells": self.field.filled,
                "cup_temperature_halves_K": None if self.halves is None else list(self.halves),
                "wall_heat_W": self.wall_heat,
                "wall_heat_halves_W": None if self.wall_heat_halves is None else list(self.wall_heat_halves),
                "steady": self.steady}  # fmt: skip


def hand_over(record: Record, rows: Rows, spec: Spec, table: EnthalpyTable) -> HandOver:
    """The hand-over of a segment whose thermal run left ``record`` and wrote ``rows``."""
    grid = CrossSection(spec.rings, spec.sectors, spec.radius)
    if record.kind == BED:
        field = build(stream(record), grid, table)
        wall_heat = spec.mass_flow * rows.wall_energy[-1] / (record.temperature.size * spec.mass)
        return HandOver(field, record.kind, record.temperature.size, (float(rows.time[0]), float(rows.time[-1])),
                        record.upward, None, wall_heat, None)  # fmt: skip
    start, end = window_of(rows.time, spec.window)
    inside = record.within(start, end)
    field = build(stream(inside), grid, table)
    middle = 0.5 * (start + end)
    halves = tuple(cup_temperature(half, table) if half.temperature.size else math.nan
                   for half in (inside.within(start, middle), inside.within(middle, end)))  # fmt: skip
    heat = rows.wall_heat.sum(axis=1)
    frames = [(rows.time >= a) & (rows.time <= b) for a, b in ((start, end), (start, middle), (middle, end))]
    mean = [float(heat[f].mean()) if f.any() else math.nan for f in frames]
    return HandOver(field, record.kind, inside.temperature.size, (start, end), record.upward, halves, mean[0],
                    (mean[1], mean[2]))  # fmt: skip


@dataclass(frozen=True)
class Rows:
    """What the hand-over reads of a thermal.h5: frame ``time`` (F,) s, ``wall_heat`` (F, P) W and
    ``wall_energy`` (F,) J."""

    time: np.ndarray
    wall_heat: np.ndarray
    wall_energy: np.ndarray

    @classmethod
    def read(cls, path) -> Rows:
        with h5py.File(path, "r") as f:
            return cls(f["time"][...], f["wall_heat"][...], f["energy/wall"][...])
