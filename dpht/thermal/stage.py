"""The thermal stage: stream DEM frames, advance particle enthalpies, write the thermal output.

I/O lives here; the physics is in :mod:`dpht.thermal.model`, :mod:`dpht.thermal.kernels` and
:mod:`dpht.thermal.integrate`. Memory stays bounded by one frame whatever the run length: frames
are read one at a time and results written as they are computed.

:func:`run` is a loop of named steps over the frames of a :class:`Schedule`, and everything carried
from one frame to the next is one :class:`State` (enthalpies, energy bookkeeping, the previous
frame for recycling), so the state after any frame plus the rows written so far is the whole run::

    state = State.initial(model, n)
    for each frame from state.count on:
        recycle(...)          reset particles re-entering at the inlet, book the energy
        row = step(...)       advance the enthalpies over the frame's interval
        writer.write(row)
    writer.finish(summary(...))

Resuming a run means restoring a State and the rows written before it, then continuing the loop;
another time integrator replaces the one call of :func:`dpht.thermal.integrate.advance` in
:func:`step`.

Energy bookkeeping (J): between consecutive rows, the change of ``energy_particles`` equals the
change of ``energy_wall`` (the interval's mean wall heat times its length) plus that of
``energy_recycled``, to round-off.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numba
import numpy as np

from dpht.closures import htc, rdf
from dpht.dem.dumps import PositionsFile
from dpht.thermal import error_estimate, integrate, model as thermal_model
from dpht.thermal.model import ThermalModel
from dpht.thermal.modes import BY_NAME as MODES, PW_MODES, solid_fractions
from dpht.thermal.output import Row, ThermalWriter, write_xdmf
from dpht.util.progress import Progress
from geometry.walls import load_walls

log = logging.getLogger("dpht")

# Resident memory of a run (the estimate logged before it starts). Measured by
# benchmarks/thermal_step.py (README, Performance; all six modes, radiation cutoff 7 radii): at most
# 175 B per particle beyond the frame (the enthalpy, the cell list, the peak of one step) and about
# 510 B per wall element (the wall index); the frames this stage holds (this and the previous
# frame's float64 positions and image flags, one float32 temperature row) and the tables count by size.
STEP_BYTES_PER_PARTICLE = 175
WALL_BYTES_PER_ELEMENT = 510
FRAME_BYTES_PER_PARTICLE = 2 * (3 * 8 + 3 * 4) + 4


def _nbytes(obj) -> int:
    """Bytes of the arrays in ``obj``: an array, or a dataclass, mapping or sequence holding arrays."""
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if isinstance(obj, dict):
        return sum(map(_nbytes, obj.values()))
    if isinstance(obj, (list, tuple)):
        return sum(map(_nbytes, obj))
    return sum(map(_nbytes, vars(obj).values())) if hasattr(obj, "__dict__") else 0


def memory_estimate(n_particles: int, n_elements: int, tables) -> int:
    """Bytes a run of ``n_particles`` against ``n_elements`` wall elements needs, ``tables`` included."""
    per_particle = STEP_BYTES_PER_PARTICLE + FRAME_BYTES_PER_PARTICLE
    return n_particles * per_particle + n_elements * WALL_BYTES_PER_ELEMENT + _nbytes(tables)


@dataclass(frozen=True)
class Schedule:
    """The DEM frames the stage takes and the box they move in, from the positions file."""

    frames: list  # DEM frame index of each thermal frame (every thermal.frame_stride-th)
    times: np.ndarray  # s, of those frames
    box_lo: np.ndarray  # m
    box_hi: np.ndarray  # m
    periodic: np.ndarray  # (3,) bool
    flow_axis: int | None  # the periodic tube axis (z): particles flow towards -z and re-enter at the top

    @classmethod
    def of(cls, dem: PositionsFile, stride: int) -> Schedule:
        frames = list(range(0, dem.n_frames, stride))
        periodic = np.asarray(dem.attrs["periodic"], dtype=bool)
        return cls(frames, dem.times[frames], np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"]),
                   periodic, 2 if periodic[2] else None)  # fmt: skip

    def interval(self, count: int) -> float:
        """Length (s) of the interval from thermal frame ``count`` to the next; 0 after the last."""
        return float(self.times[count + 1] - self.times[count]) if count + 1 < len(self.frames) else 0.0


@dataclass
class State:
    """Everything the run carries from one frame to the next (what a checkpoint must hold)."""

    count: int  # thermal frames taken so far (the index of the next one)
    h: np.ndarray  # (N,) J/kg, specific enthalpy of every particle, in the positions file's order
    wall_energy: float  # J received from the walls since the first frame
    recycled_energy: float  # J, enthalpy change from resetting re-entering particles
    previous: tuple | None  # (positions, image flags) of the last frame taken, to detect re-entry

    @classmethod
    def initial(cls, model: ThermalModel, n: int) -> State:
        return cls(0, np.full(n, model.enthalpy.enthalpy(model.initial_temperature)[()]), 0.0, 0.0, None)

    def particle_energy(self, model: ThermalModel) -> float:
        """Total particle enthalpy (J, relative to the enthalpy table's T0)."""
        return model.mass * math.fsum(self.h)


def recycle(model: ThermalModel, schedule: Schedule, state: State, positions: np.ndarray, image) -> None:
    """Reset particles that re-entered at the inlet since the last frame to the inlet temperature.

    A re-entry is a downward crossing of the periodic flow axis (from the image flags, or a jump of
    more than half the box); its enthalpy change is booked in ``state.recycled_energy``.
    """
    if state.previous is not None and schedule.flow_axis is not None:
        last_positions, last_image = state.previous
        crossed = integrate.wrapped(last_image, image, last_positions, positions, schedule.box_lo, schedule.box_hi,
                                    schedule.flow_axis)  # fmt: skip
        h_inlet = model.enthalpy.enthalpy(model.inlet_temperature)[()]
        state.recycled_energy += model.mass * float(np.sum(h_inlet - state.h[crossed]))
        state.h[crossed] = h_inlet
    state.previous = (positions, image)


def step(model: ThermalModel, schedule: Schedule, state: State, positions: np.ndarray) -> tuple[Row, int]:
    """Advance the enthalpies over the interval that starts at this frame (held fixed meanwhile).

    Returns the frame's output row and its work in particle-steps (for the progress ETA).
    """
    count = state.count
    energy_particles = state.particle_energy(model)
    frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    dt = schedule.interval(count)
    report = integrate.advance(model, frame, state.h, dt, integrate.Rates.for_frame(model, frame),
                               frame_number=schedule.frames[count])  # fmt: skip
    temperature = np.full(state.h.size, np.nan, dtype=np.float32)  # lost particles stay NaN
    temperature[frame.particles] = report.temperature
    row = Row(schedule.times[count], temperature, report.element_heat, report.substeps, energy_particles,
              state.wall_energy, state.recycled_energy)  # fmt: skip
    state.wall_energy += dt * math.fsum(report.element_heat.ravel())
    state.count += 1
    return row, frame.particles.size * max(report.substeps, 1)


def summary(schedule: Schedule, state: State, last: Row, seconds: float) -> dict:
    """The run's summary: totals (J), the wall heat per PW mode at the last frame (W), the cost."""
    return {
        "frames": len(schedule.frames),
        "particles": int(state.h.size),
        "wall_energy_J": state.wall_energy,
        "recycled_energy_J": state.recycled_energy,
        "wall_heat_last_W": dict(zip(PW_MODES, last.element_heat.sum(axis=0).tolist())),
        "seconds": seconds,
        "threads": numba.get_num_threads(),
    }


def run(
    spec: dict,
    positions_h5,
    walls_h5,
    htc_tables: dict,
    out_h5,
    *,
    rdf_table=None,
    xdmf=None,
    threads: int | None = None,
) -> dict:
    """Run the thermal stage of one scene and return a summary (also stored in the output's attrs).

    ``spec`` is :func:`dpht.config.thermal_spec` of the config; ``htc_tables`` maps "pfp"/"pfw" to
    table files; ``rdf_table`` is the RDF table file (or list of files, interpolated to the
    config's emissivities) when radiation is enabled.
    """
    if threads:
        numba.set_num_threads(threads)
    walls = load_walls(walls_h5)
    tables = {kind: htc.load_table(path) for kind, path in htc_tables.items()}
    rdf_tables = _rdf_tables(rdf_table, spec) if rdf_table else None
    model = thermal_model.build(spec, walls, tables, rdf_tables)
    started = time.perf_counter()

    with PositionsFile(positions_h5) as dem:
        schedule = Schedule.of(dem, spec["thermal"]["frame_stride"])
        state = State.initial(model, dem.n_particles)
        n = dem.n_particles
        needed = memory_estimate(n, len(walls.area), [tables, rdf_tables])
        log.info(
            "thermal: memory estimate %.3g MB: %d particles x %d B, %d wall elements x %d B, tables %.3g MB "
            "(frames are read one at a time)",
            needed / 1e6, n, STEP_BYTES_PER_PARTICLE + FRAME_BYTES_PER_PARTICLE, len(walls.area),
            WALL_BYTES_PER_ELEMENT, _nbytes([tables, rdf_tables]) / 1e6,
        )  # fmt: skip
        writer = ThermalWriter(
            out_h5,
            ids=dem.ids,
            dem_frames=schedule.frames,
            n_elements=len(walls.area),
            attrs={
                "modes": json.dumps(sorted(model.modes)),
                "inlet_temperature": model.inlet_temperature,
                "positions": str(Path(positions_h5).name),
                "spec": json.dumps(spec, sort_keys=True),
            },
        )
        progress = Progress("thermal", len(schedule.frames), unit="particle-steps")
        try:
            for count in range(state.count, len(schedule.frames)):
                current = dem.frame(schedule.frames[count])
                positions = np.asarray(current.positions, dtype=np.float64)
                recycle(model, schedule, state, positions, current.image)
                row, work = step(model, schedule, state, positions)
                writer.write(count, row)
                progress.update(count + 1, work=work)
        except BaseException:
            writer.abort()
            raise
        result = summary(schedule, state, row, time.perf_counter() - started)
        result["error_estimate"] = estimate_errors(model, schedule, dem, writer.file, spec, tables, rdf_tables, result)
        writer.finish(result)
        if xdmf:
            write_xdmf(xdmf, out_h5, positions_h5, frames=schedule.frames, n_dem_frames=dem.n_frames,
                       n_particles=dem.n_particles, times=schedule.times, precision=current.positions.dtype.itemsize)  # fmt: skip
    log.info("thermal: %d frames of %d particles in %.1f s", len(schedule.frames), dem.n_particles, result["seconds"])
    return result


# The error estimate's re-run segments: ESTIMATE_SEGMENTS spread over the run, together re-running
# about ESTIMATE_FRAMES of its frames at twice its step (each costs at most two of the run's frames).
ESTIMATE_SEGMENTS = 5
ESTIMATE_FRAMES = 0.08
ESTIMATE_MIN_FRAMES = 20
ESTIMATE_PAIRS = 2000  # pair distances the tables are checked at (evaluating the closures costs)


def estimate_errors(model: ThermalModel, schedule: Schedule, dem: PositionsFile, out, spec: dict, tables: dict,
                    rdf_tables, result: dict) -> dict | None:
    """The run's :mod:`dpht.thermal.error_estimate` from its written rows (``out``, the open
    thermal.h5): segments re-run at twice the step from the run's own temperatures, the HTC tables'
    tabulation error over the temperatures met, the RDF entries' Monte Carlo error. A run of fewer
    than ESTIMATE_MIN_FRAMES frames has no time-step part (its segments would be a frame or two,
    and measured on real runs they missed even the sign of the error)."""
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
        coarse = _rerun(model, schedule, dem, out["temperature"][k0 - 1], k0, half)
        segments.append({"coarse": coarse, "fine": fine, "seconds": float(time_rows[rows.stop] - time_rows[k0])})
    by_mode = dict(zip(PW_MODES, (wall_rows[:-1] * np.diff(time_rows)[:, None]).sum(axis=0).tolist()))
    t = spec["thermal"]
    temperature = out["temperature"]
    met = [float(np.nanmin(temperature[::max(1, n // 20)])), float(np.nanmax(temperature[::max(1, n // 20)]))]
    if model.element_temperature.size and np.isfinite(model.element_temperature).any():
        met[1] = max(met[1], float(np.nanmax(model.element_temperature)))
    parts = {"time_step": error_estimate.time_step_part(segments, float(time_rows[-1] - time_rows[0]), by_mode) if segments else None}
    met_distances = _met_distances(model, schedule, dem, out)
    for kind, table in tables.items():
        if kind in model.modes:
            dT = table.temperature[1] - table.temperature[0]
            columns = (table.temperature >= met[0] - dT) & (table.temperature <= met[1] + dT)
            column = int(np.argmin(np.abs(table.temperature - 0.5 * (met[0] + met[1]))))
            in_temperature = error_estimate.table_interpolation_error(table.values, columns=columns, axes=(1,))
            d = np.clip(met_distances[kind][:: max(1, met_distances[kind].size // ESTIMATE_PAIRS)], table.distance[0],
                        table.distance[-1])  # fmt: skip
            T = np.full_like(d, table.temperature[column])
            exact = getattr(htc, kind)(d, T, radius=table.radius, k_solid=table.k_solid,
                                       solid_fraction=table.solid_fraction, gas=table.gas)  # fmt: skip
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


def _rerun(model: ThermalModel, schedule: Schedule, dem: PositionsFile, temperature, k0: int, m: int) -> np.ndarray:
    """Wall heat (J per PW mode) of thermal frames k0 to k0 + 2m re-run with every other frame (twice
    the step), from the run's temperatures at the start of frame k0 (``temperature``, before its resets)."""
    frames = schedule.frames[k0:k0 + 2 * m + 1:2]
    coarse = replace(schedule, frames=frames, times=schedule.times[k0:k0 + 2 * m + 1:2])
    last = dem.frame(schedule.frames[k0 - 1])
    h = model.enthalpy.enthalpy(np.where(np.isfinite(temperature), temperature, model.inlet_temperature))
    state = State(0, np.asarray(h, dtype=np.float64), 0.0, 0.0, (np.asarray(last.positions, dtype=np.float64), last.image))
    heat = np.zeros(len(PW_MODES))
    for j in range(m):
        current = dem.frame(frames[j])
        positions = np.asarray(current.positions, dtype=np.float64)
        recycle(model, coarse, state, positions, current.image)
        row, _ = step(model, coarse, state, positions)
        heat += coarse.interval(j) * row.element_heat.sum(axis=0)
    return heat


def _rdf_tables(paths, spec) -> rdf.RDFTables:
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    return rdf.for_emissivities([rdf.load(p) for p in paths], spec["particles"]["emissivity"], spec["wall"]["emissivity"])
