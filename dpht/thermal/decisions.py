"""What the thermal stage decides from the DEM run and the first frame before it starts: the
measured solid fractions (:func:`resolve_solid_fractions`), the wall surfaces LIGGGHTS used
(:func:`wall_kinds`), both read from the DEM run's summary (:class:`DemRun`), and resolved
intra-particle conduction (:func:`decide_intraparticle`).

``thermal.intraparticle: auto`` is decided once, from the first frame, by the particles' Biot
numbers, so a resumed run decides the same. The screening stage (:mod:`dpht.thermal.screening`)
takes the same decisions on the same frame.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpht.closures import rdf
from dpht.dem.dumps import PositionsFile
from dpht.dem.report import FORMAT as DEM_REPORT_FORMAT, measured_solid_fraction, solid_fraction_over
from dpht.errors import ConfigError, DPHTError
from dpht.thermal import integrate, model as thermal_model, modes as registry
from dpht.thermal.model import ThermalModel
from dpht.thermal.schedule import Schedule

log = logging.getLogger("dpht")


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
    table, or outside (0, 0.75), stops the run before it starts (:func:`check_measured`); a spread
    above :data:`SOLID_FRACTION_SPREAD` in a region an enabled mode reads is logged as a warning."""
    t = spec["thermal"]
    over = solid_fraction_over(run_summary, frames)
    used = {registry.BY_NAME[m].region for m in registry.enabled(t["modes"])}
    values, record = {}, {}
    for region, value in registry.solid_fractions(t["solid_fraction"]).items():
        if registry.is_measured(value):
            values[region] = measured_solid_fraction(run_summary, region, source)
            flowing = run_summary["solid_fraction"]["flowing"]
            record[region] = {"value": values[region], "source": f"{source}: solid_fraction.flowing.{region}",
                              "dem_frames": flowing.get("frames")}  # fmt: skip
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
    grids = None if rdf_tables is None else {kind: getattr(rdf_tables, kind).solid_fraction for kind in ("pp", "pw")}
    for region, edge in check_measured(t, values, source, grids).items():
        record[region]["rdf_read_at"] = edge
    return {**spec, "thermal": {**t, "solid_fraction": values}}, record


def check_measured(thermal: dict, values: dict, source: str, grids: dict | None) -> dict[str, float]:
    """The measured solid fractions (``values``, region -> number, the DEM run's of ``source``) of a
    scene's ``thermal`` section must be ones the closures (Eq. 13) accept and, for the radiation
    modes on in ``thermal["modes"]``, the RDF tables: ``grids`` are their solid fractions by table
    ("pp", "pw"; None: not checked), covered to :data:`dpht.closures.rdf.SOLID_FRACTION_MARGIN`.
    The screening stage checks with the modes it decided on, so the thermal stage is never planned
    for a bed its tables do not cover. Returns, by region, the table edge a value just outside a
    table is read at (warned about)."""
    phi = registry.solid_fractions(thermal["solid_fraction"])
    edges = {}
    for region in (r for r, value in phi.items() if registry.is_measured(value)):
        key = f"thermal.solid_fraction.{region}" if isinstance(thermal["solid_fraction"], dict) else "thermal.solid_fraction"
        value = values[region]
        where = f"{key} = measured: the DEM run measured {value:.4f} ({source})"
        if not 0.0 < value < 0.75:
            raise ConfigError(f"{where}, outside (0, 0.75); give the solid fraction as a number")
        for mode in registry.MODES:
            if mode.region == region and mode.table and mode.table[0] == "rdf" and thermal["modes"].get(mode.name) \
                    and grids is not None:
                grid = grids[mode.table[1]]
                if not rdf.covers(grid, value):
                    raise ConfigError(
                        f"{where}, outside the {mode.table[1].upper()} RDF table's solid fractions {grid[0]}-{grid[-1]} "
                        f"(by more than {rdf.SOLID_FRACTION_MARGIN}; {mode.name}); give {key} as a number within "
                        f"{grid[0]}-{grid[-1]}, or use an RDF table that covers {value:.4f}"
                    )
                if not grid[0] <= value <= grid[-1]:
                    edge = min(max(value, grid[0]), grid[-1])
                    log.warning("thermal: warning: %s, just outside the %s RDF table's solid fractions %s-%s (%s): "
                                "its factors are read at %s", where, mode.table[1].upper(), grid[0], grid[-1], mode.name,
                                edge)  # fmt: skip
                    edges[region] = edge
    return edges


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
