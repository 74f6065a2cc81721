"""The outputs users care about, of one thermal run, and their errors against a reference run.

Headline outputs (:func:`headline`), over the first ``record`` fraction of the run (1: all of it):

- total wall heat (J): ``/energy/wall`` of thermal.h5 at the record's last frame;
- wall heat by mode (J): the mean heat of each interval times its length, per PW mode;
- mean outlet (mixing-cup) temperature (K) over the steady window: the temperature of the mean
  specific enthalpy of the particles leaving through the outlet (crossing the periodic boundary
  downwards), taken at the start of the interval in which they cross (row k of thermal.h5 holds
  the state at the start of its own frame, after the resets of the particles that re-entered
  there, so the state at the crossing itself is not stored: this misses the last interval's
  heating, 0.0005 K of the default tube's 3.44 K outlet rise at its 0.01 s step);
- the radial temperature profile (K) in the band above the orifice (the figures' Fig. 12b), over
  the steady window;
- local particle temperatures (K) at the last time both runs share (:func:`local_rms`).

A shorter DEM record (the ``record_length`` knob) is compared by its steady-window wall heat rate
(W) instead of the total, which grows with the run's length.

Errors (:func:`errors`) are relative: wall heat to the reference's total (so a small mode's error
is its share of the total's), the outlet temperature to the reference's outlet rise above the inlet
(a 1 K change of an outlet at 1000 K is 0.1% of its temperature but may be 10% of its heating), the
radial profile and the local temperatures as RMS differences over the RMS of the reference's
rise above the inlet (of its bins, of its particles).

The Watkins slice (:func:`slice_headline`, :func:`slice_errors`) has the Watkins figures' outputs
(:mod:`dpht.figures.watkins`): the mean particle temperature rise at 0.645 m (K, relative error),
the wall heat (W) the tube receives over the slice's whole path and by PW mode (relative to the
total, as above), the split of the wall heat by mode overall and at 0.645 m (%; its error is
absolute, the largest difference of a mode's share: 0.01 is one percentage point), and the local
particle temperatures at the end (:func:`local_rms`).
"""

from __future__ import annotations

import math

import h5py
import numpy as np

from dpht.figures import watkins
from dpht.figures.outlet import leaving_temperatures, mixing_cup
from dpht.figures.scene import profile_sums
from dpht.figures.windows import window_frames, window_intervals

# Outputs the recommended defaults are judged on (the headline ones; profiles and local temperatures
# are reported beside them, but one particle's temperature is not what a default should be tuned for).
HEADLINE = ("wall_heat", "wall_heat_by_mode", "outlet_temperature")
SLICE_HEADLINE = ("rise", "wall_heat", "wall_heat_by_mode", "split_overall", "split_at_measurement")


def _record_rows(time: np.ndarray, record: float) -> int:
    """Rows of the first ``record`` fraction of a run."""
    end = time[0] + record * (time[-1] - time[0]) * (1 + 1e-9)
    return int(np.count_nonzero(time <= end))


def headline(thermal_h5, positions_h5, *, window, radial_band, specific_heat, inlet_temperature: float,
             record: float = 1.0) -> dict:
    """Headline outputs (module docstring) of one run; ``window`` is the steady window (fractions of
    the record), ``radial_band`` (z_low, z_high) m, ``specific_heat`` the config's value."""
    with h5py.File(thermal_h5, "r") as f:
        time = f["time"][...]
        rows = _record_rows(time, record)
        wall_energy = float(f["energy/wall"][rows - 1])
        dt = np.diff(time[:rows])
        by_mode = (f["wall_heat"][: rows - 1] * dt[:, None]).sum(axis=0)
        modes = [m.decode() if isinstance(m, bytes) else str(m) for m in f.attrs["wall_modes"]]
        steady = (window[0] * record, window[1] * record)
        frames = window_frames(time[:rows], steady)
        intervals, lengths = window_intervals(time[:rows], steady)
        steady_heat = (f["wall_heat"][intervals[0]:intervals[-1] + 1] * lengths[:, None]).sum(axis=0) / lengths.sum()
    leaving = leaving_temperatures(thermal_h5, positions_h5, frames)
    outlet = mixing_cup(leaving, specific_heat) if leaving.size else math.nan
    _, _, _, _, radial, _ = profile_sums(positions_h5, thermal_h5, steady, radial_band=radial_band)
    with np.errstate(invalid="ignore", divide="ignore"):
        profile = radial[2] / radial[0]
    return {
        "wall_heat_J": wall_energy,
        "wall_heat_by_mode_J": dict(zip(modes, by_mode.tolist())),
        "steady_wall_heat_W": float(steady_heat.sum()),
        "steady_wall_heat_by_mode_W": dict(zip(modes, steady_heat.tolist())),
        "outlet_temperature_K": outlet,
        "outlet_particles": int(leaving.size),
        "inlet_temperature_K": float(inlet_temperature),
        "radial_profile_K": profile.tolist(),
        "time_s": float(time[rows - 1] - time[0]),
    }


