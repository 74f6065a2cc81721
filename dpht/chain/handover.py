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
takes it over the same stretch. Its profile along the tube (:func:`slice_profile`,
:func:`resolved_profile`) splits that heat into bins of the scene's z about a particle diameter long:
a resolved segment's wall elements by their centroids, a slice's heat by the height it had reached
when it took it.
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
    steady window of a resolved segment's run (fractions), the chain's ``mass_flow`` (kg/s), a
    particle's ``mass`` (kg) and the length (m) of the bins of the wall heat profile."""

    rings: int
    sectors: int
    radius: float
    window: tuple[float, float]
    mass_flow: float
    mass: float
    bin: float


@dataclass(frozen=True)
class Place:
    """Where a segment sits: its ends (m, the scene's z) and, resolved, its bottom in its DEM
    (``plane``, m; None for a slice, which starts at ``top`` and travels at ``velocity`` m/s)."""

    bottom: float
    top: float
    plane: float | None = None
    velocity: float | None = None

    def edges(self, length: float) -> np.ndarray:
        """m, the edges of its profile's bins, equal, about ``length`` long, top first."""
        n = max(1, round((self.top - self.bottom) / length))
        return np.linspace(self.top, self.bottom, n + 1)


def slice_profile(place: Place, rows: Rows, scale: float, edges: np.ndarray) -> np.ndarray:
    """W per bin of ``edges`` (top first) of a slice: the heat of each interval between its frames
    (``rows``) spread evenly over the heights it travelled then, times ``scale`` (the chain's mass
    flow over the slice's mass); what it took past its stretch's bottom (less than a thermal step
    of travel) counts in the lowest bin."""
    t = rows.time
    heat = rows.wall_heat[:-1].sum(axis=1) * np.diff(t)  # J per interval
    upper, lower = place.top - place.velocity * t[:-1], place.top - place.velocity * t[1:]
    lower = np.maximum(lower, edges[-1])
    upper = np.maximum(upper, lower)
    out = np.zeros(edges.size - 1)
    for b in range(out.size):
        overlap = np.clip(np.minimum(upper, edges[b]) - np.maximum(lower, edges[b + 1]), 0.0, None)
        span = upper - lower
        share = np.divide(overlap, span, out=np.zeros_like(span), where=span > 0)
        if b == out.size - 1:
            share = np.where(span > 0, share, 1.0)  # the steps wholly past the bottom
        out[b] = math.fsum(heat * share)
    return scale * out


def resolved_profile(place: Place, element_heat: np.ndarray, centroid_z: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """W per bin of ``edges`` (top first) of a resolved segment: each wall element's mean heat over
    the window (``element_heat`` (M,) W) in the bin of its centroid (``centroid_z`` (M,) m in the
    DEM, moved to the scene's z); elements beyond the stretch (its DEM's run-out and head, adiabatic)
    in the nearest end bin."""
    z = centroid_z - place.plane + place.bottom
    bins = np.clip(np.searchsorted(-edges, -z, side="right") - 1, 0, edges.size - 2)
    return np.bincount(bins, weights=element_heat, minlength=edges.size - 1)


def stream(record: Record) -> Stream:
    """The samples of ``record`` as a :class:`Stream` (flux factor 1 each)."""
    n = record.temperature.size
    if n == 0:
        raise DPHTError("hand-over: no particle left the segment (no crossing of its outlet plane in its steady window): "
                        "its DEM run jammed or did not flow (see its summary.json: jammed, mass_flow_kg_s)")
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
    edges: np.ndarray  # m, the profile's bins, top first
    profile: np.ndarray  # W per bin

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
                "steady": self.steady, "profile_edges_m": self.edges.tolist(), "profile_W": self.profile.tolist()}  # fmt: skip


def hand_over(record: Record, rows: Rows, spec: Spec, table: EnthalpyTable, place: Place,
              centroid_z: np.ndarray | None = None) -> HandOver:  # fmt: skip
    """The hand-over of a segment at ``place`` whose thermal run left ``record`` and wrote ``rows``
    (a resolved segment's: with its wall elements' centroids' z, m in its DEM)."""
    grid = CrossSection(spec.rings, spec.sectors, spec.radius)
    edges = place.edges(spec.bin)
    if record.kind == BED:
        field = build(stream(record), grid, table)
        scale = spec.mass_flow / (record.temperature.size * spec.mass)
        return HandOver(field, record.kind, record.temperature.size, (float(rows.time[0]), float(rows.time[-1])),
                        record.upward, None, scale * rows.wall_energy[-1], None, edges,
                        slice_profile(place, rows, scale, edges))  # fmt: skip
    start, end = window_of(rows.time, spec.window)
    inside = record.within(start, end)
    field = build(stream(inside), grid, table)
    middle = 0.5 * (start + end)
    halves = tuple(cup_temperature(half, table) if half.temperature.size else math.nan
                   for half in (inside.within(start, middle), inside.within(middle, end)))  # fmt: skip
    heat = rows.wall_heat.sum(axis=1)
    frames = [(rows.time >= a) & (rows.time <= b) for a, b in ((start, end), (start, middle), (middle, end))]
    mean = [float(heat[f].mean()) if f.any() else math.nan for f in frames]
    elements = rows.element_heat(frames[0])
    return HandOver(field, record.kind, inside.temperature.size, (start, end), record.upward, halves, mean[0],
                    (mean[1], mean[2]), edges, resolved_profile(place, elements, centroid_z, edges))  # fmt: skip


@dataclass(frozen=True)
class Rows:
    """What the hand-over reads of a thermal.h5: frame ``time`` (F,) s, ``wall_heat`` (F, P) W,
    ``wall_energy`` (F,) J and the file, whose per-element heat it reads for a window."""

    time: np.ndarray
    wall_heat: np.ndarray
    wall_energy: np.ndarray
    path: str | None = None

    @classmethod
    def read(cls, path) -> Rows:
        with h5py.File(path, "r") as f:
            return cls(f["time"][...], f["wall_heat"][...], f["energy/wall"][...], str(path))

    def element_heat(self, frames: np.ndarray) -> np.ndarray:
        """(M,) W: each wall element's heat, all modes, averaged over the frames of mask ``frames``
        (read one frame at a time, in float64)."""
        with h5py.File(self.path, "r") as f:
            data = f["element_heat"]
            total = np.zeros(data.shape[1])
            for k in np.flatnonzero(frames):
                total += data[k].astype(np.float64).sum(axis=1)
        return total / max(int(np.count_nonzero(frames)), 1)
