"""The thermal stage: stream DEM frames, advance particle enthalpies, write the thermal output.

I/O lives here; the physics is in :mod:`dpht.thermal.model`, :mod:`dpht.thermal.kernels` and :mod:`dpht.thermal.integrate`.
Memory stays bounded by one frame whatever the run length: frames are read one at a time and
results written as they are computed.
"""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

import numba
import numpy as np

from dpht.closures import htc, rdf
from dpht.thermal import integrate, model as thermal_model
from dpht.dem.dumps import PositionsFile
from dpht.util.progress import Progress
from dpht.thermal.output import ThermalWriter, write_xdmf
from geometry.walls import load_walls

log = logging.getLogger("dpht")


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
    model = thermal_model.build(spec, walls, tables, _rdf_tables(rdf_table, spec) if rdf_table else None)
    stride = spec["thermal"]["frame_stride"]
    started = time.perf_counter()

    with PositionsFile(positions_h5) as dem:
        frames = list(range(0, dem.n_frames, stride))
        n = dem.n_particles
        times = dem.times[frames]
        box_lo, box_hi = np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"])
        periodic = np.asarray(dem.attrs["periodic"], dtype=bool)
        flow_axis = 2 if periodic[2] else None  # the tube axis; particles flow towards -z
        enthalpy = model.enthalpy
        h = np.full(n, enthalpy.enthalpy(model.initial_temperature)[()])
        h_inlet = enthalpy.enthalpy(model.inlet_temperature)[()]
        writer = ThermalWriter(
            out_h5,
            ids=dem.ids,
            dem_frames=frames,
            n_elements=len(walls.area),
            attrs={
                "modes": json.dumps(sorted(model.modes)),
                "inlet_temperature": model.inlet_temperature,
                "positions": str(Path(positions_h5).name),
                "spec": json.dumps(spec, sort_keys=True),
            },
        )
        progress = Progress("thermal", len(frames), unit="particle-steps")
        wall_energy = recycled_energy = 0.0
        last = None  # positions and image flags of the previous frame, for recycling
        rates = frame = None
        try:
            for count, k in enumerate(frames):
                current = dem.frame(k)
                positions = np.asarray(current.positions, dtype=np.float64)
                image = current.image
                if last is not None and flow_axis is not None:
                    crossed = integrate.wrapped(last[1], image, last[0], positions, box_lo, box_hi, flow_axis)
                    recycled_energy += model.mass * float(np.sum(h_inlet - h[crossed]))
                    h[crossed] = h_inlet
                last = (positions, image)
                energy_particles = model.mass * math.fsum(h)

                frame = None  # free the last frame's arrays before the next is built
                frame = integrate.prepare_frame(model, positions, box_lo, box_hi, periodic)
                if rates is None or rates.q.size != frame.particles.size:
                    size = frame.particles.size
                    rates = integrate.Rates(np.zeros(size), np.zeros(size), np.zeros((len(walls.area), 3)))
                dt = float(times[count + 1] - times[count]) if count + 1 < len(frames) else 0.0
                report = integrate.advance(model, frame, h, dt, rates, frame_number=k)
                temperature = np.full(n, np.nan, dtype=np.float32)  # lost particles stay NaN
                temperature[frame.particles] = report.temperature
                writer.write(
                    count,
                    time=times[count],
                    temperature=temperature,
                    element_heat=report.element_heat,
                    substeps=report.substeps,
                    energy_particles=energy_particles,
                    energy_wall=wall_energy,
                    energy_recycled=recycled_energy,
                )
                wall_energy += dt * math.fsum(report.element_heat.ravel())
                progress.update(count + 1, work=frame.particles.size * max(report.substeps, 1))
        except BaseException:
            writer.close(complete=False)
            raise
        summary = {
            "frames": len(frames),
            "particles": n,
            "wall_energy_J": wall_energy,
            "recycled_energy_J": recycled_energy,
            "wall_heat_last_W": dict(zip(("pw_contact", "pfw", "pw_radiation"), report.element_heat.sum(axis=0).tolist())),
            "seconds": time.perf_counter() - started,
            "threads": numba.get_num_threads(),
        }
        writer.file.attrs["summary"] = json.dumps(summary)
        writer.close()
        if xdmf:
            write_xdmf(xdmf, out_h5, positions_h5, frames=frames, n_dem_frames=dem.n_frames, n_particles=n,
                       times=times, precision=current.positions.dtype.itemsize)
    log.info("thermal: %d frames of %d particles in %.1f s", len(frames), n, summary["seconds"])
    return summary


def _rdf_tables(paths, spec) -> rdf.RDFTables:
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    return rdf.for_emissivities([rdf.load(p) for p in paths], spec["particles"]["emissivity"], spec["wall"]["emissivity"])