def common_rows(thermal_a, thermal_b) -> tuple[int, int]:
    """Rows of the last time both runs hold a state at (row k: the state at the start of its own
    frame, ``time[k]``; times equal to a millionth of the shorter step). Runs over one DEM run at
    different strides share the times of their coarser one."""
    with h5py.File(thermal_a, "r") as fa, h5py.File(thermal_b, "r") as fb:
        ta, tb = fa["time"][...], fb["time"][...]
    tolerance = 1e-6 * min(np.diff(ta).min(), np.diff(tb).min())  # every run has two frames or more
    j = np.clip(np.searchsorted(tb, ta), 1, tb.size - 1)
    j = np.where(np.abs(tb[j - 1] - ta) < np.abs(tb[j] - ta), j - 1, j)  # the nearest of b's times
    common = np.flatnonzero(np.abs(tb[j] - ta) <= tolerance)
    if not common.size:
        raise ValueError(f"{thermal_a} and {thermal_b} share no time")
    return int(common[-1]), int(j[common[-1]])


def relative_rms(values, reference, inlet_temperature: float) -> float:
    """RMS of ``values`` - ``reference`` over the RMS of the reference's rise above the inlet (K/K),
    where both are finite (NaN if they never are)."""
    a, b = np.asarray(values, float), np.asarray(reference, float)
    both = np.isfinite(a) & np.isfinite(b)
    if not both.any():
        return math.nan
    return float(np.sqrt(np.mean((a[both] - b[both]) ** 2) / np.mean((b[both] - inlet_temperature) ** 2)))


def local_rms(thermal_h5, reference_h5, inlet_temperature: float) -> float:
    """:func:`relative_rms` of the particle temperatures at the last time the runs share
    (:func:`common_rows`). Both runs must follow the same DEM run (the same particles)."""
    row, reference_row = common_rows(thermal_h5, reference_h5)
    with h5py.File(thermal_h5, "r") as fa, h5py.File(reference_h5, "r") as fb:
        return relative_rms(fa["temperature"][row], fb["temperature"][reference_row], inlet_temperature)


def _heat_errors(total: float, by_mode: dict, reference_total: float, reference_by_mode: dict) -> dict:
    """Errors of a wall heat and its modes, relative to the reference's total."""
    modes = {m: (by_mode[m] - v) / abs(reference_total) for m, v in reference_by_mode.items()}
    return {"wall_heat": (total - reference_total) / abs(reference_total),
            "wall_heat_by_mode": max(modes.values(), key=abs), **{f"wall_heat_{m}": v for m, v in modes.items()}}  # fmt: skip


def errors(run: dict, reference: dict, local: float | None = None, steady: bool = False) -> dict:
    """Relative errors (module docstring) of :func:`headline` outputs ``run`` against ``reference``;
    ``local`` the :func:`local_rms` of the pair (None when their particles do not follow one DEM run).
    ``steady``: compare the wall heat rates of the steady windows, not the totals (runs of
    different lengths)."""
    heat, modes = ("steady_wall_heat_W", "steady_wall_heat_by_mode_W") if steady else ("wall_heat_J", "wall_heat_by_mode_J")
    rise = reference["outlet_temperature_K"] - reference["inlet_temperature_K"]
    a, b = run["radial_profile_K"], reference["radial_profile_K"]
    return {
        **_heat_errors(run[heat], run[modes], reference[heat], reference[modes]),
        "outlet_temperature": (run["outlet_temperature_K"] - reference["outlet_temperature_K"]) / rise,
        "radial_profile": relative_rms(a, b, reference["inlet_temperature_K"]) if len(a) == len(b) else math.nan,
        "local_rms": math.nan if local is None else local,
    }


def slice_headline(positions_h5, thermal_h5, walls_h5) -> dict:
    """Outputs of a Watkins slice run (module docstring), as the Watkins figures compute them."""
    s = watkins.slice_profile(positions_h5, thermal_h5, walls_h5)
    heat = watkins.slice_tube_heat(s, 0.0, s["path"])
    overall, at = watkins.splits(s)
    return {"rise_K": watkins.rise_at(s), "wall_heat_W": float(heat.sum()),
            "wall_heat_by_mode_W": dict(zip(s["modes"], heat.tolist())),
            "wall_heat_J": float((s["heat"] * s["dt"][:, None]).sum()),  # into the slice over its run
            "split_overall_percent": overall, "split_at_measurement_percent": at,
            "inlet_temperature_K": s["inlet_temperature"], "particles": s["particles"], "time_s": float(s["dt"].sum())}  # fmt: skip


def slice_errors(run: dict, reference: dict, local: float | None = None) -> dict:
    """Errors (module docstring) of :func:`slice_headline` outputs ``run`` against ``reference``:
    relative, but the splits' (absolute differences of the modes' shares); ``local`` as in
    :func:`errors`."""
    split = {name: max((run[f"{name}_percent"][m] - v for m, v in reference[f"{name}_percent"].items()), key=abs) / 100.0
             for name in ("split_overall", "split_at_measurement")}  # fmt: skip
    return {"rise": (run["rise_K"] - reference["rise_K"]) / reference["rise_K"],
            **_heat_errors(run["wall_heat_W"], run["wall_heat_by_mode_W"], reference["wall_heat_W"], reference["wall_heat_by_mode_W"]),
            **split, "local_rms": math.nan if local is None else local}  # fmt: skip


def worst(errors_: dict, names=HEADLINE) -> float:
    """The largest magnitude of the named relative errors."""
    return max(abs(errors_[n]) for n in names)
