"""The thermal stage: stream DEM frames, advance particle enthalpies, write the thermal output.

I/O lives here; the physics is in :mod:`dpht.thermal.model`, :mod:`dpht.thermal.kernels` and
:mod:`dpht.thermal.integrate`. Memory stays bounded by one frame whatever the run length: frames
are read one at a time and results written as they are computed.

:func:`run` is a loop of named steps over the frames of a :class:`Schedule` (:func:`advance_frames`),
and everything carried from one frame to the next is one :class:`State` (enthalpies, energy
bookkeeping, the previous frame for recycling), so the state after any frame plus the rows written
so far is the whole run::

    state = State.initial(model, n)             or restored from a checkpoint (resume)
    for each frame from state.count on:         (frames_from)
        recycle(...)          reset particles re-entering at the inlet, book the energy
        row = step(...)       advance the enthalpies over the frame's interval
        out.write(row)        into the open segment (Segments); a checkpoint when one is due
    assemble(...)             the rows into thermal.h5, with summary(...) and the error estimate

Resuming a run means restoring a State and the rows written before it, then continuing the loop.
:func:`step` makes the one call of the time integrator (``thermal.integrator``, from the registry
:mod:`dpht.thermal.integrators`; ``auto`` chooses per frame); what the integrator carries from
frame to frame is its checkpoint (:meth:`checkpoint`), saved with the State.

Frozen bed (``thermal.frozen_bed: {frame, duration, step}``): one DEM frame held fixed for
``duration`` s in steps of ``step`` s, for static-bed studies (an effective conductivity, a bin's
charging curve) without a DEM flow run; :meth:`Schedule.frozen_bed` gives the schedule (every row
refers to that DEM frame, nothing is recycled) and the frame's geometry is prepared once. The
positions file may hold a DEM settle or flow run, or a packing from
:func:`dpht.radiation.packing.write_packed_bed`.

Resume (:class:`WorkDir`): rows are written into *segment* files in the stage's work directory;
every ``thermal.checkpoint_frames`` frames or ``thermal.checkpoint_minutes`` minutes, whichever
comes first, the segment is closed and the State saved (``checkpoint.h5``, replaced atomically).
A run killed at any point restarts from the last checkpoint and writes the same rows: the State
is all the loop carries, so the result is bitwise that of an uninterrupted run. When the last
frame is done the segments are copied, compressed chunks as they are, into ``thermal.h5`` in the
work directory, which is then published as the stage's output (a hard link,
:func:`dpht.util.files.publish`): a file at the output's name is always complete, and a later
run of the same inputs publishes it again instead of recomputing it.

Resolved intra-particle conduction (``thermal.intraparticle``, :mod:`dpht.thermal.intraparticle`):
the State also holds every particle's shell enthalpies; ``auto`` decides once, from the first
frame, by the particles' Biot numbers (:func:`decide_intraparticle`), so a resumed run decides
the same. The written temperature is the particle's mean (from h), the one the energy books use.

Energy bookkeeping (J): between consecutive rows, the change of ``energy_particles`` equals the
change of ``energy_wall`` (the interval's mean wall heat times its length) plus those of
``energy_recycled`` and ``energy_convected`` (particle-gas convection, ``thermal.convection``),
to round-off.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import h5py
import numba
import numpy as np

from dpht.closures import htc, rdf
from dpht.dem.dumps import PositionsFile, content_digest
from dpht.dem.report import FORMAT as DEM_REPORT_FORMAT, measured_solid_fraction, solid_fraction_over
from dpht.errors import ConfigError, DPHTError
from dpht.thermal import effects, error_estimate, integrate, integrators, model as thermal_model, modes as registry
from dpht.thermal.model import ThermalModel
from dpht.thermal.modes import BY_NAME as MODES, PW_MODES, solid_fractions
from dpht.thermal.output import Row, ThermalWriter, write_xdmf
from dpht.thermal.slice import Slice, cycled
from dpht.util import processes
from dpht.util.files import WorkdirLock, partial_path, publish, replacing
from dpht.util.progress import Progress
from geometry.walls import load_walls

log = logging.getLogger("dpht")

# Look-ups clamped at a table's edge, counted per frame at its start and summed over the run: PFP and
# PFW distances below their HTC table (deep overlaps without softening), and particles whose
# temperature lies outside a temperature table (ThermalModel.lookup_range).
CLAMPED = ("pfp_distance", "pfw_distance", "temperature")

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


def memory_estimate(n_particles: int, n_elements: int, tables, shells: int = 0) -> int:
    """Bytes a run of ``n_particles`` against ``n_elements`` wall elements needs, ``tables`` included
    (and ``shells`` float64 shell enthalpies per particle when resolved)."""
    per_particle = _per_particle(shells)
    return n_particles * per_particle + n_elements * WALL_BYTES_PER_ELEMENT + _nbytes(tables)


def _per_particle(shells: int) -> int:
    return STEP_BYTES_PER_PARTICLE + FRAME_BYTES_PER_PARTICLE + 8 * shells


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
        frame = int(frozen.get("frame", 0))
        if not -dem.n_frames <= frame < dem.n_frames:
            raise ConfigError(f"thermal.frozen_bed.frame: {frame} is not a frame of the positions file ({dem.n_frames} frames)")
        times = frozen_times(frozen)
        axes = cls.of(dem, dem.n_frames)  # periodic for heat as in a flowing run; nothing is recycled
        return cls([frame % dem.n_frames] * times.size, times, axes.box_lo, axes.box_hi, axes.periodic, None, frozen=True)

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
    frames_by: dict = field(default_factory=lambda: dict.fromkeys(integrators.NAMES, 0))  # frames each integrator ran
    clamped: dict = field(default_factory=lambda: dict.fromkeys(CLAMPED, 0))  # look-ups clamped so far, by kind
    integrator: dict = field(default_factory=dict)  # the integrator's checkpoint, taken when the State is saved
    shells: np.ndarray | None = None  # (N, n) J/kg, shell enthalpies of resolved particles (mean: h)
    convected_energy: float = 0.0  # J received from the gas (thermal.convection) since the first frame

    @classmethod
    def initial(cls, model: ThermalModel, n: int) -> State:
        h0 = model.enthalpy.enthalpy(model.initial_temperature)[()]
        shells = np.full((n, model.shells.n), h0) if model.shells is not None else None
        return cls(0, np.full(n, h0), 0.0, 0.0, None, shells=shells)

    def particle_energy(self, model: ThermalModel) -> float:
        """Total particle enthalpy (J, relative to the enthalpy table's T0)."""
        return model.mass * math.fsum(self.h)


def recycle(model: ThermalModel, schedule: Schedule, state: State, positions: np.ndarray, image) -> None:
    """Reset particles that re-entered at the inlet since the last frame to the inlet temperature.

    A re-entry is a downward crossing of the recycled flow axis (from the image flags, or a jump of
    more than half the box); its enthalpy change is booked in ``state.recycled_energy``.
    """
    if state.previous is not None and schedule.flow_axis is not None:
        last_positions, last_image = state.previous
        crossed = integrate.wrapped(last_image, image, last_positions, positions, schedule.box_lo, schedule.box_hi,
                                    schedule.flow_axis)  # fmt: skip
        h_inlet = model.enthalpy.enthalpy(model.inlet_temperature)[()]
        state.recycled_energy += model.mass * float(np.sum(h_inlet - state.h[crossed]))
        state.h[crossed] = h_inlet
        if state.shells is not None:
            state.shells[crossed] = h_inlet
    state.previous = (positions, image)


def step(model: ThermalModel, schedule: Schedule, state: State, positions: np.ndarray, integrator,
         frame: integrate.Frame | None = None) -> tuple[Row, integrate.StepReport]:  # fmt: skip
    """Advance the enthalpies over the interval that starts at this frame (held fixed meanwhile)
    with ``integrator`` (see :mod:`dpht.thermal.integrators`); ``frame`` is the frame's prepared
    geometry when the caller keeps it (a frozen bed), else it is prepared from ``positions``.

    Returns the frame's output row and the integrator's report.
    """
    count = state.count
    energy_particles = state.particle_energy(model)
    if frame is None:
        frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    dt = schedule.interval(count)
    if model.wall_temperature_at is not None:  # a travelling slice: the wall where it is mid-interval
        model.element_temperature[:] = model.wall_temperature_at(schedule.times[count] + 0.5 * dt)
    report = integrator.advance(frame, state.h, dt, frame_number=schedule.frames[count],
                                **({} if state.shells is None else {"shells": state.shells}))  # fmt: skip
    integrate.check_finite(state.h[frame.particles], frame.particles, schedule.frames[count], report.substeps,
                           lambda i: f"enthalpy {float(state.h[frame.particles[i]])!r} J/kg after the {report.integrator} step")  # fmt: skip
    if report.substeps:
        state.frames_by[report.integrator] += 1
    lo, hi = model.lookup_range()
    outside = {**report.stats.get("clamped", {}),
               "temperature": int(np.count_nonzero((report.temperature < lo) | (report.temperature > hi)))}  # fmt: skip
    if any(outside.values()) and not any(state.clamped.values()):
        log.warning("thermal: frame %d has table look-ups outside their range, clamped to the table's edge "
                    "(%s; counted in the summary's clamped_lookups)", schedule.frames[count],
                    ", ".join(f"{k} {v}" for k, v in outside.items()))  # fmt: skip
    for key, value in outside.items():
        state.clamped[key] += value
    temperature = np.full(state.h.size, np.nan, dtype=np.float32)  # lost particles stay NaN
    temperature[frame.particles] = report.temperature
    row = Row(schedule.times[count], temperature, report.element_heat, report.substeps, energy_particles,
              state.wall_energy, state.recycled_energy, state.convected_energy)  # fmt: skip
    state.wall_energy += dt * math.fsum(report.element_heat.ravel())
    state.convected_energy += report.convected
    state.count += 1
    return row, report


def decide_intraparticle(model: ThermalModel, schedule: Schedule, positions: np.ndarray) -> tuple[ThermalModel, dict]:
    """The model with or without shells, and the record of why (logged, and kept in the summary).

    ``thermal.intraparticle: auto`` resolves the particles when the largest Biot number on the first
    frame ``positions`` exceeds ``thermal.biot_threshold`` (ParScale: Bi_crit ~ 0.1, ~0.01 in dense
    beds). The conductances are those at the scene's hottest temperature (initial, inlet, walls,
    the gas of ``thermal.convection``), where radiation makes them largest; all enabled modes count
    (:func:`integrate.biot_numbers`).
    """
    record = {"switch": model.intraparticle, "shells": model.shell_count, "threshold": model.biot_threshold}
    if model.intraparticle != "auto":
        record.update(resolved=model.shells is not None, reason="set in the config")
        return model, record
    frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    wall = model.element_temperature[np.isfinite(model.element_temperature)]
    gas = [model.convection.gas_temperature] if model.convection.coefficient > 0.0 else []
    T_max = float(max(model.initial_temperature, model.inlet_temperature, *wall.tolist(), *gas))
    bi, k_p = integrate.biot_numbers(model, frame, T_max)
    largest = float(bi.max()) if bi.size else 0.0
    on = largest > model.biot_threshold
    record.update(resolved=on, biot_max=largest, biot_median=float(np.median(bi)) if bi.size else 0.0,
                  fraction_above=float(np.mean(bi > model.biot_threshold)) if bi.size else 0.0, at_K=T_max,
                  k_particle_W_mK=k_p)  # fmt: skip
    record["reason"] = (
        f"Bi up to {largest:.3g} (median {record['biot_median']:.3g}; {record['fraction_above']:.1%} of "
        f"{bi.size} particles above {model.biot_threshold:g}) on frame {schedule.frames[0]} at T_max = {T_max:.0f} K, "
        f"Bi = G d_p / (pi d_p^2 k_p) from the summed surface conductances G, k_p = {k_p:.3g} W/(m K), "
        f"d_p = {2 * model.radius:.3g} m"
    )  # fmt: skip
    log.info("thermal.intraparticle auto: %s (%s)", f"resolved, {model.shell_count} shells" if on else "uniform particles",
             record["reason"])  # fmt: skip
    return (thermal_model.resolved(model) if on else model), record


def reproducible(result: dict) -> dict:
    """A run's summary without what differs between runs of the same inputs: the wall times and
    the thread count (the run's and its error estimate's)."""
    out = {k: v for k, v in result.items() if k not in ("seconds", "threads")}
    if out.get("error_estimate"):
        out["error_estimate"] = {k: v for k, v in out["error_estimate"].items() if k not in ("seconds", "cost_fraction")}
    return out


def summary(schedule: Schedule, state: State, wall_heat_last: np.ndarray, seconds: float, integrator=None) -> dict:
    """The run's summary: totals (J), the wall heat per PW mode at the last frame (W), the
    integrator (requested, frames run by each, auto's decisions), look-ups clamped, the cost."""
    return {
        "frames": len(schedule.frames),
        "particles": int(state.h.size),
        "wall_energy_J": state.wall_energy,
        "recycled_energy_J": state.recycled_energy,
        "convected_energy_J": state.convected_energy,
        "wall_heat_last_W": dict(zip(PW_MODES, wall_heat_last.tolist())),
        "integrator": integrators.summary(integrator, state.frames_by) if integrator is not None else None,
        "clamped_lookups": dict(state.clamped),
        "frozen_bed": schedule.frozen,
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
                    shells = f["shells"][...] if "shells" in f else None
                    if (shells is None) == (model.shells is None):  # the same decision of auto as before
                        carried = {}

                        def read(key, item):
                            if isinstance(item, h5py.Dataset):
                                carried[key] = item[...]

                        f["integrator"].visititems(read)
                        frames_by, clamped = json.loads(f.attrs["carried"])
                        state = State(int(f.attrs["count"]), f["h"][...], float(f.attrs["wall_energy"]),
                                      float(f.attrs["recycled_energy"]), previous, shells=shells,
                                      convected_energy=float(f.attrs["convected_energy"]), frames_by=frames_by,
                                      clamped=clamped, integrator={**json.loads(f.attrs["integrator"]), **carried})  # fmt: skip
                        seconds = float(f.attrs["seconds"])
                    else:
                        segments = []
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
            if state.shells is not None:
                f.create_dataset("shells", data=state.shells)
            if state.previous is not None:
                f.create_dataset("previous_positions", data=state.previous[0])
                f.create_dataset("previous_image", data=state.previous[1])
            arrays = {k: v for k, v in state.integrator.items() if isinstance(v, np.ndarray)}
            group = f.create_group("integrator")  # arrays at their keys ("implicit/amg_T"), the rest in JSON
            for key, value in arrays.items():
                group.create_dataset(key, data=value)
            f.attrs.update(fingerprint=self.fingerprint, count=state.count, wall_energy=state.wall_energy,
                           recycled_energy=state.recycled_energy, convected_energy=state.convected_energy,
                           segments=json.dumps(segments), seconds=seconds, carried=json.dumps([state.frames_by, state.clamped]),
                           integrator=json.dumps({k: v for k, v in state.integrator.items() if k not in arrays}))  # fmt: skip

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
    """Digest of what a thermal run computes from: the spec, the positions file's frame data (read
    and hashed here: a stored digest would not see frames changed in place) and the bytes of the
    other input files."""
    h = hashlib.sha256(json.dumps(spec, sort_keys=True).encode())
    with h5py.File(positions_h5, "r") as dem:
        h.update(content_digest(dem).encode())
    for path in [p for p in inputs if p is not None]:
        with open(path, "rb") as stream:
            h.update(hashlib.file_digest(stream, "sha256").digest())
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
    dem_summary=None,
    workdir=None,
    checkpoints: Checkpoints = Checkpoints(),
) -> dict:
    """Run the thermal stage of one scene and return a summary (also stored in the output's attrs).

    ``spec`` is :func:`dpht.config.thermal_spec` of the config; ``htc_tables`` maps "pfp"/"pfw" to
    table files; ``rdf_table`` is the RDF table file (or list of files, interpolated to the
    config's emissivities) when radiation is enabled; ``dem_summary`` the DEM run's summary file
    (``results/dem/<key>/summary.json``; by default the copy in the positions file), which gives
    measured solid fractions and the wall surfaces LIGGGHTS used. ``workdir`` (default: ``<out_h5
    stem>.work`` next to it) holds the checkpoints and the complete output, which ``out_h5`` is a
    hard link to; a run interrupted at any point continues from its last checkpoint, and a run of
    inputs whose output is complete there only publishes it.
    """
    effects.check_decided(spec["thermal"])  # before anything is written
    integrators.check_intraparticle(spec["thermal"])
    out_h5 = Path(out_h5)
    rdf_paths = [rdf_table] if isinstance(rdf_table, (str, Path)) else list(rdf_table or [])
    inputs = [walls_h5, *(htc_tables[k] for k in sorted(htc_tables)), *rdf_paths]
    dem_run = DemRun.of(positions_h5, dem_summary)
    work = WorkDir(workdir if workdir is not None else out_h5.with_name(out_h5.stem + ".work"),
                   fingerprint({**spec, "dem_run": dem_run.used()}, positions_h5, inputs))  # fmt: skip
    with WorkdirLock(work.folder, LOCK, "thermal"):
        result = work.complete()
        if result is not None:
            log.info("thermal: %s is the complete %s of an earlier run of these inputs", out_h5, work.final)
            work.clear()
        else:
            result = _compute(spec, positions_h5, dem_run, walls_h5, htc_tables, rdf_table, work, threads, checkpoints)
        if xdmf:  # in the output's folder, so its relative paths hold for the final name
            with PositionsFile(positions_h5) as dem, replacing(xdmf) as tmp:
                schedule = Schedule.of_spec(dem, spec["thermal"])
                write_xdmf(tmp, out_h5, positions_h5, frames=schedule.frames, n_dem_frames=dem.n_frames,
                           n_particles=dem.n_particles, times=schedule.times,
                           precision=dem.frame(0).positions.dtype.itemsize)  # fmt: skip
        publish(work.final, out_h5)
    return result


@dataclass(frozen=True)
class DemRun:
    """What the stage reads from the DEM run besides its frames: its summary (``source`` names the
    file) and the positions file's ``recycled`` axes."""

    summary: dict
    source: str
    recycled: list | None

    @classmethod
    def of(cls, positions_h5, dem_summary=None) -> DemRun:
        """From ``dem_summary`` (a DEM run's ``summary.json``), or the copy in the positions file."""
        with PositionsFile(positions_h5) as dem:
            recycled = dem.attrs.get("recycled")
            recycled = None if recycled is None else np.asarray(recycled, dtype=bool).tolist()
            if dem_summary is None:
                return cls(dem.summary, f"{positions_h5} (its DEM summary)", recycled)
        return cls(json.loads(Path(dem_summary).read_text()), str(dem_summary), recycled)

    def crossings(self, positions_h5) -> int:
        """Particles whose image along the recycled axis differs between the first and the last
        frame of the positions file: they crossed it (0 without a recycled axis)."""
        if not self.recycled or not any(self.recycled):
            return 0
        axis = self.recycled.index(True)
        with PositionsFile(positions_h5) as dem:  # rows are particles, the same in every frame
            first, last = dem.frame(0), dem.frame(dem.n_frames - 1)
            return int(np.count_nonzero(first.image[:, axis] != last.image[:, axis]))

    def used(self) -> dict:
        """The part of it a run's result depends on (for the checkpoints' fingerprint: not the
        summary's wall times, which differ between DEM runs of the same frames)."""
        solid = self.summary.get("solid_fraction") or {}
        return {"solid_fraction": {k: solid.get(k) for k in ("flowing", "per_frame")}, "walls": self.summary.get("walls"),
                "recycled": self.recycled}  # fmt: skip


def _compute(spec, positions_h5, dem_run: DemRun, walls_h5, htc_tables, rdf_table, work: WorkDir, threads,
             checkpoints: Checkpoints) -> dict:  # fmt: skip
    """Compute the run's rows from the last checkpoint on, then assemble ``work.final``::

        setup = Setup.of(...)     schedule, model (solid fractions, shells), integrator
        resume(...)               the last checkpoint's State and segments, or the initial State
        for each frame on:        recycle, step, write; a checkpoint when one is due
        assemble(...)             the segments' rows into thermal.h5, the summary, the error estimate
    """
    if threads:
        numba.set_num_threads(threads)
    walls = load_walls(walls_h5)
    tables = {kind: htc.load_table(path) for kind, path in htc_tables.items()}
    rdf_tables = _rdf_tables(rdf_table, spec) if rdf_table else None
    with PositionsFile(positions_h5) as dem:
        setup = Setup.of(spec, dem, dem_run, walls, tables, rdf_tables)
        started = time.perf_counter()
        _log_memory(setup, dem.n_particles)
        state, segments, seconds_before = resume(setup, work, dem.n_particles)

        def elapsed() -> float:  # s of computing, this run's and those before its checkpoint
            return seconds_before + time.perf_counter() - started

        attrs = setup.output_attrs(positions_h5)
        out = Segments(work, segments, ids=dem.ids, dem_frames=setup.schedule.frames, n_elements=setup.n_elements,
                       attrs=attrs, rows=checkpoints.frames, minutes=checkpoints.minutes)  # fmt: skip
        try:
            advance_frames(setup, dem, state, out, elapsed)
        except integrate.NonFiniteTemperature as error:
            raise DPHTError(f"{positions_h5}: {error} Its DEM id is {int(dem.ids[error.particle])}.") from None
        result = assemble(setup, dem, work, state, out.done, attrs, elapsed)
    log.info("thermal: %d frames of %d particles in %.1f s", len(setup.schedule.frames), dem.n_particles, result["seconds"])
    return result


@dataclass
class Setup:
    """What the frame loop works with, from the stage's inputs: the spec with its measured solid
    fractions resolved, the schedule, the model (resolved particles or not), the integrator, the
    tables, and the records of the solid fractions and the intra-particle decision for the summary."""

    spec: dict
    schedule: Schedule
    model: ThermalModel
    integrator: object  # of dpht.thermal.integrators
    tables: dict  # HTC tables by kind (pfp, pfw)
    rdf_tables: rdf.RDFTables | None
    n_elements: int  # wall elements
    solid_fraction: dict
    intraparticle: dict

    @classmethod
    def of(cls, spec: dict, dem: PositionsFile, dem_run: DemRun, walls, tables: dict, rdf_tables) -> Setup:
        schedule = Schedule.of_spec(dem, spec["thermal"])
        spec, solid_fraction = resolve_solid_fractions(spec, dem_run.summary, dem_run.source, schedule.frames, rdf_tables)
        model = thermal_model.build(spec, walls, tables, rdf_tables, wall_kinds(dem_run.summary, dem_run.source, walls))
        model, intraparticle = decide_intraparticle(model, schedule, np.asarray(dem.frame(schedule.frames[0]).positions,
                                                                                 dtype=np.float64))  # fmt: skip
        t = spec["thermal"]
        integrator = integrators.create(t.get("integrator", integrators.AUTO), model, t)
        return cls(spec, schedule, model, integrator, tables, rdf_tables, len(walls.area), solid_fraction, intraparticle)

    def output_attrs(self, positions_h5) -> dict:
        """The attributes of thermal.h5 and of its segments."""
        return {
            "modes": json.dumps(sorted(self.model.modes)),
            "inlet_temperature": self.model.inlet_temperature,
            "positions": str(Path(positions_h5).name),
            "spec": json.dumps(self.spec, sort_keys=True),
        }


def _log_memory(setup: Setup, n: int) -> None:
    """Log the run's memory estimate (:func:`memory_estimate`)."""
    model, tables = setup.model, [setup.tables, setup.rdf_tables]
    n_shells = model.shells.n if model.shells is not None else 0
    needed = memory_estimate(n, setup.n_elements, tables, n_shells)
    log.info(
        "thermal: memory estimate %.3g MB: %d particles x %d B, %d wall elements x %d B, tables %.3g MB "
        "(frames are read one at a time)",
        needed / 1e6, n, _per_particle(n_shells), setup.n_elements, WALL_BYTES_PER_ELEMENT, _nbytes(tables) / 1e6,
    )  # fmt: skip


def resume(setup: Setup, work: WorkDir, n: int) -> tuple[State, list[tuple[int, int]], float]:
    """The State, segments and computing time (s) of the last checkpoint in ``work`` (or the
    initial State of ``n`` particles, :meth:`WorkDir.restore`), with the integrator given back
    what it carried then; says where the run continues."""
    state, segments, seconds = work.restore(setup.model, n)
    if state.integrator:
        setup.integrator.restore(state.integrator)
    if state.count:
        log.info("thermal: resuming from the checkpoint after frame %d of %d in %s", state.count, len(setup.schedule.frames),
                 work.folder)  # fmt: skip
    return state, segments, seconds


def frames_from(dem: PositionsFile, schedule: Schedule, model: ThermalModel, start: int):
    """``(count, positions, image flags, frame)`` of every thermal frame from ``start`` on: the
    positions (m, float64) of its DEM frame and, for a frozen bed, its geometry prepared once for
    the whole run (else None: :func:`step` prepares each frame)."""
    frame = None
    for count in range(start, len(schedule.frames)):
        if frame is None or not schedule.frozen:
            current = dem.frame(schedule.frames[count])
            positions = np.asarray(current.positions, dtype=np.float64)
            if schedule.frozen:
                frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
        yield count, positions, current.image, frame


def advance_frames(setup: Setup, dem: PositionsFile, state: State, out: Segments, elapsed) -> None:
    """The loop of the module docstring from ``state.count`` to the last frame: recycle, step,
    write, and a checkpoint whenever one is due; a signal stops the run after its frame, saved.
    ``elapsed()`` is the run's computing time so far (s)."""
    model, schedule = setup.model, setup.schedule
    progress = Progress("thermal", len(schedule.frames), unit="particle-steps", start=state.count)
    with processes.deferred_signals() as interrupted, out:
        for count, positions, image, frame in frames_from(dem, schedule, model, state.count):
            recycle(model, schedule, state, positions, image)
            row, report = step(model, schedule, state, positions, setup.integrator, frame)
            out.write(count, row)
            progress.update(count + 1, work=report.temperature.size * max(report.substeps, 1))
            if out.due(state.count, interrupted.signal):
                state.integrator = setup.integrator.checkpoint()
                out.checkpoint(state, elapsed())
            interrupted.stop_if_asked()


def assemble(setup: Setup, dem: PositionsFile, work: WorkDir, state: State, segments: list, attrs: dict, elapsed) -> dict:
    """Copy the rows of ``segments`` into ``work.final`` with the run's summary and error estimate
    (returned), then remove the segments and the checkpoint."""
    schedule = setup.schedule
    with replacing(work.final) as tmp:
        final = ThermalWriter(tmp, ids=dem.ids, dem_frames=schedule.frames, n_elements=setup.n_elements, attrs=attrs)
        for first, rows in segments:
            final.copy_rows(work.segment(first), first, rows)
        wall_heat_last = final.file["wall_heat"][-1]
        result = {**summary(schedule, state, wall_heat_last, elapsed(), setup.integrator),
                  "solid_fraction": setup.solid_fraction, "intraparticle": setup.intraparticle}  # fmt: skip
        result["error_estimate"] = estimate_errors(setup.model, schedule, dem, final.file, setup.spec, setup.tables,
                                                   setup.rdf_tables, result)  # fmt: skip
        final.file.attrs["fingerprint"] = work.fingerprint
        final.finish(result)
    work.clear()
    return result


SEGMENT_FORMAT = "dpht-thermal-segment-1"  # the output's layout, with rows 0..rows-1 of frames first..


class Segments:
    """The rows of a run, written into *segment* files of the work directory (module docstring):
    one is open from its first row until a checkpoint is due (``rows`` rows written, ``minutes``
    of computing since it opened, or a signal), then closed with the State after its rows saved.
    ``done`` lists the closed segments, ``(first frame, rows)``; as a context, a segment left open
    by an error is removed (its rows are lost, the checkpoint before them stays)."""

    def __init__(self, work: WorkDir, done: list, *, ids, dem_frames, n_elements: int, attrs: dict, rows: int, minutes: float):
        self.work, self.done, self.rows, self.minutes = work, done, rows, minutes
        self.ids, self.dem_frames, self.n_elements, self.attrs = ids, dem_frames, n_elements, attrs
        self.writer, self.first, self.opened = None, None, time.monotonic()

    def write(self, count: int, row: Row) -> None:
        """Write the row of thermal frame ``count``, opening a segment at it if none is open."""
        if self.writer is None:
            self.first = count
            self.writer = ThermalWriter(partial_path(self.work.segment(count)), ids=self.ids, n_elements=self.n_elements,
                                        dem_frames=self.dem_frames[count : count + self.rows], attrs=self.attrs)  # fmt: skip
        self.writer.write(count - self.first, row)

    def due(self, count: int, signal) -> bool:
        """Whether a checkpoint is due after the rows up to ``count`` (exclusive)."""
        full = count - self.first == self.writer.file["time"].shape[0]
        return bool(full or signal or time.monotonic() - self.opened >= 60.0 * self.minutes)

    def checkpoint(self, state: State, seconds: float) -> None:
        """Close the open segment (complete as a segment, under its name) and save ``state``, the
        State after its rows, with the list of segments and the computing time (s)."""
        rows = state.count - self.first
        self.writer.file.attrs.update(format=SEGMENT_FORMAT, first=self.first, rows=rows, complete=True)
        self.writer.close()
        self.writer.path.replace(self.work.segment(self.first))
        self.done.append((self.first, rows))
        self.work.save(state, self.done, seconds)
        self.writer, self.opened = None, time.monotonic()

    def __enter__(self) -> Segments:
        return self

    def __exit__(self, *exc) -> None:
        if self.writer is not None:  # an error or a second signal: the rows since the checkpoint are lost
            self.writer.close()
            self.writer.path.unlink(missing_ok=True)
            self.writer = None


def wall_kinds(run_summary: dict, source: str, walls) -> dict | None:
    """The surface LIGGGHTS collided particles with per wall zone ("primitive" or "mesh"), from the
    DEM run's summary (read from ``source``); None (meshes) for positions not written by a DEM run
    (no summary) when the wall table has no primitives to choose from."""
    kinds = run_summary.get("walls")
    if kinds is None and walls.primitives:
        raise DPHTError(
            f"{source}: the DEM summary does not record which wall zones LIGGGHTS used as exact primitives and "
            f"which as meshes (key 'walls', recorded since DEM report format {DEM_REPORT_FORMAT!r}): re-run the DEM stage"
        )
    return kinds


# Largest standard deviation of the DEM run's per-frame solid fraction over the thermal frames before
# the stage warns that one value does not describe the bed of the whole run.
SOLID_FRACTION_SPREAD = 0.02


def resolve_solid_fractions(spec: dict, run_summary: dict, source: str, frames, rdf_tables=None) -> tuple[dict, dict]:
    """``spec`` with numbers for measured solid fractions (DPHT paper Eq. 13 and the RDF look-ups:
    the bulk for the particle-particle modes, the near-wall band for the particle-wall modes),
    and the record of each region for the summary: value, source (``config``, or the DEM summary
    ``source`` and the frames it averaged), and the mean and spread of the DEM run's per-frame
    values over this run's ``frames``. A measured value outside an enabled radiation mode's RDF
    table, or outside (0, 0.75), stops the run before it starts; a spread above
    :data:`SOLID_FRACTION_SPREAD` in a region an enabled mode reads is logged as a warning."""
    t = spec["thermal"]
    over = solid_fraction_over(run_summary, frames)
    used = {registry.BY_NAME[m].region for m in registry.enabled(t["modes"])}
    values, record = {}, {}
    for region, value in registry.solid_fractions(t["solid_fraction"]).items():
        key = f"thermal.solid_fraction.{region}" if isinstance(t["solid_fraction"], dict) else "thermal.solid_fraction"
        if registry.is_measured(value):
            values[region] = measured_solid_fraction(run_summary, region, source)
            flowing = run_summary["solid_fraction"]["flowing"]
            record[region] = {"value": values[region], "source": f"{source}: solid_fraction.flowing.{region}",
                              "dem_frames": flowing.get("frames")}  # fmt: skip
            _check_measured(key, values[region], region, source, t["modes"], rdf_tables)
        else:
            values[region] = value
            record[region] = {"value": value, "source": "config"}
        if region in over:
            record[region]["thermal_frames"] = {**over[region], "frames": [int(frames[0]), int(frames[-1])]}
            if region in used and over[region]["std"] > SOLID_FRACTION_SPREAD:
                log.warning(
                    "thermal: warning: the DEM run's %s solid fraction varies over the thermal frames %d-%d (mean %.4f, "
                    "standard deviation %.4f > %.2f), but one value (%.4f) is used for the whole run (%s)", region,
                    frames[0], frames[-1], over[region]["mean"], over[region]["std"], SOLID_FRACTION_SPREAD, values[region],
                    record[region]["source"],
                )  # fmt: skip
    return {**spec, "thermal": {**t, "solid_fraction": values}}, record


def _check_measured(key: str, value: float, region: str, source: str, switches: dict, rdf_tables) -> None:
    """A measured solid fraction must be one the closures (Eq. 13) and the RDF tables accept."""
    where = f"{key} = measured: the DEM run measured {value:.4f} ({source})"
    if not 0.0 < value < 0.75:
        raise ConfigError(f"{where}, outside (0, 0.75); give the solid fraction as a number")
    for mode in registry.MODES:
        if mode.region == region and mode.table and mode.table[0] == "rdf" and switches.get(mode.name) and rdf_tables is not None:
            grid = getattr(rdf_tables, mode.table[1]).solid_fraction
            if not grid[0] <= value <= grid[-1]:
                raise ConfigError(
                    f"{where}, outside the {mode.table[1].upper()} RDF table's solid fractions {grid[0]}-{grid[-1]} "
                    f"({mode.name}); give the solid fraction as a number or use a table that covers it"
                )


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
        coarse = _rerun(model, schedule, dem, out["temperature"][k0 - 1], k0, half, spec)
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


def _rerun(model: ThermalModel, schedule: Schedule, dem: PositionsFile, temperature, k0: int, m: int, spec: dict) -> np.ndarray:
    """Wall heat (J per PW mode) of thermal frames k0 to k0 + 2m re-run with every other frame (twice
    the step) by a fresh integrator of the run's kind, from the run's temperatures at the start of
    frame k0 (``temperature``, before its resets)."""
    frames = schedule.frames[k0:k0 + 2 * m + 1:2]
    coarse = replace(schedule, frames=frames, times=schedule.times[k0:k0 + 2 * m + 1:2])
    last = dem.frame(schedule.frames[k0 - 1])
    h = model.enthalpy.enthalpy(np.where(np.isfinite(temperature), temperature, model.inlet_temperature))
    integrator = integrators.create(spec["thermal"].get("integrator", integrators.AUTO), model, spec["thermal"])
    h = np.asarray(h, dtype=np.float64)
    shells = np.repeat(h[:, None], model.shells.n, axis=1) if model.shells is not None else None  # uniform at the start
    state = State(0, h, 0.0, 0.0, (np.asarray(last.positions, dtype=np.float64), last.image), shells=shells)
    heat = np.zeros(len(PW_MODES))
    for j in range(m):
        current = dem.frame(frames[j])
        positions = np.asarray(current.positions, dtype=np.float64)
        recycle(model, coarse, state, positions, current.image)
        row, _ = step(model, coarse, state, positions, integrator)
        heat += coarse.interval(j) * row.element_heat.sum(axis=0)
    return heat


def _rdf_tables(paths, spec) -> rdf.RDFTables:
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    return rdf.for_emissivities([rdf.load(p) for p in paths], spec["particles"]["emissivity"], spec["wall"]["emissivity"])
