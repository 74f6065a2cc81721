"""Time windows of a run: fractions of it, ``(0.5, 1.0)`` = the second half (the steady state).

A window ``(a, b)`` holds the frames with ``t0 + a (t_end - t0) <= t <= t0 + b (t_end - t0)`` and
the intervals (frame k to k + 1) lying wholly inside it. Kept apart from the figures so that the
workflow's pre-flight check can use it without loading matplotlib.
"""

from __future__ import annotations

import numpy as np

from dpht.errors import DPHTError


def check_window(window) -> tuple[float, float]:
    """``window`` as (start, end) fractions of the run, checked: 0 <= start < end <= 1."""
    try:
        a, b = (float(w) for w in window)
    except (TypeError, ValueError):
        raise DPHTError(f"window must be (start, end) fractions of the run, got {window!r}") from None
    if not 0.0 <= a < b <= 1.0:
        raise DPHTError(f"window must satisfy 0 <= start < end <= 1 (fractions of the run), got {window!r}")
    return a, b


def _window_bounds(time: np.ndarray, window) -> tuple[float, float]:
    """Start and end time [s] of ``window``, widened by round-off so that boundary frames stay in."""
    a, b = check_window(window)
    t0, t1 = float(time[0]), float(time[-1])
    slack = 1e-9 * (t1 - t0)
    return t0 + a * (t1 - t0) - slack, t0 + b * (t1 - t0) + slack


def window_frames(time: np.ndarray, window) -> np.ndarray:
    """Indices of the frames inside ``window`` (fractions of the run)."""
    lo, hi = _window_bounds(time, window)
    frames = np.flatnonzero((time >= lo) & (time <= hi))
    if frames.size == 0:
        raise DPHTError(f"window {tuple(window)} contains no frame")
    return frames


def window_intervals(time: np.ndarray, window) -> tuple[np.ndarray, np.ndarray]:
    """Intervals ``k`` (frame k to k+1) wholly inside ``window`` and their durations [s]."""
    lo, hi = _window_bounds(time, window)
    k = np.flatnonzero((time[:-1] >= lo) & (time[1:] <= hi))
    if k.size == 0:
        raise DPHTError(f"window {tuple(window)} contains no whole interval between frames")
    dt = time[k + 1] - time[k]
    if np.any(dt <= 0):
        raise DPHTError("frame times must increase")
    return k, dt
