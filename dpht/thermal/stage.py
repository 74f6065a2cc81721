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

Another time integrator replaces the one call of :func:`dpht.thermal.integrate.advance` in
:func:`step`.

Resume (:class:`WorkDir`): rows are written into *segment* files in the stage's work directory;
every ``thermal.checkpoint_frames`` frames or ``thermal.checkpoint_minutes`` minutes, whichever
comes first, the segment is closed and the State saved (``checkpoint.h5``, replaced atomically).
A run killed at any point restarts from the last checkpoint and writes the same rows: the State
is all the loop carries, so the result is bitwise that of an uninterrupted run. When the last
frame is done the segments are copied, compressed chunks as they are, into ``thermal.h5`` in the
work directory, which is then published as the stage's output (a hard link,
:func:`dpht.util.files.publish`): a file at the output's name is always complete, and a later
run of the same inputs publishes it again instead of recomputing it.

Energy bookkeeping (J): between consecutive rows, the change of ``energy_particles`` equals the
change of ``energy_wall`` (the interval's mean wall heat times its length) plus that of
``energy_recycled``, to round-off.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numba
import numpy as np

from dpht.closures import htc, rdf
from dpht.dem.dumps import CONTENT_DIGEST, PositionsFile
from dpht.thermal import error_estimate, integrate, model as thermal_model
from dpht.thermal.model import ThermalModel
from dpht.thermal.modes import BY_NAME as MODES, PW_MODES, solid_fractions
from dpht.thermal.output import Row, ThermalWriter, write_xdmf
from dpht.util import processes
from dpht.util.files import WorkdirLock, partial_path, publish, replacing
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


def summary(schedule: Schedule, state: State, wall_heat_last: np.ndarray, seconds: float) -> dict:
    """The run's summary: totals (J), the wall heat per PW mode at the last frame (W), the cost."""
    return {
        "frames": len(schedule.frames),
        "particles": int(state.h.size),
        "wall_energy_J": state.wall_energy,
        "recycled_energy_J": state.recycled_energy,
        "wall_heat_last_W": dict(zip(PW_MODES, wall_heat_last.tolist())),
        "seconds": seconds,
        "threads": numba.get_num_threads(),
    }


# --- checkpoints ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Checkpoints:
    """How often the state is saved: after ``frames`` frames or ``minutes`` of computing, whichever
    comes first (``thermal.checkpoint_frames``, ``thermal.checkpoint_minutes``; not part of the
    stage key, since they do not change the result)."""

    frames: int = 500
    minutes: float = 10.0


class WorkDir:
    """The work directory of one thermal run: ``rows.<first frame>.h5`` segments, ``checkpoint.h5``
    (the State after the segments' rows, and the list of segments) and, once done, the complete
    ``thermal.h5``. Everything in it belongs to one ``fingerprint`` of the inputs (spec, positions
    frames, walls, tables); a checkpoint of other inputs is discarded."""

    CHECKPOINT, FINAL = "checkpoint.h5", "thermal.h5"

    def __init__(self, folder, fingerprint: str):
        self.folder, self.fingerprint = Path(folder), fingerprint
        self.folder.mkdir(parents=True, exist_ok=True)

    @property
    def final(self) -> Path:
        return self.folder / self.FINAL

    def segment(self, first: int) -> Path:
        return self.folder / f"rows.{first:08d}.h5"

    def complete(self) -> dict | None:
        """The stored summary of the complete output of these inputs, if there is one."""
        return _complete(self.final, self.fingerprint)

    def restore(self, model: ThermalModel, n: int) -> tuple[State, list[tuple[int, int]], float]:
        """(State, [(first frame, rows) of each segment], seconds spent) of the last checkpoint of
        these inputs, or the initial state; files that the checkpoint does not list are removed."""
        state, segments, seconds = State.initial(model, n), [], 0.0
        try:
            with h5py.File(self.folder / self.CHECKPOINT, "r") as f:
                if f.attrs["fingerprint"] == self.fingerprint:
                    segments = [tuple(s) for s in json.loads(f.attrs["segments"])]
                    previous = (f["previous_positions"][...], f["previous_image"][...]) if "previous_image" in f else None
                    state = State(int(f.attrs["count"]), f["h"][...], float(f.attrs["wall_energy"]),
                                  float(f.attrs["recycled_energy"]), previous)  # fmt: skip
                    seconds = float(f.attrs["seconds"])
        except (OSError, KeyError, ValueError):
            pass
        if not all(_rows(self.segment(first)) == rows for first, rows in segments):
            state, segments, seconds = State.initial(model, n), [], 0.0  # a damaged segment: start again
        keep = {self.segment(first).name for first, _ in segments} | {self.CHECKPOINT, self.FINAL, LOCK}
        for path in self.folder.iterdir():
            if path.name not in keep:
                path.unlink()
        return state, segments, seconds

    def save(self, state: State, segments: list[tuple[int, int]], seconds: float) -> None:
        """Replace the checkpoint (atomically): the State after the rows of ``segments``."""
        with replacing(self.folder / self.CHECKPOINT) as tmp, h5py.File(tmp, "w") as f:
            f.create_dataset("h", data=state.h)
            if state.previous is not None:
                f.create_dataset("previous_positions", data=state.previous[0])
                f.create_dataset("previous_image", data=state.previous[1])
            f.attrs.update(fingerprint=self.fingerprint, count=state.count, wall_energy=state.wall_energy,
                           recycled_energy=state.recycled_energy, segments=json.dumps(segments), seconds=seconds)  # fmt: skip

    def clear(self) -> None:
        """Remove the segments and the checkpoint (once the complete output exists)."""
        for path in self.folder.glob("rows.*.h5"):
            path.unlink()
        (self.folder / self.CHECKPOINT).unlink(missing_ok=True)


LOCK = ".thermal.lock"


def _rows(segment: Path) -> int | None:
    try:
        with h5py.File(segment, "r") as f:
            return int(f.attrs["rows"])
    except (OSError, KeyError, ValueError):
        return None


def _complete(path: Path, fingerprint: str) -> dict | None:
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("complete") and f.attrs.get("fingerprint") == fingerprint:
                return json.loads(f.attrs["summary"])
    except (OSError, KeyError, ValueError):
        pass
    return None


def fingerprint(spec: dict, positions_h5, inputs) -> str:
    """Digest of what a thermal run computes from: the spec, the positions file's frames (its
    content digest where the DEM stage stored one) and the bytes of the other input files."""
    h = hashlib.sha256(json.dumps(spec, sort_keys=True).encode())
    with PositionsFile(positions_h5) as dem:
        digest = dem.attrs.get(CONTENT_DIGEST)
    for path in ([] if digest else [positions_h5]) + [p for p in inputs if p is not None]:
        with open(path, "rb") as stream:
            h.update(hashlib.file_digest(stream, "sha256").digest())
    h.update(str(digest).encode())
    return h.hexdigest()


# --- the stage ----------------------------------------------------------------------------------


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
    workdir=None,
    checkpoints: Checkpoints = Checkpoints(),
) -> dict:
    """Run the thermal stage of one scene and return a summary (also stored in the output's attrs).

    ``spec`` is :func:`dpht.config.thermal_spec` of the config; ``htc_tables`` maps "pfp"/"pfw" to
    table files; ``rdf_table`` is the RDF table file (or list of files, interpolated to the
    config's emissivities) when radiation is enabled. ``workdir`` (default: ``<out_h5
    stem>.work`` next to it) holds the checkpoints and the complete output, which ``out_h5`` is a
    hard link to; a run interrupted at any point continues from its last checkpoint, and a run of
    inputs whose output is complete there only publishes it.
    """
    out_h5 = Path(out_h5)
    rdf_paths = [rdf_table] if isinstance(rdf_table, (str, Path)) else list(rdf_table or [])
    inputs = [walls_h5, *(htc_tables[k] for k in sorted(htc_tables)), *rdf_paths]
    work = WorkDir(workdir if workdir is not None else out_h5.with_name(out_h5.stem + ".work"),
                   fingerprint(spec, positions_h5, inputs))  # fmt: skip
    with WorkdirLock(work.folder, LOCK, "thermal"):
        result = work.complete()
        if result is not None:
            log.info("thermal: %s is the complete %s of an earlier run of these inputs", out_h5, work.final)
            work.clear()
        else:
            result = _compute(spec, positions_h5, walls_h5, htc_tables, rdf_table, work, threads, checkpoints)
        if xdmf:  # in the output's folder, so its relative paths hold for the final name
            with PositionsFile(positions_h5) as dem, replacing(xdmf) as tmp:
                schedule = Schedule.of(dem, spec["thermal"]["frame_stride"])
                write_xdmf(tmp, out_h5, positions_h5, frames=schedule.frames, n_dem_frames=dem.n_frames,
                           n_particles=dem.n_particles, times=schedule.times,
                           precision=dem.frame(0).positions.dtype.itemsize)  # fmt: skip
        publish(work.final, out_h5)
    return result


