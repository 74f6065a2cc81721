"""A thermal run's estimate of its own numerical error (:func:`estimate_errors`), from its written
rows: the parts of :mod:`dpht.thermal.error_estimate`, fed with segments of the run re-run at
twice its step (:func:`_rerun`), the HTC tables read at the pair distances and temperatures the run
met (:func:`_met_distances`), and the RDF entries it read.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np

from dpht.closures import htc
from dpht.dem.dumps import PositionsFile
from dpht.thermal import error_estimate, integrate, integrators
from dpht.thermal.model import ThermalModel
from dpht.thermal.modes import BY_NAME as MODES, PW_MODES, solid_fractions
from dpht.thermal.schedule import Schedule
from dpht.thermal.state import State, recycle, step

log = logging.getLogger("dpht")


# The error estimate's re-run segments: ESTIMATE_SEGMENTS spread over the run, together re-running
# about ESTIMATE_FRAMES of its frames at twice its step (each costs at most two of the run's frames).
ESTIMATE_SEGMENTS = 5
ESTIMATE_FRAMES = 0.08
ESTIMATE_MIN_FRAMES = 20
ESTIMATE_PAIRS = 2000  # pair distances the tables are checked at (evaluating the closures costs)


def estimate_errors(model: ThermalModel, schedule: Schedule, dem: PositionsFile, out, spec: dict, tables: dict,
                    rdf_tables, result: dict, inflow=None) -> dict | None:
    """The run's :mod:`dpht.thermal.error_estimate` from its written rows (``out``, the open
    thermal.h5): segments re-run at twice the step from the run's own temperatures, the HTC tables'
    tabulation error over the temperatures met, the RDF entries' Monte Carlo error. A run of fewer
    than ESTIMATE_MIN_FRAMES frames has no time-step part (its segments would be a frame or two,
    and measured on real runs they missed even the sign of the error). ``inflow``: the run's hand-over
    fields (:mod:`dpht.thermal.inflow`), whose inlet field the re-runs recycle with as the run did."""
    started = time.perf_counter()
    n = len(schedule.frames)
    time_rows, wall_rows = out["time"][...], out["wall_heat"][...]
    budget = max(1, round(ESTIMATE_FRAMES * n))  # coarse frames in all
    half = max(1, round(budget / ESTIMATE_SEGMENTS))  # coarse frames per segment
    count = min(ESTIMATE_SEGMENTS, max(1, budget // half), (n - 2) // (2 * half))
    segments = []
    for i in range(count if n >= ESTIMATE_MIN_FRAMES else 0):
        k0 = 1 + round((i + 0.5) / count * (n - 2 - 2 * half))
        rows = range(k0, k0 + 2 * half)
        fine = (wall_rows[rows.start:rows.stop] * np.diff(time_rows[rows.start:rows.stop + 1])[:, None]).sum(axis=0)
        coarse = _rerun(model, schedule, dem, out["temperature"][k0 - 1], k0, half, spec, inflow)
        segments.append({"coarse": coarse, "fine": fine, "seconds": float(time_rows[rows.stop] - time_rows[k0])})
    by_mode = dict(zip(PW_MODES, (wall_rows[:-1] * np.diff(time_rows)[:, None]).sum(axis=0).tolist()))
    t = spec["thermal"]
    temperature = out["temperature"]
    met = [float(np.nanmin(temperature[::max(1, n // 20)])), float(np.nanmax(temperature[::max(1, n // 20)]))]
    if model.wall_range is not None:  # the walls over the whole run, not where a slice's last step left them
        met[1] = max(met[1], model.wall_range[1])
    parts = {"time_step": error_estimate.time_step_part(segments, float(time_rows[-1] - time_rows[0]), by_mode) if segments else None}
    met_distances = _met_distances(model, schedule, dem, out)
    for kind, table in tables.items():
        if kind in model.modes and np.any(table.values):  # an all-zero table (a vacuum) has no error
            dT = table.temperature[1] - table.temperature[0]
            columns = (table.temperature >= met[0] - dT) & (table.temperature <= met[1] + dT)
            column = int(np.argmin(np.abs(table.temperature - 0.5 * (met[0] + met[1]))))
            in_temperature = error_estimate.table_interpolation_error(table.values, columns=columns, axes=(1,))
            d = np.clip(met_distances[kind][:: max(1, met_distances[kind].size // ESTIMATE_PAIRS)], table.distance[0],
                        table.distance[-1])  # fmt: skip
            T = np.full_like(d, table.temperature[column])
            exact = table.exact(d, T)
            parts[kind] = in_temperature + error_estimate.tabulation_error(htc.interpolate(table, d, T), exact)
    phi = solid_fractions(t["solid_fraction"])
    for name, side in (("pp_radiation", "pp"), ("pw_radiation", "pw")):
        if name in model.modes and rdf_tables is not None:
            table, mode = getattr(rdf_tables, side), MODES[name]
            column = [np.interp(phi[mode.region], table.solid_fraction, v[:, k]) for v in (table.rdf, table.stderr)
                      for k in range(table.distance.size)]  # fmt: skip
            values = np.reshape(column, (2, table.distance.size))
            parts[f"{side}_rdf"] = error_estimate.rdf_relative_stderr(table.distance, values[0], values[1],
                                                                       mode.cutoff_radii(t), shell=side == "pp")  # fmt: skip
    estimate = error_estimate.combine(parts, by_mode)
    estimate["seconds"] = time.perf_counter() - started
    estimate["cost_fraction"] = estimate["seconds"] / result["seconds"] if result["seconds"] > 0 else None
    log.info("thermal: error estimate %.3g%% of the wall heat (%s) in %.2f s (%.0f%% of the run)",
             100 * estimate["wall_heat"]["relative"],
             ", ".join(f"{k} {100 * v:.2g}%" for k, v in estimate["wall_heat"]["parts"].items()),
             estimate["seconds"], 100 * (estimate["cost_fraction"] or 0))  # fmt: skip
    return estimate


def _met_distances(model: ThermalModel, schedule: Schedule, dem: PositionsFile, out, frames: int = 2) -> dict:
    """Centre-centre (PFP) and centre-wall (PFW) distances (m) within the cutoffs in ``frames``
    frames spread over the run: the pairs the HTC tables were read at."""
    from scipy.spatial import cKDTree

    met = {"pfp": [], "pfw": []}
    for k in np.linspace(0, len(schedule.frames) - 1, frames).round().astype(int):
        positions = np.asarray(dem.frame(schedule.frames[k]).positions, dtype=np.float64)
        positions = positions[np.all(np.isfinite(positions), axis=1)]
        if "pfp" in model.modes:
            tree = cKDTree(positions)
            pairs = tree.query_pairs(model.cutoffs["pfp"], output_type="ndarray")
            met["pfp"].append(np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1))
        if "pfw" in model.modes:
            frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
            d = frame.wall_distance[frame.wall_element >= 0]
            met["pfw"].append(d[d <= model.cutoffs["pfw"]])
    return {kind: np.concatenate(v) if v else np.zeros(0) for kind, v in met.items()}


def _rerun(model: ThermalModel, schedule: Schedule, dem: PositionsFile, temperature, k0: int, m: int, spec: dict,
           inflow=None) -> np.ndarray:  # fmt: skip
    """Wall heat (J per PW mode) of thermal frames k0 to k0 + 2m re-run with every other frame (twice
    the step) by a fresh integrator of the run's kind, from the run's temperatures at the start of
    frame k0 (``temperature``, before its resets)."""
    frames = schedule.frames[k0:k0 + 2 * m + 1:2]
    coarse = replace(schedule, frames=frames, times=schedule.times[k0:k0 + 2 * m + 1:2])
    last = dem.frame(schedule.frames[k0 - 1])
    h = model.enthalpy.enthalpy(np.where(np.isfinite(temperature), temperature, model.inlet_temperature))
    integrator = integrators.create(integrators.requested(spec["thermal"]), model, spec["thermal"])
    h = np.asarray(h, dtype=np.float64)
    shells = np.repeat(h[:, None], model.shells.n, axis=1) if model.shells is not None else None  # uniform at the start
    state = State(0, h, 0.0, 0.0, (np.asarray(last.positions, dtype=np.float64), last.image), shells=shells)
    heat = np.zeros(len(PW_MODES))
    for j in range(m):
        current = dem.frame(frames[j])
        positions = np.asarray(current.positions, dtype=np.float64)
        recycle(model, coarse, state, positions, current.image, inflow)
        row, _ = step(model, coarse, state, positions, integrator)
        heat += coarse.interval(j) * row.element_heat.sum(axis=0)
    return heat
