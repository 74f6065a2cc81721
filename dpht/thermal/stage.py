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

Resolved intra-particle conduction (``thermal.intraparticle``, :mod:`dpht.thermal.intraparticle`):
the State also holds every particle's shell enthalpies; ``auto`` decides once, from the first
frame, by the particles' Biot numbers (:func:`decide_intraparticle`), so a resumed run decides
the same. The written temperature is the particle's mean (from h), the one the energy books use.

Energy bookkeeping (J): between consecutive rows, the change of ``energy_particles`` equals the
change of ``energy_wall`` (the interval's mean wall heat times its length) plus that of
``energy_recycled``, to round-off.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from dpht.closures import htc, rdf
from dpht.dem.dumps import PositionsFile
from dpht.thermal import integrate, model as thermal_model
from dpht.thermal.model import ThermalModel
from dpht.thermal.modes import PW_MODES
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


def memory_estimate(n_particles: int, n_elements: int, tables, shells: int = 0) -> int:
    """Bytes a run of ``n_particles`` against ``n_elements`` wall elements needs, ``tables`` included
    (and ``shells`` float64 shell enthalpies per particle when resolved)."""
    per_particle = _per_particle(shells)
    return n_particles * per_particle + n_elements * WALL_BYTES_PER_ELEMENT + _nbytes(tables)


def _per_particle(shells: int) -> int:
    return STEP_BYTES_PER_PARTICLE + FRAME_BYTES_PER_PARTICLE + 8 * shells


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
    shells: np.ndarray | None = None  # (N, n) J/kg, shell enthalpies of resolved particles (mean: h)

    @classmethod
    def initial(cls, model: ThermalModel, n: int) -> State:
        h0 = model.enthalpy.enthalpy(model.initial_temperature)[()]
        shells = np.full((n, model.shells.n), h0) if model.shells is not None else None
        return cls(0, np.full(n, h0), 0.0, 0.0, None, shells)

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
        if state.shells is not None:
            state.shells[crossed] = h_inlet
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
                               frame_number=schedule.frames[count], shells=state.shells)  # fmt: skip
    temperature = np.full(state.h.size, np.nan, dtype=np.float32)  # lost particles stay NaN
    temperature[frame.particles] = report.temperature
    row = Row(schedule.times[count], temperature, report.element_heat, report.substeps, energy_particles,
              state.wall_energy, state.recycled_energy)  # fmt: skip
    state.wall_energy += dt * math.fsum(report.element_heat.ravel())
    state.count += 1
    return row, frame.particles.size * max(report.substeps, 1)


def decide_intraparticle(model: ThermalModel, schedule: Schedule, positions: np.ndarray) -> tuple[ThermalModel, dict]:
    """The model with or without shells, and the record of why (logged, and kept in the summary).

    ``thermal.intraparticle: auto`` resolves the particles when the largest Biot number on the first
    frame ``positions`` exceeds ``thermal.biot_threshold`` (ParScale: Bi_crit ~ 0.1, ~0.01 in dense
    beds). The conductances are those at the scene's hottest temperature (initial, inlet, walls),
    where radiation makes them largest; all enabled modes count (:func:`integrate.biot_numbers`).
    """
    record = {"switch": model.intraparticle, "shells": model.shell_count, "threshold": model.biot_threshold}
    if model.intraparticle != "auto":
        record.update(resolved=model.shells is not None, reason="set in the config")
        return model, record
    frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    wall = model.element_temperature[np.isfinite(model.element_temperature)]
    T_max = float(max(model.initial_temperature, model.inlet_temperature, *wall.tolist()))
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
        model, intraparticle = decide_intraparticle(model, schedule, np.asarray(dem.frame(schedule.frames[0]).positions,
                                                                                 dtype=np.float64))  # fmt: skip
        state = State.initial(model, dem.n_particles)
        n = dem.n_particles
        n_shells = model.shells.n if model.shells is not None else 0
        needed = memory_estimate(n, len(walls.area), [tables, rdf_tables], n_shells)
        log.info(
            "thermal: memory estimate %.3g MB: %d particles x %d B, %d wall elements x %d B, tables %.3g MB "
            "(frames are read one at a time)",
            needed / 1e6, n, _per_particle(n_shells), len(walls.area),
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
        result["intraparticle"] = intraparticle
        writer.finish(result)
        if xdmf:
            write_xdmf(xdmf, out_h5, positions_h5, frames=schedule.frames, n_dem_frames=dem.n_frames,
                       n_particles=dem.n_particles, times=schedule.times, precision=current.positions.dtype.itemsize)  # fmt: skip
    log.info("thermal: %d frames of %d particles in %.1f s", len(schedule.frames), dem.n_particles, result["seconds"])
    return result


def _rdf_tables(paths, spec) -> rdf.RDFTables:
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    return rdf.for_emissivities([rdf.load(p) for p in paths], spec["particles"]["emissivity"], spec["wall"]["emissivity"])