def _compute(spec, positions_h5, walls_h5, htc_tables, rdf_table, work: WorkDir, threads, checkpoints: Checkpoints) -> dict:
    """Compute the run's rows from the last checkpoint on, then assemble ``work.final``."""
    if threads:
        numba.set_num_threads(threads)
    walls = load_walls(walls_h5)
    tables = {kind: htc.load_table(path) for kind, path in htc_tables.items()}
    rdf_tables = _rdf_tables(rdf_table, spec) if rdf_table else None
    model = thermal_model.build(spec, walls, tables, rdf_tables)
    started = time.perf_counter()

    with PositionsFile(positions_h5) as dem:
        schedule = Schedule.of(dem, spec["thermal"]["frame_stride"])
        n_frames = len(schedule.frames)
        state, segments, seconds_before = work.restore(model, dem.n_particles)
        n = dem.n_particles
        needed = memory_estimate(n, len(walls.area), [tables, rdf_tables])
        log.info(
            "thermal: memory estimate %.3g MB: %d particles x %d B, %d wall elements x %d B, tables %.3g MB "
            "(frames are read one at a time)",
            needed / 1e6, n, STEP_BYTES_PER_PARTICLE + FRAME_BYTES_PER_PARTICLE, len(walls.area),
            WALL_BYTES_PER_ELEMENT, _nbytes([tables, rdf_tables]) / 1e6,
        )  # fmt: skip
        attrs = {
            "modes": json.dumps(sorted(model.modes)),
            "inlet_temperature": model.inlet_temperature,
            "positions": str(Path(positions_h5).name),
            "spec": json.dumps(spec, sort_keys=True),
        }
        if state.count:
            log.info("thermal: resuming from the checkpoint after frame %d of %d in %s", state.count, n_frames, work.folder)
        progress = Progress("thermal", n_frames, unit="particle-steps", start=state.count)
        writer, first, saved = None, state.count, time.monotonic()
        with processes.deferred_signals() as interrupted:  # a signal stops the run after a frame, saved
            try:
                for count in range(state.count, n_frames):
                    if writer is None:
                        first, saved = count, time.monotonic()
                        writer = ThermalWriter(partial_path(work.segment(first)), ids=dem.ids, n_elements=len(walls.area),
                                               dem_frames=schedule.frames[first : first + checkpoints.frames],
                                               attrs=attrs)  # fmt: skip
                    current = dem.frame(schedule.frames[count])
                    positions = np.asarray(current.positions, dtype=np.float64)
                    recycle(model, schedule, state, positions, current.image)
                    row, work_done = step(model, schedule, state, positions)
                    writer.write(count - first, row)
                    progress.update(count + 1, work=work_done)
                    full = state.count - first == writer.file["time"].shape[0]
                    if full or interrupted.signal or time.monotonic() - saved >= 60.0 * checkpoints.minutes:
                        _close_segment(writer, work, first, state.count - first)
                        segments.append((first, state.count - first))
                        work.save(state, segments, seconds_before + time.perf_counter() - started)
                        writer = None
                    interrupted.stop_if_asked()
            finally:
                if writer is not None:  # an error or a second signal: the rows since the checkpoint are lost
                    writer.close()
                    writer.path.unlink(missing_ok=True)
        with replacing(work.final) as tmp:
            final = ThermalWriter(tmp, ids=dem.ids, dem_frames=schedule.frames, n_elements=len(walls.area), attrs=attrs)
            for first, rows in segments:
                final.copy_rows(work.segment(first), first, rows)
            wall_heat_last = final.file["wall_heat"][-1]
            result = summary(schedule, state, wall_heat_last, seconds_before + time.perf_counter() - started)
            result["error_estimate"] = estimate_errors(model, schedule, dem, final.file, spec, tables, rdf_tables, result)
            final.file.attrs["fingerprint"] = work.fingerprint
            final.finish(result)
        work.clear()
    log.info("thermal: %d frames of %d particles in %.1f s", n_frames, dem.n_particles, result["seconds"])
    return result


SEGMENT_FORMAT = "dpht-thermal-segment-1"  # the output's layout, with rows 0..rows-1 of frames first..


def _close_segment(writer: ThermalWriter, work: WorkDir, first: int, rows: int) -> None:
    """Record the rows written, close the segment (complete as a segment) and give it its name."""
    writer.file.attrs.update(format=SEGMENT_FORMAT, first=first, rows=rows, complete=True)
    writer.close()
    writer.path.replace(work.segment(first))


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
