"""The Watkins validation (DPHT paper, Section 5, Figs. 11-13) from a travelling slice, and the check
of that reduction against a full tube.

A slice run (``thermal.slice``, :mod:`dpht.thermal.slice`) is read as the steady tube it stands for:
thermal frame k at time t_k is the tube at distance ``v t_k`` from the inlet. Its heat rates are the
interval means from frame k to k + 1, placed at the interval's middle. The tube's wall heat per unit
time over a stretch of its length equals the slice's energy gained there per metre of slice times v
(steady plug flow carries one slice length of bed past a point in L/v).

Each function writes a PNG and the plotted numbers as CSV next to it (SI units, K; the figures show
deg C as the paper does) and returns a dict of its headline numbers.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from dpht.dem import dumps
from dpht.errors import DPHTError
from dpht.figures import scene
from dpht.figures.scene import KELVIN_OFFSET, STEADY, _bin_index, _bin_sums, _divide, _edges, _open, _run_spec, _save, _write_csv
from dpht.figures.windows import window_frames, window_intervals
from dpht.thermal.model import wall_temperatures
from dpht.thermal.modes import LABELS as MODE_LABELS
from dpht.thermal.slice import Slice
from dpht.geometry.walls import load_walls

# Published numbers (DPHT paper, Section 5, and Watkins, 2018, Configuration 6).
MEASURED_RISE_K = 570.0  # mean temperature rise inlet -> 0.645 m, experiment
PAPER_RISE_K = 547.0  # the same, DPHT
MEASUREMENT_DISTANCE = 0.645  # m from the inlet
PAPER_SPLIT_OVERALL = {"pfw": 85.6, "pw_contact": 8.5, "pw_radiation": 5.9}  # % of the wall heat
PAPER_SPLIT_AT_MEASUREMENT = {"pfw": 82.5, "pw_contact": 7.2, "pw_radiation": 10.3}
PROFILE_FRAMES = 400  # frames sampled for the radial profiles along the tube (Fig. 12a)


def _dirichlet(walls, spec: dict) -> np.ndarray:
    """Mask of the wall elements with a temperature condition."""
    return np.isfinite(wall_temperatures(walls, spec["thermal"]["walls"]))


def slice_profile(positions_h5, thermal_h5, walls_h5) -> dict:
    """The tube a slice run stands for, along its distance from the inlet (m).

    Per frame: ``distance`` (the last frame may lie past the slice's ``path``, m), ``temperature`` (mean particle temperature, K; equal masses, so also
    the mixing-cup temperature of plug flow), ``wall_temperature`` (K, mean over the heated
    elements at the slice's height). Per interval (placed at its middle): ``distance_mid``, ``heat``
    (W into the slice per PW mode), ``flux`` (W/m^2 per mode), ``dt`` (s). Also the slice's
    ``length`` (m, its DEM box: a slice loaded to a wall stress is shorter than its tube,
    dem.drive.wall_stress), ``velocity`` (m/s), ``particles``, ``mass`` (kg) and ``modes``.
    """
    walls = load_walls(walls_h5)
    with _open(positions_h5, "positions") as fp:
        length = dumps.axial_length(fp.attrs)
    with _open(thermal_h5, "thermal") as f:
        spec = _run_spec(f, thermal_h5)
        slice_ = Slice.of(spec["thermal"])
        if slice_ is None:
            raise DPHTError(f"{thermal_h5}: not a slice run (its spec has no thermal.slice)")
        time = f["time"][...]
        temperature = np.array([np.nanmean(f["temperature"][k].astype(np.float64)) for k in range(time.size)])
        heat = f["wall_heat"][...]
        n = f["ids"].shape[0]
        modes = [str(m) for m in np.atleast_1d(f.attrs["wall_modes"]).astype(str)]
        enabled = set(json.loads(f.attrs["modes"]))
    heated = _dirichlet(walls, spec)
    # The heated wall's area over the box: the wall mesh spans the tube's configured length.
    area = float(walls.area[heated].sum()) * length / float(np.ptp(walls.vertices[heated][..., 2]))
    wall_T = np.array([np.nanmean(wall_temperatures(walls, spec["thermal"]["walls"], z=float(z))[heated])
                       for z in slice_.height(time)])  # fmt: skip
    dt = np.diff(time)
    mid = time[:-1] + 0.5 * dt
    p = spec["particles"]
    mass = n * p["density"] * math.pi * p["diameter"] ** 3 / 6.0
    return {
        "distance": slice_.velocity * time, "temperature": temperature, "wall_temperature": wall_T,
        "distance_mid": slice_.velocity * mid, "heat": heat[:-1], "flux": heat[:-1] / area, "dt": dt,
        "length": length, "area": area, "velocity": slice_.velocity, "inlet_height": slice_.inlet_height,
        "path": slice_.distance,
        "particles": n, "mass": mass, "modes": modes, "enabled": [m for m in modes if m in enabled],
        "inlet_temperature": spec["thermal"]["inlet_temperature"],
    }  # fmt: skip


def slice_tube_heat(profile: dict, low: float, high: float) -> np.ndarray:
    """W per PW mode the tube receives between ``low`` and ``high`` m from the inlet: the slice's
    energy gained over that stretch per metre of slice, times its velocity."""
    inside = (profile["distance_mid"] >= low) & (profile["distance_mid"] <= high)
    energy = (profile["heat"][inside] * profile["dt"][inside, None]).sum(axis=0)  # J per mode
    return energy * profile["velocity"] / profile["length"]


def _at(profile: dict, key: str, distance: float, where: str = "distance"):
    return np.interp(distance, profile[where], profile[key]) if np.ndim(profile[key]) == 1 else np.array(
        [np.interp(distance, profile[where], column) for column in profile[key].T])  # fmt: skip


def _split(heat: np.ndarray, modes) -> dict:
    total = heat.sum()
    return {m: 100.0 * float(h) / total if total else math.nan for m, h in zip(modes, heat)}


def rise_at(profile: dict, distance: float = MEASUREMENT_DISTANCE) -> float:
    """Mean particle temperature rise (K) above the inlet at ``distance`` m from it (Fig. 11)."""
    return float(_at(profile, "temperature", distance)) - profile["inlet_temperature"]


def splits(profile: dict, distance: float = MEASUREMENT_DISTANCE) -> tuple[dict, dict]:
    """The wall heat's split by PW mode (% of the total): over the slice's whole path, and of the
    local flux at ``distance`` m from the inlet (Fig. 13)."""
    overall = _split(slice_tube_heat(profile, 0.0, profile["path"]), profile["modes"])
    return overall, _split(_at(profile, "flux", distance, "distance_mid"), profile["modes"])


# ------------------------------------------------------------------------ the reduction check


def full_tube_profile(positions_h5, thermal_h5, walls_h5, window, z_edges) -> dict:
    """Steady state of a full-tube run over ``window``: mean particle temperature (K) per z bin of
    ``z_edges`` (m) and the wall heat (W) per PW mode of the heated elements whose centroids lie in
    each bin; also the mean axial particle velocity (m/s, downwards) in the bins' range."""
    walls = load_walls(walls_h5)
    with _open(positions_h5, "positions") as fp, _open(thermal_h5, "thermal") as ft:
        spec = _run_spec(ft, thermal_h5)
        frames = ft["dem_frame"][...] if "dem_frame" in ft else np.arange(ft["time"].shape[0])
        sums = np.zeros((2, z_edges.size - 1))
        for k in window_frames(ft["time"][...], window):
            z = fp["positions"][frames[k]][:, 2].astype(np.float64)
            T = ft["temperature"][k].astype(np.float64)
            alive = np.isfinite(T) & np.isfinite(z)
            sums += _bin_sums(_bin_index(z[alive], z_edges), z_edges.size - 1, np.ones(alive.sum()), T[alive])
        k, dt = window_intervals(ft["time"][...], window)
        element_heat = scene._stream_mean(ft["element_heat"], k, dt)
        velocity = _axial_velocity(fp, frames[window_frames(ft["time"][...], window)], z_edges[0], z_edges[-1])
    heated = _dirichlet(walls, spec)
    index = _bin_index(walls.centroid[:, 2], z_edges)
    index[~heated] = -1
    heat = np.column_stack(_bin_sums(index, z_edges.size - 1, *element_heat.T))
    return {"z_edges": z_edges, "temperature": _divide(sums[1], sums[0]), "samples": sums[0], "heat": heat,
            "velocity": velocity, "inlet_temperature": spec["thermal"]["inlet_temperature"]}  # fmt: skip


def _axial_velocity(fp, frames, z_low: float, z_high: float) -> float:
    """Mean downward velocity (m/s) of the particles between ``z_low`` and ``z_high`` over ``frames``
    (unwrapped displacement between consecutive frames, from the image flags)."""
    box = dumps.axial_length(fp.attrs)
    time = fp["time"][...]
    speeds = []
    for a, b in zip(frames[:-1], frames[1:]):
        za = fp["positions"][a][:, 2]
        drop = -dumps.axial_step(za, fp["positions"][b][:, 2], fp["image"][a], fp["image"][b], box)
        inside = (za >= z_low) & (za <= z_high) & np.isfinite(drop)
        speeds.append(np.mean(drop[inside]) / (time[b] - time[a]))
    return float(np.mean(speeds))


def reduction_check(full: tuple, slice_: tuple, png, *, window=STEADY, bin_diameters: float = 4.0) -> dict:
    """Compare a slice run with the full-tube run it reduces (same particles, wall temperatures
    and velocity): mean temperature rise along the heated length and wall heat per PW mode over it.

    ``full`` and ``slice_`` = (positions_h5, thermal_h5, walls_h5) of the full tube and of the slice. The heated length is the slice's path; bins of ``bin_diameters``
    particle diameters. Writes ``<stem>.csv`` (the profiles) and ``<stem>.summary.csv`` (totals and
    relative differences); returns the summary.
    """
    s = slice_profile(*slice_)
    with _open(full[1], "thermal") as f:
        d = _run_spec(f, full[1])["particles"]["diameter"]
    z_top, z_bottom = s["inlet_height"], s["inlet_height"] - s["path"]
    z_edges = _edges(None, z_bottom, z_top, bin_diameters * d, "bins")
    tube = full_tube_profile(*full, window, z_edges)
    z_mid = 0.5 * (z_edges[:-1] + z_edges[1:])
    # The slice's mean temperature where its centre passes each bin's middle.
    slice_T = np.interp(z_top - z_mid, s["distance"], s["temperature"])
    rise_full, rise_slice = tube["temperature"] - tube["inlet_temperature"], slice_T - s["inlet_temperature"]
    heat_full = tube["heat"].sum(axis=0)
    heat_slice = slice_tube_heat(s, 0.0, s["path"])
    # Per bin, the slice's heat over the bin's stretch of its path.
    heat_slice_bins = np.array([slice_tube_heat(s, z_top - hi, z_top - lo) for lo, hi in zip(z_edges[:-1], z_edges[1:])])
    summary = {
        "velocity_full_m_s": tube["velocity"], "velocity_slice_m_s": s["velocity"],
        "rise_outlet_full_K": float(rise_full[0]), "rise_outlet_slice_K": float(rise_slice[0]),
        "rise_mean_full_K": float(np.mean(rise_full)), "rise_mean_slice_K": float(np.mean(rise_slice)),
        "outlet_bin_lo_m": float(z_edges[0]), "outlet_bin_hi_m": float(z_edges[1]),
    }  # fmt: skip
    summary["rise_outlet_rel_diff"] = summary["rise_outlet_slice_K"] / summary["rise_outlet_full_K"] - 1.0
    summary["rise_mean_rel_diff"] = summary["rise_mean_slice_K"] / summary["rise_mean_full_K"] - 1.0
    for j, mode in enumerate(s["modes"]):
        if mode in s["enabled"]:
            summary[f"heat_{mode}_full_W"] = float(heat_full[j])
            summary[f"heat_{mode}_slice_W"] = float(heat_slice[j])
            summary[f"heat_{mode}_rel_diff"] = float(heat_slice[j] / heat_full[j] - 1.0)
    summary["heat_total_full_W"], summary["heat_total_slice_W"] = float(heat_full.sum()), float(heat_slice.sum())
    summary["heat_total_rel_diff"] = summary["heat_total_slice_W"] / summary["heat_total_full_W"] - 1.0

    fig = Figure(figsize=(9.6, 4.0))
    ax_t, ax_q = fig.subplots(1, 2)
    distance = z_top - z_mid
    ax_t.plot(distance, rise_full, "o", color="black", label="full tube (steady window)")
    ax_t.plot(s["distance"], s["temperature"] - s["inlet_temperature"], color="tab:red", label="travelling slice")
    ax_t.set(xlabel="distance from the heated length's top (m)", ylabel="mean temperature rise (K)",
             title="(a) mean particle temperature rise")
    ax_t.legend(frameon=False)
    width = z_edges[1:] - z_edges[:-1]
    for j, mode in enumerate(s["modes"]):
        if mode in s["enabled"]:
            line = ax_q.plot(distance, tube["heat"][:, j] / width, "o", label=f"{MODE_LABELS.get(mode, mode)}, full")
            ax_q.plot(distance, heat_slice_bins[:, j] / width, color=line[0].get_color(), label="slice")
    ax_q.set(xlabel="distance from the heated length's top (m)", ylabel="wall heat per length (W/m)",
             title="(b) wall heat by mode")
    ax_q.legend(frameon=False, fontsize="small", ncol=2)
    fig.tight_layout()
    png = _save(fig, png)
    columns = {"z_lo_m": z_edges[:-1], "z_hi_m": z_edges[1:], "distance_m": distance,
               "rise_full_K": rise_full, "rise_slice_K": rise_slice}  # fmt: skip
    for j, mode in enumerate(s["modes"]):
        columns[f"heat_{mode}_full_W"] = tube["heat"][:, j]
        columns[f"heat_{mode}_slice_W"] = heat_slice_bins[:, j]
    _write_csv(png.with_suffix(".csv"), columns)
    _write_summary(png.with_suffix(".summary.csv"), summary)
    return summary


def _write_summary(path: Path, summary: dict) -> None:
    _write_csv(path, {"quantity": list(summary), "value": list(summary.values())})


# ---------------------------------------------------------------------- the Watkins figures


def fig11(positions_h5, thermal_h5, walls_h5, png) -> dict:
    """Inner wall temperature (Eq. 30 at the slice's height) and mean particle temperature against
    distance from the inlet, with the measured (570 K rise) and the paper's (547 K) mean temperature
    at 0.645 m marked (DPHT paper, Fig. 11)."""
    s = slice_profile(positions_h5, thermal_h5, walls_h5)
    inlet = s["inlet_temperature"]
    # A slice stopped short of the measurement (a smoke run) is measured where it stopped, and says so.
    reached = min(MEASUREMENT_DISTANCE, float(s["path"]))
    rise = rise_at(s, reached)
    title = f"rise to {MEASUREMENT_DISTANCE} m: {rise:.0f} K (measured {MEASURED_RISE_K:.0f}, paper {PAPER_RISE_K:.0f})"
    if reached < MEASUREMENT_DISTANCE:
        title = f"smoke run: {reached:.3g} m travelled, rise {rise:.0f} K (not the paper's {MEASUREMENT_DISTANCE} m)"
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.subplots()
    ax.plot(s["distance"], s["wall_temperature"] - KELVIN_OFFSET, "--", color="tab:blue", label="inner wall, Eq. (30)")
    ax.plot(s["distance"], s["temperature"] - KELVIN_OFFSET, color="tab:red", label="mean particle, this work")
    ax.plot([0.0, MEASUREMENT_DISTANCE], [inlet - KELVIN_OFFSET, inlet + MEASURED_RISE_K - KELVIN_OFFSET], "s",
            color="black", label="mean particle, Watkins (2018)")
    ax.plot([MEASUREMENT_DISTANCE], [inlet + PAPER_RISE_K - KELVIN_OFFSET], "^", color="tab:green",
            label="mean particle, DPHT paper")
    ax.set(xlabel="distance from inlet (m)", ylabel="temperature (°C)", title=title)
    ax.legend(frameon=False)
    fig.tight_layout()
    png = _save(fig, png)
    _write_csv(png.with_suffix(".csv"), {"distance_m": s["distance"], "wall_temperature_K": s["wall_temperature"],
                                         "mean_particle_temperature_K": s["temperature"]})  # fmt: skip
    return {"rise_K": rise, "rise_distance_m": reached, "rise_vs_measured": rise / MEASURED_RISE_K - 1.0,
            "rise_vs_paper": rise / PAPER_RISE_K - 1.0}


def fig13(positions_h5, thermal_h5, walls_h5, png, *, bin_width: float = 0.01) -> dict:
    """Particle-wall heat flux by mode along the tube (DPHT paper, Fig. 13), in bins of ``bin_width``
    m of the slice's path, and the split of the wall heat by mode overall and at 0.645 m against the
    paper's 85.6/8.5/5.9 and 82.5/7.2/10.3 %."""
    s = slice_profile(positions_h5, thermal_h5, walls_h5)
    edges = _edges(None, 0.0, s["path"], bin_width, "bins")
    index = _bin_index(s["distance_mid"], edges)
    duration = _bin_sums(index, edges.size - 1, s["dt"])[0]
    flux = np.column_stack(_bin_sums(index, edges.size - 1, *(s["flux"] * s["dt"][:, None]).T)) / duration[:, None]
    middle = 0.5 * (edges[:-1] + edges[1:])
    overall, at = splits(s)
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.subplots()
    for j, mode in enumerate(s["modes"]):
        if mode in s["enabled"]:
            ax.plot(middle, flux[:, j], label=f"{MODE_LABELS.get(mode, mode)} ({overall[mode]:.1f}% overall, "
                                              f"paper {PAPER_SPLIT_OVERALL.get(mode, math.nan)}%)")
    ax.plot(middle, flux.sum(axis=1), color="black", label="total")
    ax.axvline(MEASUREMENT_DISTANCE, color="grey", lw=0.5)
    ax.set(xlabel="distance from inlet (m)", ylabel=scene._FLUX_LABEL, title="particle-wall heat flux by mode")
    ax.legend(frameon=False, fontsize="small")
    fig.tight_layout()
    png = _save(fig, png)
    columns = {"distance_lo_m": edges[:-1], "distance_hi_m": edges[1:]}
    for j, mode in enumerate(s["modes"]):
        columns[f"flux_{mode}_W_m2"] = flux[:, j]
    columns["flux_total_W_m2"] = flux.sum(axis=1)
    _write_csv(png.with_suffix(".csv"), columns)
    rows = [m for m in s["modes"] if m in PAPER_SPLIT_OVERALL]
    _write_csv(png.with_suffix(".split.csv"), {
        "mode": rows, "overall_percent": [overall[m] for m in rows], "paper_overall_percent": [PAPER_SPLIT_OVERALL[m] for m in rows],
        "at_0.645m_percent": [at[m] for m in rows], "paper_at_0.645m_percent": [PAPER_SPLIT_AT_MEASUREMENT[m] for m in rows]})
    return {"split_overall_percent": overall, "split_at_measurement_percent": at,
            "split_overall_max_diff_points": max(abs(overall[m] - PAPER_SPLIT_OVERALL[m]) for m in rows),
            "split_at_measurement_max_diff_points": max(abs(at[m] - PAPER_SPLIT_AT_MEASUREMENT[m]) for m in rows)}


def fig12(positions_h5, thermal_h5, walls_h5, png, *, radial_bins: int = 12) -> dict:
    """(a) Particle temperature over radius and distance from the inlet: the steady tube the slice
    stands for, the tube's length compressed into the figure's height as in the paper; (b) the
    radial profile at the outlet (the run's last frame) (DPHT paper, Fig. 12)."""
    with _open(positions_h5, "positions") as fp, _open(thermal_h5, "thermal") as ft:
        spec = _run_spec(ft, thermal_h5)
        slice_ = Slice.of(spec["thermal"])
        time = ft["time"][...]
        frames = ft["dem_frame"][...]
        r_max = _particle_radius_range(fp)
        r_edges = np.linspace(0.0, r_max, radial_bins + 1)
        picks = np.unique(np.linspace(0, time.size - 1, min(PROFILE_FRAMES, time.size)).round().astype(int))
        image = np.full((picks.size, radial_bins), np.nan)
        for row, k in enumerate(picks):
            x = fp["positions"][frames[k]].astype(np.float64)
            T = ft["temperature"][k].astype(np.float64)
            alive = np.isfinite(T)
            n, total = _bin_sums(_bin_index(np.hypot(x[alive, 0], x[alive, 1]), r_edges), radial_bins,
                                 np.ones(alive.sum()), T[alive])  # fmt: skip
            image[row] = _divide(total, n)
    distance = slice_.velocity * time[picks]
    r_mid = 0.5 * (r_edges[:-1] + r_edges[1:])
    fig = Figure(figsize=(8.0, 5.0))
    ax_a, ax_b = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.6]})
    # Both halves of the cross-section (mirror image about the axis), distance downwards.
    full = np.hstack([image[:, ::-1], image]) - KELVIN_OFFSET
    mesh = ax_a.imshow(full, aspect="auto", origin="upper", cmap="inferno",
                       extent=(-1e3 * r_max, 1e3 * r_max, distance[-1], distance[0]))
    fig.colorbar(mesh, ax=ax_a, label="particle temperature (°C)")
    ax_a.set(xlabel="radial position (mm)", ylabel="distance from inlet (m)", title="(a) cross-section")
    last = image[-1]
    ax_b.plot(1e3 * r_mid, last - KELVIN_OFFSET, "o-", color="tab:red")
    ax_b.set(xlabel="radial position (mm)", ylabel="mean particle temperature (°C)",
             title=f"(b) radial profile at {distance[-1]:.3g} m")
    fig.tight_layout()
    png = _save(fig, png)
    _write_csv(png.with_suffix(".radial.csv"), {"r_lo_m": r_edges[:-1], "r_hi_m": r_edges[1:], "temperature_K": last})
    columns = {"distance_m": distance}
    for j in range(radial_bins):
        columns[f"T_r{j}_K"] = image[:, j]
    _write_csv(png.with_suffix(".map.csv"), columns)
    finite = last[np.isfinite(last)]
    return {"outlet_radial_difference_K": float(finite.max() - finite.min()) if finite.size else math.nan}


