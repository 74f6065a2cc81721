"""The reduced model of a long tube: a short periodic axial slice carried down it (``thermal.slice``).

In a tall tube the bed moves down as a plug (DPHT paper, Section 5: the Watkins tube), so the
particles between two heights at one time are those of one slice at another: a periodic slice driven
at the tube's plug-flow velocity v (:mod:`dpht.dem`, ``dem.drive``) sees, at time t, the wall of
the tube at the height it has reached, ``z = inlet_height - v t``. The thermal stage therefore
evaluates the walls' temperature expressions (of x, y, z) with that z on every element of the slice,
and resets no particle at the slice's periodic boundary (its particles are the same ones all the way
down). Axial conduction across the slice's ends is what the reduction leaves out; at the Watkins
Peclet number (v L / alpha of order 10^3 over a centimetre) it is negligible.

The DEM record of the slice is usually shorter than the residence time: its frames are reused
(:func:`cycled`), which assumes the slice's packing is statistically steady over the record. How
much that costs is measured by the Watkins reduction check (``workflow/rules/watkins.smk``) and by
the accuracy study's ``slice_record`` knob, which reuses only the start of a longer DEM record
(``thermal.slice.record``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dpht.defaults import setting
from dpht.errors import ConfigError

FRAME_REUSE = ("mirror", "wrap")
HEIGHT_SAMPLES = 513  # heights at which the wall temperatures are sampled for the scene's range


@dataclass(frozen=True)
class Slice:
    """A slice travelling down the tube (SI units): ``thermal.slice`` with dem.drive.velocity."""

    velocity: float  # m/s, downwards
    inlet_height: float  # m, z of the slice at t = 0
    distance: float  # m travelled by the end of the run
    frames: str  # how the DEM record is reused: "mirror" or "wrap"
    record: float | None = None  # s of the DEM record reused, from its start (None: all of it)

    @classmethod
    def of(cls, thermal: dict) -> Slice | None:
        """The slice of the thermal section (:func:`dpht.config.thermal_spec`), or None without one."""
        s = thermal.get("slice")
        if s is None:
            return None
        frames = setting(s, "thermal.slice.frames")
        if frames not in FRAME_REUSE:
            raise ConfigError(f"thermal.slice.frames = {frames!r}: expected one of {FRAME_REUSE}")
        velocity = s.get("velocity")
        if not isinstance(velocity, (int, float)) or not velocity > 0:
            raise ConfigError(f"thermal.slice needs dem.drive.velocity > 0 (m/s), got {velocity!r}")
        record = s.get("record")
        return cls(float(velocity), float(s["inlet_height"]), float(s["distance"]), frames,
                   None if record is None else float(record))  # fmt: skip

    @property
    def duration(self) -> float:
        """s to travel ``distance``."""
        return self.distance / self.velocity

    def height(self, t):
        """z (m) the slice has reached at time ``t`` (s) from its start."""
        return self.inlet_height - self.velocity * np.asarray(t, dtype=float)

    def heights(self) -> np.ndarray:
        """Heights (m) sampling the run's path, both ends included (for the range of wall temperatures)."""
        return self.height(np.linspace(0.0, self.duration, HEIGHT_SAMPLES))

    def recorded(self, times: np.ndarray) -> np.ndarray:
        """Mask of the DEM frames at ``times`` (s) within the record reused (from the first)."""
        times = np.asarray(times, dtype=float)
        if self.record is None:
            return np.ones(times.shape, dtype=bool)
        return times - times[0] <= self.record * (1 + 1e-9)

    def n_frames(self, interval: float) -> int:
        """Thermal frames at ``interval`` (s) apart from t = 0 until the slice has travelled ``distance``."""
        return math.ceil(self.duration / interval * (1 - 1e-12)) + 1


def cycled(n_record: int, n_frames: int, mode: str) -> np.ndarray:
    """Index into a record of ``n_record`` frames for each of ``n_frames`` thermal frames.

    "wrap": 0, 1, ..., n-1, 0, 1, ... (the positions jump back once per record); "mirror":
    0, 1, ..., n-1, n-2, ..., 1, 0, 1, ... (the record played backwards and forwards: positions
    never jump, and what the thermal stage reads of them, distances, is the same either way).
    """
    if n_record < 1:
        raise ConfigError("thermal.slice: the DEM record has no frame")
    k = np.arange(n_frames)
    if mode == "wrap" or n_record == 1:
        return k % n_record
    period = 2 * (n_record - 1)
    j = k % period
    return np.where(j < n_record, j, period - j)
