"""The thermal stage: stream DEM frames, advance particle enthalpies, write the thermal output.

I/O lives here; the physics is in :mod:`dpht.thermal.model`, :mod:`dpht.thermal.kernels` and
:mod:`dpht.thermal.integrate`. Memory stays bounded by one frame whatever the run length: frames
are read one at a time and results written as they are computed.

:func:`run` is a loop of named steps over the frames of a :class:`~dpht.thermal.schedule.Schedule`
(:func:`advance_frames`), and everything carried from one frame to the next is one
:class:`~dpht.thermal.state.State` (enthalpies, energy bookkeeping, the previous frame for
recycling), so the state after any frame plus the rows written so far is the whole run::

    setup = Setup.of(...)       schedule, model (decisions: solid fractions, shells), integrator
    state = resume(...)         State.initial(model, n), or restored from a checkpoint
    for each frame from state.count on:         (frames_from)
        recycle(...)          reset particles re-entering at the inlet, book the energy
        row = step(...)       advance the enthalpies over the frame's interval
        out.write(row)        into the open segment (Segments); a checkpoint when one is due
    assemble(...)             the rows into thermal.h5, with summary(...) and the error estimate

The pieces live beside it: the frames in :mod:`dpht.thermal.schedule`, the State, ``recycle`` and
``step`` in :mod:`dpht.thermal.state`, the work directory, segments and checkpoints in
:mod:`dpht.thermal.checkpoint`, what is decided before the first step (measured solid fractions,
wall surfaces, resolved intra-particle conduction) in :mod:`dpht.thermal.decisions`, and the
run's error estimate in :mod:`dpht.thermal.estimates`.

Resuming a run means restoring a State and the rows written before it, then continuing the loop.
:func:`~dpht.thermal.state.step` makes the one call of the time integrator
(``thermal.integrator``, from the registry :mod:`dpht.thermal.integrators`; ``auto`` chooses per
frame); what the integrator carries from frame to frame is its checkpoint (:meth:`checkpoint`),
saved with the State.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from dpht.closures import htc, rdf
from dpht.dem.dumps import PositionsFile
from dpht.errors import DPHTError
from dpht.thermal import effects, integrate, integrators, model as thermal_model
from dpht.thermal.checkpoint import LOCK, Checkpoints, Segments, WorkDir, fingerprint
from dpht.thermal.decisions import DemRun, decide_intraparticle, resolve_solid_fractions, wall_kinds
from dpht.thermal.estimates import estimate_errors
from dpht.thermal.inflow import Inflow, node_enthalpies
from dpht.thermal.model import ThermalModel
from dpht.thermal.modes import PW_MODES
from dpht.chain import outlet as outlet_record
from dpht.thermal import outlet as outlet_journal
from dpht.thermal.output import ThermalWriter, write_xdmf
from dpht.thermal.schedule import Schedule
from dpht.thermal.state import State, recycle, step
from dpht.util import processes
from dpht.util.files import WorkdirLock, publish, replacing
from dpht.util.progress import Progress
from dpht.geometry.walls import load_walls

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


def memory_estimate(n_particles: int, n_elements: int, tables, shells: int = 0) -> int:
    """Bytes a run of ``n_particles`` against ``n_elements`` wall elements needs, ``tables`` included
    (and ``shells`` float64 shell enthalpies per particle when resolved)."""
    per_particle = _per_particle(shells)
    return n_particles * per_particle + n_elements * WALL_BYTES_PER_ELEMENT + _nbytes(tables)


def _per_particle(shells: int) -> int:
    return STEP_BYTES_PER_PARTICLE + FRAME_BYTES_PER_PARTICLE + 8 * shells


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
    initial_field=None,
    inlet_field=None,
    outlet: outlet_record.Outlet | None = None,
    inlet_plane: float | None = None,
) -> dict:
    """Run the thermal stage of one scene and return a summary (also stored in the output's attrs).

    ``spec`` is :func:`dpht.config.thermal_spec` of the config; ``htc_tables`` maps "pfp"/"pfw" to
    table files; ``rdf_table`` is the RDF table file (or list of files, interpolated to the
    config's emissivities) when radiation is enabled; ``dem_summary`` the DEM run's summary file
    (``results/dem/<key>/summary.json``; by default the copy in the positions file), which gives
    measured solid fractions and the wall surfaces LIGGGHTS used. ``workdir`` (default: ``<out_h5
    stem>.work`` next to it) holds the checkpoints and the complete output, which ``out_h5`` is a
    copy of; a run interrupted at any point continues from its last checkpoint, and a run of
    inputs whose output is complete there only publishes it. ``initial_field`` and ``inlet_field``
    are hand-over field files of the segment upstream in a chain (:mod:`dpht.thermal.inflow`);
    ``outlet`` asks for the record of what leaves the run in float64 (:mod:`dpht.chain.outlet`);
    ``inlet_plane`` (m) is where the inlet field is given (:class:`dpht.thermal.inflow.Inflow`).
    """
    effects.check_decided(spec["thermal"])  # before anything is written
    integrators.check_intraparticle(spec["thermal"])
    out_h5 = Path(out_h5)
    rdf_paths = [rdf_table] if isinstance(rdf_table, (str, Path)) else list(rdf_table or [])
    inputs = [walls_h5, *(htc_tables[k] for k in sorted(htc_tables)), *rdf_paths, initial_field, inlet_field]
    dem_run = DemRun.of(positions_h5, dem_summary)
    asked = outlet.key() if outlet is not None else {}  # a run without them keeps its fingerprint
    if inlet_plane is not None:
        asked["inlet_plane"] = float(inlet_plane)
    work = WorkDir(workdir if workdir is not None else out_h5.with_name(out_h5.stem + ".work"),
                   fingerprint({**spec, "dem_run": dem_run.used(), **asked}, positions_h5, inputs))  # fmt: skip
    with WorkdirLock(work.folder, LOCK, "thermal"):
        result = work.complete()
        if result is not None:
            log.info("thermal: %s is the complete %s of an earlier run of these inputs", out_h5, work.final)
            work.clear()
            outlet_journal.journal_path(work.folder).unlink(missing_ok=True)
        else:
            inflow = Inflow.of(initial_field, inlet_field, inlet_plane)
            result = _compute(spec, positions_h5, dem_run, walls_h5, htc_tables, rdf_table, work, threads, checkpoints, inflow,
                              outlet)  # fmt: skip
        if xdmf:  # in the output's folder, so its relative paths hold for the final name
            with PositionsFile(positions_h5) as dem, replacing(xdmf) as tmp:
                schedule = Schedule.of_spec(dem, spec["thermal"])
                write_xdmf(tmp, out_h5, positions_h5, frames=schedule.frames, n_dem_frames=dem.n_frames,
                           n_particles=dem.n_particles, times=schedule.times,
                           precision=dem.frame(0).positions.dtype.itemsize)  # fmt: skip
        publish(work.final, out_h5)
    return result


def _compute(spec, positions_h5, dem_run: DemRun, walls_h5, htc_tables, rdf_table, work: WorkDir, threads,
             checkpoints: Checkpoints, inflow: Inflow | None = None,
             outlet: outlet_record.Outlet | None = None) -> dict:  # fmt: skip
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
        setup = Setup.of(spec, dem, dem_run, walls, tables, rdf_tables, inflow)
        started = time.perf_counter()
        _log_memory(setup, dem.n_particles)
        state, segments, seconds_before = resume(setup, work, dem.n_particles)
        journal = None
        if outlet is not None and outlet.plane is not None:  # the crossings of its outlet plane, as they happen
            schedule = setup.schedule
            journal = outlet_journal.Journal(outlet_journal.journal_path(work.folder), outlet.plane,
                                            schedule.box_hi[2] - schedule.box_lo[2],
                                            setup.model.shells.n if state.shells is not None else 0, state.count)  # fmt: skip

        def elapsed() -> float:  # s of computing, this run's and those before its checkpoint
            return seconds_before + time.perf_counter() - started

        attrs = setup.output_attrs(positions_h5)
        out = Segments(work, segments, ids=dem.ids, dem_frames=setup.schedule.frames, n_elements=setup.n_elements,
                       attrs=attrs, rows=checkpoints.frames, minutes=checkpoints.minutes)  # fmt: skip
        try:
            advance_frames(setup, dem, state, out, elapsed, journal)
        except integrate.NonFiniteTemperature as error:
            raise DPHTError(f"{positions_h5}: {error} Its DEM id is {int(dem.ids[error.particle])}.") from None
        finally:
            if journal is not None:
                journal.close()
        leaving = _outlet(setup, dem, state, journal) if outlet is not None else None
        result = assemble(setup, dem, work, state, out.done, attrs, elapsed, leaving)
        if journal is not None:
            journal.close(remove=True)
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
    inflow: Inflow | None = None  # the hand-over fields of the segment upstream (dpht.thermal.inflow)
    started: tuple | None = None  # (particles placed, dpht.chain.field.Handed) of the initial field

    @classmethod
    def of(cls, spec: dict, dem: PositionsFile, dem_run: DemRun, walls, tables: dict, rdf_tables,
           inflow: Inflow | None = None) -> Setup:  # fmt: skip
        schedule = Schedule.of_spec(dem, spec["thermal"])
        spec, solid_fraction = resolve_solid_fractions(spec, dem_run.summary, dem_run.source, schedule.frames, rdf_tables)
        model = thermal_model.build(spec, walls, tables, rdf_tables, wall_kinds(dem_run.summary, dem_run.source, walls))
        first = np.asarray(dem.frame(schedule.frames[0]).positions, dtype=np.float64)
        model, intraparticle = decide_intraparticle(model, schedule, first)
        t = spec["thermal"]
        integrator = integrators.create(integrators.requested(t), model, t)
        if inflow is not None:
            inflow.check(model)
        started = inflow.start(model, first) if inflow is not None else None
        return cls(spec, schedule, model, integrator, tables, rdf_tables, len(walls.area), solid_fraction, intraparticle,
                   inflow, started)  # fmt: skip

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
    if state.count == 0 and setup.started is not None:  # the first frame's particles from the initial field
        placed, handed = setup.started
        state.h[placed] = handed.enthalpy[:, 0]
        if state.shells is not None:
            state.shells[placed] = node_enthalpies(setup.model, handed.enthalpy)
    if state.integrator:
        setup.integrator.restore(state.integrator)
    if state.count:
        log.info("thermal: resuming from the checkpoint after frame %d of %d in %s", state.count, len(setup.schedule.frames),
                 work.folder)  # fmt: skip
    return state, segments, seconds


def frames_from(dem: PositionsFile, schedule: Schedule, model: ThermalModel, start: int):
    """``(count, positions, image flags, frame)`` of every thermal frame from ``start`` on: the
    positions (m, float64) of its DEM frame and, for a frozen bed, its geometry prepared once for
    the whole run, frame 0's whatever ``start`` (else None: :func:`step` prepares each frame)."""
    frame = None
    for count in range(start, len(schedule.frames)):
        if frame is None or not schedule.frozen:
            current = dem.frame(schedule.frames[count])
            positions = np.asarray(current.positions, dtype=np.float64)
            if schedule.frozen:
                frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic, key=0)
        yield count, positions, current.image, frame


def advance_frames(setup: Setup, dem: PositionsFile, state: State, out: Segments, elapsed,
                   journal: outlet_journal.Journal | None = None) -> None:  # fmt: skip
    """The loop of the module docstring from ``state.count`` to the last frame: recycle, step,
    write, and a checkpoint whenever one is due; a signal stops the run after its frame, saved.
    ``elapsed()`` is the run's computing time so far (s); ``journal`` records the crossings."""
    model, schedule = setup.model, setup.schedule
    progress = Progress("thermal", len(schedule.frames), unit="particle-steps", start=state.count)
    with processes.deferred_signals() as interrupted, out:
        for count, positions, image, frame in frames_from(dem, schedule, model, state.count):
            if journal is not None:  # before recycle resets the particles re-entering
                journal.observe(count, None if state.previous is None else state.previous[0], positions, state.h,
                                state.shells)  # fmt: skip
            recycle(model, schedule, state, positions, image, setup.inflow)
            row, report = step(model, schedule, state, positions, setup.integrator, frame)
            out.write(count, row)
            progress.update(count + 1, work=report.temperature.size * max(report.substeps, 1))
            if out.due(state.count, interrupted.signal):
                state.integrator = setup.integrator.checkpoint()
                out.checkpoint(state, elapsed())
            interrupted.stop_if_asked()


def _outlet(setup: Setup, dem: PositionsFile, state: State, journal) -> outlet_record.Record:
    """What left the run (:mod:`dpht.chain.outlet`): the journalled crossings of its outlet plane,
    else the particles at the end of the run."""
    model, schedule = setup.model, setup.schedule
    weight = model.shells.weight if state.shells is not None else np.zeros(0)
    if journal is not None:
        return outlet_journal.crossings(journal.rows(), journal.plane, schedule.times, model.enthalpy.temperature, model.radius,
                                       weight)  # fmt: skip
    last = np.asarray(dem.frame(schedule.frames[-1]).positions, dtype=np.float64)
    return outlet_journal.bed(last, state.h, state.shells, len(schedule.frames) - 1, float(schedule.times[-1]),
                             model.enthalpy.temperature, model.radius, weight)  # fmt: skip


def assemble(setup: Setup, dem: PositionsFile, work: WorkDir, state: State, segments: list, attrs: dict, elapsed,
             leaving: outlet_record.Record | None = None) -> dict:  # fmt: skip
    """Copy the rows of ``segments`` into ``work.final`` with the run's summary and error estimate
    (returned) and, when asked, what left the run (``leaving``), then remove the segments and the
    checkpoint."""
    schedule = setup.schedule
    with replacing(work.final) as tmp:
        final = ThermalWriter(tmp, ids=dem.ids, dem_frames=schedule.frames, n_elements=setup.n_elements, attrs=attrs)
        for first, rows in segments:
            final.copy_rows(work.segment(first), first, rows)
        wall_heat_last = final.file["wall_heat"][-1]
        result = {**summary(schedule, state, wall_heat_last, elapsed(), setup.integrator),
                  "solid_fraction": setup.solid_fraction, "intraparticle": setup.intraparticle}  # fmt: skip
        if setup.inflow is not None:
            result["hand_over"] = setup.inflow.summary(setup.started[1] if setup.started else None,
                                                       setup.inflow.entered(setup.model, schedule, dem))  # fmt: skip
        result["error_estimate"] = estimate_errors(setup.model, schedule, dem, final.file, setup.spec, setup.tables,
                                                   setup.rdf_tables, result, setup.inflow)  # fmt: skip
        if leaving is not None:
            outlet_record.write(final.file, leaving)
        final.file.attrs["fingerprint"] = work.fingerprint
        final.finish(result)
    work.clear()
    return result


def _rdf_tables(paths, spec) -> rdf.RDFTables:
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    return rdf.for_emissivities([rdf.load(p) for p in paths], spec["particles"]["emissivity"], spec["wall"]["emissivity"])