def _particle_radius_range(fp) -> float:
    """Radius (m) out to which particles are found: the half-width of the box less a particle diameter."""
    lo, hi = np.asarray(fp.attrs["box_lo"], float), np.asarray(fp.attrs["box_hi"], float)
    return float(min(-lo[0], hi[0], -lo[1], hi[1]) - 2.0 * float(fp.attrs["radius"]))


def watkins_summary(results: dict, path) -> Path:
    """The Watkins numbers beside the paper's and the experiment's (CSV): rise at 0.645 m (or where a
    shorter slice stopped), split."""
    rows = [(f"mean temperature rise to {results['rise_distance_m']:.3g} m (K)", results["rise_K"], PAPER_RISE_K, MEASURED_RISE_K)]
    for name, ours, paper in (("overall", results["split_overall_percent"], PAPER_SPLIT_OVERALL),
                              ("at 0.645 m", results["split_at_measurement_percent"], PAPER_SPLIT_AT_MEASUREMENT)):
        rows += [(f"{MODE_LABELS.get(m, m)} share {name} (%)", ours[m], paper[m], math.nan) for m in paper]
    names, ours, paper, measured = zip(*rows)
    return _write_csv(Path(path), {"quantity": names, "this_work": ours, "dpht_paper": paper, "experiment": measured})

