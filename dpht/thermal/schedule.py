"""The thermal frames of a run (:class:`Schedule`): the DEM frames the thermal stage takes, their
times and the box they move in.

Every ``thermal.frame_stride``-th frame of the positions file; for a travelling slice
(``thermal.slice``, :mod:`dpht.thermal.slice`) the frames of its record reused until it has
travelled its distance; for a frozen bed (``thermal.frozen_bed: {frame, duration, step}``) one DEM
frame held fixed for ``duration`` s in steps of ``step`` s (:meth:`Schedule.frozen_bed`,
:func:`frozen_times`), for static-bed studies (an effective conductivity, a bin's charging curve)
without a DEM flow run: every row refers to that DEM frame, nothing is recycled, and the thermal
stage prepares the frame's geometry once. The positions file may hold a DEM settle or flow run, or
a packing from :func:`dpht.radiation.packing.write_packed_bed`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dpht.defaults import setting
from dpht.dem.dumps import PositionsFile
from dpht.errors import ConfigError, DPHTError
from dpht.thermal.slice import Slice, cycled


def frozen_times(frozen: dict) -> np.ndarray:
    """Times (s, from 0) of a frozen bed's frames: ``duration`` s in steps of ``step`` s, the last
    step shortened to end on ``duration``."""
    duration, step = float(frozen["duration"]), float(frozen["step"])
    return np.minimum(step * np.arange(max(1, math.ceil(duration / step * (1 - 1e-12))) + 1), duration)


@dataclass(frozen=True)
class Schedule:
    """The DEM frames the stage takes and the box they move in, from the positions file."""

    frames: list  # DEM frame index of each thermal frame (every thermal.frame_stride-th)
    times: np.ndarray  # s, of those frames
    box_lo: np.ndarray  # m
    box_hi: np.ndarray  # m
    periodic: np.ndarray  # (3,) bool, periodic for heat: pairs across the box boundary exchange heat
    flow_axis: int | None  # the recycled axis (the tube's z): particles flow towards -z and re-enter at the top
    frozen: bool = False  # one DEM frame held fixed (thermal.frozen_bed)

    @classmethod
    def of(cls, dem: PositionsFile, stride: int, slice_: Slice | None = None) -> Schedule:
        """Every ``stride``-th frame of ``dem``. Its periodic axes are of two kinds, as the positions
        file says (attribute ``recycled``, :mod:`dpht.dem.dumps`; none without it): an axis the DEM
        only recycles particles across (the tube's inlet and outlet, where the real tube has a
        hopper above and an outlet below) is open for heat, and particles crossing it re-enter at
        the inlet temperature; the others are physically periodic and stay periodic for heat.

        For a travelling ``slice_`` (a driven DEM), those frames within its record reused
        (:func:`dpht.thermal.slice.cycled`) at their uniform interval from t = 0 until the slice has
        travelled its distance, every periodic axis periodic for heat and no flow axis (the slice's
        particles are the same all the way down: nothing is reset at the inlet)."""
        frames = list(range(0, dem.n_frames, stride))
        periodic = np.asarray(dem.attrs["periodic"], dtype=bool)
        recycled = np.asarray(dem.attrs.get("recycled", np.zeros(3, dtype=bool)), dtype=bool)
        if recycled.shape != (3,) or np.any(recycled & ~periodic) or recycled.sum() > 1:
            raise DPHTError(
                f"positions file {dem.path}: recycled axes {recycled.tolist()} must be one periodic axis at most "
                f"(periodic: {periodic.tolist()})"
            )
        box = np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"])
        if slice_ is None:
            return cls(frames, dem.times[frames], *box, periodic & ~recycled,
                       int(np.flatnonzero(recycled)[0]) if recycled.any() else None)  # fmt: skip
        span = float(dem.times[-1] - dem.times[0])
        if slice_.record is not None and slice_.record > span * (1 + 1e-9):
            raise DPHTError(f"thermal.slice.record = {slice_.record} s: the DEM record is only {span:.6g} s long")
        frames = [f for f, kept in zip(frames, slice_.recorded(dem.times[frames])) if kept]
        if len(frames) < 2:
            raise DPHTError(f"thermal.slice: the DEM record has {len(frames)} frame(s) at thermal.frame_stride {stride}; "
                            "it needs two to give the thermal step")
        steps = np.diff(dem.times[frames])
        if not np.allclose(steps, steps[0], rtol=1e-9):
            raise DPHTError("thermal.slice: the DEM frames are not evenly spaced in time, so they cannot be reused")
        n = slice_.n_frames(float(steps[0]))
        reused = [frames[i] for i in cycled(len(frames), n, slice_.frames)]
        return cls(reused, steps[0] * np.arange(n), *box, periodic, None)

    @classmethod
    def of_spec(cls, dem: PositionsFile, thermal: dict) -> Schedule:
        """The schedule the thermal config section asks for: a frozen bed, a travelling slice, or
        every frame_stride-th frame."""
        frozen = thermal.get("frozen_bed")
        return cls.frozen_bed(dem, frozen) if frozen else cls.of(dem, thermal["frame_stride"], Slice.of(thermal))

    @classmethod
    def frozen_bed(cls, dem: PositionsFile, frozen: dict) -> Schedule:
        """DEM frame ``frozen["frame"]`` (negative: from the end) for ``duration`` s in steps of
        ``step`` s (the last step shortened to end on ``duration``); times from 0."""
        frame = int(setting(frozen, "thermal.frozen_bed.frame"))
        if not -dem.n_frames <= frame < dem.n_frames:
            raise ConfigError(f"thermal.frozen_bed.frame: {frame} is not a frame of the positions file ({dem.n_frames} frames)")
        times = frozen_times(frozen)
        axes = cls.of(dem, dem.n_frames)  # periodic for heat as in a flowing run; nothing is recycled
        return cls([frame % dem.n_frames] * times.size, times, axes.box_lo, axes.box_hi, axes.periodic, None, frozen=True)

    def interval(self, count: int) -> float:
        """Length (s) of the interval from thermal frame ``count`` to the next; 0 after the last."""
        return float(self.times[count + 1] - self.times[count]) if count + 1 < len(self.frames) else 0.0
