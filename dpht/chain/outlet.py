"""The outlet record of a segment of a chain (docs/theory/chain.md): what left its thermal run, in
float64, the group ``outlet`` of its thermal.h5 (written by the thermal stage,
:mod:`dpht.thermal.outlet`).

thermal.h5 keeps float32 temperature rows, which would hand the energy over to 1e-7 only; this
record holds the run's own enthalpies converted to temperatures in float64.

- ``kind = "crossings"`` (a resolved segment): every particle crossing the outlet plane z = ``plane``
  downwards between two frames, with its cross-section position where it crossed (linear between the
  two frames) and its enthalpy then (the run's, at the start of the frame it is first seen below).
  A particle crossing back up and down again is counted again; ``upward`` counts the crossings up.
- ``kind = "bed"`` (a travelling slice): its particles at the end of the run, at their positions in
  the last frame (those without a finite position left out).

Layout: ``frame`` (M,) int64 thermal frame of the sample, ``time`` (M,) s, ``particle`` (M,) int64
index in the positions file, ``xy`` (M, 2) m, ``temperature`` (M,) K float64, ``shells`` (M, K) K
float64 (resolved particles, else K = 0) and ``shell_weight`` (K,); attributes ``kind``, ``radius``
(m), ``plane`` (m, NaN for a bed) and ``upward``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import h5py
import numpy as np

from dpht.errors import DPHTError

GROUP = "outlet"
CROSSINGS, BED = "crossings", "bed"
_DATASETS = ("frame", "time", "particle", "xy", "temperature", "shells", "shell_weight")


@dataclass(frozen=True)
class Outlet:
    """What a thermal run records as its outlet: the crossings of the plane z = ``plane`` (m), or with None
    its particles at the end."""

    plane: float | None = None

    def key(self) -> dict:
        """Its part of the run's fingerprint."""
        return {"outlet": "bed" if self.plane is None else float(self.plane)}


@dataclass(frozen=True)
class Record:
    """The group ``outlet`` of a thermal.h5 (module docstring), SI units."""

    kind: str
    frame: np.ndarray
    time: np.ndarray
    particle: np.ndarray
    xy: np.ndarray
    temperature: np.ndarray
    shells: np.ndarray
    shell_weight: np.ndarray
    radius: float
    plane: float = math.nan
    upward: int = 0

    def within(self, start: float, end: float) -> Record:
        """The samples of times in [start, end] s."""
        keep = (self.time >= start) & (self.time <= end)
        return Record(self.kind, self.frame[keep], self.time[keep], self.particle[keep], self.xy[keep],
                      self.temperature[keep], self.shells[keep], self.shell_weight, self.radius, self.plane,
                      self.upward)  # fmt: skip


def crossed(previous: np.ndarray, positions: np.ndarray, plane: float, length: float):
    """The particles crossing the plane z = ``plane`` between two frames' positions (N, 3) m: those
    going down (indices, and their cross-section positions where they crossed, linear between the
    frames) and those going up (indices; a jump up of more than half the periodic ``length`` m is a
    re-entry through the periodic boundary, no crossing)."""
    z0, z1 = previous[:, 2], positions[:, 2]
    with np.errstate(invalid="ignore"):
        down = np.flatnonzero((z0 >= plane) & (z1 < plane))
        up = np.flatnonzero((z0 < plane) & (z1 >= plane) & (z1 - z0 < 0.5 * length))
    f = ((z0[down] - plane) / (z0[down] - z1[down]))[:, None]
    return down, up, previous[down, :2] + f * (positions[down, :2] - previous[down, :2])


def write(file: h5py.File, record: Record) -> None:
    """Write ``record`` as the group ``outlet`` of an open thermal.h5."""
    group = file.create_group(GROUP)
    group.attrs.update(kind=record.kind, radius=record.radius, plane=record.plane, upward=record.upward)
    for name in _DATASETS:
        group.create_dataset(name, data=getattr(record, name))


def read(path) -> Record:
    """The outlet record of thermal.h5 ``path`` (DPHTError naming the file when it has none)."""
    with h5py.File(path, "r") as f:
        if GROUP not in f:
            raise DPHTError(f"{path}: no outlet record (group {GROUP!r}): the run was not asked for its outlet")
        g = f[GROUP]
        return Record(str(g.attrs["kind"]), radius=float(g.attrs["radius"]), plane=float(g.attrs["plane"]),
                      upward=int(g.attrs["upward"]), **{name: g[name][...] for name in _DATASETS})  # fmt: skip
