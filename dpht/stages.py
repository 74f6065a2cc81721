"""Workflow stages: one function per Snakemake rule, called as ``python -m dpht stage NAME``.

Each stage takes its parameters (``spec``, JSON from the rule's ``params``), its input and output
paths and a thread count; the MPI stages (DEM, orifice calibration) also the rule's MPI launcher
and rank count (``resources.mpi``, ``resources.tasks``). Errors the user can fix
(:data:`dpht.errors.USER_ERRORS`) are logged as one clear message, to the terminal and the rule's
log, and the stage exits non-zero. Under the workflow the message goes to the log only, and the
rule raises :class:`StageFailed` with it (:func:`failure`), so that the message is the error
Snakemake shows, once, without the command line.

Interruptions: every declared output appears at its final name only when complete
(:mod:`dpht.util.files`); the stage process stops cleanly on SIGINT, SIGTERM and SIGHUP, and when
the snakemake process that started it is gone (:mod:`dpht.util.processes`). The rule's log is
appended to, never truncated, and recreated with everything logged so far if it is removed while
the stage runs (Snakemake removes a job's log when it starts the job again).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import sys
import time
from pathlib import Path

from dpht import integrity
from dpht.errors import USER_ERRORS
from dpht.util import processes
from dpht.util.files import claim_log, no_nan, replacing, staged, staging, write_json, write_text

log = logging.getLogger("dpht")


def geometry(spec, inputs, outputs, threads):
    from dpht.geometry import build, picture

    with staged(outputs) as out:  # with the zone STLs and geometry.msh written beside them
        summary = build(spec["geometry"], spec["particle_diameter"], out["walls"].parent)
        picture(out["walls"].parent, out["picture"])
    log.info("geometry: %s", json.dumps({z: v["triangles"] for z, v in summary["zones"].items()}))


def dem(spec, inputs, outputs, threads, mpi):
    from dpht.dem.liggghts import run_dem

    out = Path(outputs["positions"])
    summary = run_dem(
        spec, Path(inputs["walls"]).parent, out.parent / "work", out, ranks=mpi["ranks"], log=log.info, mpi=mpi["launcher"]
    )
    write_json(outputs["summary"], summary)


def _htc_table(spec, dem_summary):
    """The HTC table of ``spec`` (a measured solid fraction read from the DEM run's ``dem_summary``)."""
    from dpht.closures import htc
    from dpht.dem.report import measured_solid_fraction
    from dpht.thermal.modes import is_measured

    phi = spec["solid_fraction"]
    if is_measured(phi):  # the DEM run's flowing bed
        spec = {**spec, "solid_fraction": measured_solid_fraction(json.loads(Path(dem_summary).read_text()), phi["region"],
                                                                  dem_summary)}  # fmt: skip
        log.info("HTC table %s: %s solid fraction %.4f measured by the DEM run (%s)", spec["kind"], phi["region"],
                 spec["solid_fraction"], dem_summary)  # fmt: skip
    return htc.table_from_spec(spec)


def htc_table(spec, inputs, outputs, threads):
    from dpht.closures import htc

    table = _htc_table(spec, inputs.get("dem_summary"))
    with replacing(outputs["table"]) as out:
        htc.save_table(out, table)


def screening(spec, inputs, outputs, threads):
    """Which effects the scene calls for, on its settled bed (:mod:`dpht.thermal.screening`)."""
    import numba

    from dpht.cost import compile_notice
    from dpht.preflight import rdf_solid_fractions
    from dpht.thermal.screening import screen

    if threads:
        numba.set_num_threads(threads)
    compile_notice("screening", log.info)
    tables = {kind: _htc_table(s, inputs["dem_summary"]) for kind, s in spec["htc"].items()}
    # The solid fractions of the RDF tables the thermal stage will read: a measured one outside them stops here.
    grids = {kind: grid for kind, (grid, _) in rdf_solid_fractions(spec["thermal"]).items()} if inputs.get("rdf") else None
    result = screen(spec["thermal"], inputs["positions"], inputs["walls"], inputs["dem_summary"], tables, inputs.get("rdf"),
                    grids)  # fmt: skip
    write_json(outputs["screening"], result)


def rdf_table(spec, inputs, outputs, threads):
    from dpht.closures import rdf
    from dpht.radiation.tables import build_tables, monotone_violations

    params = {k: v for k, v in spec.items() if k not in ("particle_emissivity", "wall_emissivity", "solid_fractions")}
    tables = build_tables(
        spec["particle_emissivity"], spec["wall_emissivity"], tuple(spec["solid_fractions"]), progress=log.info, **params
    )
    for kind in ("pp", "pw"):
        table = getattr(tables, kind)
        log.info(
            "RDF %s: %d distances x %d solid fractions, max standard error %.2g, monotonicity violations %d",
            kind, table.distance.size, table.solid_fraction.size, table.stderr.max(), len(monotone_violations(table)),
        )  # fmt: skip
    with replacing(outputs["table"]) as out:
        rdf.save(out, tables)


def thermal(spec, inputs, outputs, threads):
    write_json(outputs["summary"], _thermal(spec, inputs, outputs, threads))


def _thermal(spec, inputs, outputs, threads, outlet=None, inlet_plane=None) -> dict:
    """The thermal stage's run (its summary returned), ``outlet`` its record of what leaves it,
    ``inlet_plane`` where its inlet field is given (:mod:`dpht.thermal.inflow`)."""
    from dpht.config import THERMAL_RUN_SETTINGS
    from dpht.cost import compile_notice
    from dpht.thermal.stage import Checkpoints, run

    settings = {k: spec["thermal"].pop(k) for k in THERMAL_RUN_SETTINGS if k in spec["thermal"]}
    spec, decided = effects_decided(spec, inputs)
    compile_notice("thermal", log.info)
    out = Path(outputs["thermal"])
    summary = run(
        spec,
        inputs["positions"],
        inputs["walls"],
        {kind: inputs[kind] for kind in ("pfp", "pfw") if kind in inputs},
        out,
        rdf_table=inputs.get("rdf"),
        xdmf=outputs["xdmf"],
        threads=threads,
        dem_summary=inputs.get("dem_summary"),
        workdir=out.parent / "work",
        initial_field=inputs.get("initial_field"),
        inlet_field=inputs.get("inlet_field"),
        checkpoints=Checkpoints(settings.get("checkpoint_frames", Checkpoints.frames),
                                settings.get("checkpoint_minutes", Checkpoints.minutes)),
        outlet=outlet,
        inlet_plane=inlet_plane,
    )
    return {**summary, "effects": decided}


def segment(spec, inputs, outputs, threads):
    """A chain's segment (docs/theory/chain.md): the thermal stage started from, and for a resolved
    segment fed by, the hand-over field of the segment above (inputs ``initial_field``,
    ``inlet_field``, given at the top of its stretch), recording what leaves it
    (:mod:`dpht.chain.outlet`); then its own hand-over
    field for the next (:mod:`dpht.chain.handover`), its books in the summary's ``outlet``."""
    import numpy as np

    from dpht.chain import handover, outlet
    from dpht.chain.files import save_field
    from dpht.closures import heat_capacity
    from dpht.geometry.walls import load_walls

    spec = dict(spec)
    given = spec.pop("handover")
    books = handover.Spec(**{**given, "window": tuple(given["window"])})
    travelling = spec["thermal"].get("slice")
    place = handover.Place(**spec.pop("outlet"), velocity=travelling["velocity"] if travelling else None)
    top = None if place.plane is None else place.plane + place.top - place.bottom  # resolved: fed at its top
    summary = _thermal(spec, inputs, outputs, threads, outlet.Outlet(place.plane), top if "inlet_field" in inputs else None)
    record = outlet.read(outputs["thermal"])
    T = np.concatenate([record.temperature, record.shells.ravel()])
    table = heat_capacity.build(heat_capacity.specific_heat(spec["particles"]["specific_heat"]), float(T.min()), float(T.max()))
    centroids = load_walls(inputs["walls"]).centroid[:, 2] if place.plane is not None else None
    result = handover.hand_over(record, handover.Rows.read(outputs["thermal"]), books, table, place, centroids)
    save_field(outputs["handover"], result.field)
    write_json(outputs["summary"], {**summary, "outlet": result.summary()})
    log.info("segment: hands over %d particles (%s), mixing cup %.3f K, wall heat %.4g W at the chain's flow%s",
             result.samples, result.kind, result.field.cup_temperature, result.wall_heat,
             "" if result.steady is not False else "; NOT steady over its window (wall heat halves "
             f"{result.wall_heat_halves[0]:.4g}, {result.wall_heat_halves[1]:.4g} W)")  # fmt: skip


def chain_summary(spec, inputs, outputs, threads):
    """results/<run>/<variant>/chain.json: a chain's segments, joints and totals (:mod:`dpht.chain.summary`)."""
    from dpht.chain.files import load_field
    from dpht.chain.summary import summarize

    n = len(spec["segments"])
    summaries = [json.loads(Path(inputs[f"summary_{k}"]).read_text()) for k in range(n)]
    result = summarize(spec, summaries, [load_field(inputs[f"handover_{k}"]) for k in range(n)])
    write_json(outputs["summary"], result)
    log.info("chain: %d segments (%d DEM runs), wall heat %.4g W, outlet mixing cup %.3f K, balance %+.2e",
             n, result["dem_runs"], result["wall_heat_W"], result["outlet_cup_temperature_K"], result["balance_relative"])


def effects_decided(spec: dict, inputs: dict) -> tuple[dict, list[dict]]:
    """``spec`` with every effect decided (:mod:`dpht.thermal.effects`: by the config, by the
    screening stage's ``inputs["screening"]``, recycling by the DEM run), and the decisions' records."""
    from dpht.thermal import effects
    from dpht.thermal.stage import DemRun
    from dpht.geometry.walls import load_walls

    decisions = effects.from_config(spec["thermal"], load_walls(inputs["walls"]).zone_names)
    if "screening" in inputs:
        screened = json.loads(Path(inputs["screening"]).read_text())["decisions"]
        decisions.update({name: effects.Decision(**screened[name]) for name in effects.pending(decisions)})
    dem_run = DemRun.of(inputs["positions"], inputs.get("dem_summary"))
    decisions["recycling"] = effects.recycling(dem_run.recycled, dem_run.crossings(inputs["positions"]),
                                               "slice" in spec["thermal"])  # fmt: skip
    for decision in decisions.values():
        log.info("thermal: effect %s", decision.line())
    return {**spec, "thermal": effects.resolve(spec["thermal"], decisions)}, [d.record() for d in decisions.values()]


def calibrate_orifice(spec, inputs, outputs, threads, mpi):
    out = Path(outputs["result"])
    result = calibrate_config(spec, out.parent / "runs", ranks=mpi["ranks"], mpi=mpi["launcher"], log=log.info)
    write_json(out, result)
    log.info("geometry.tube.orifice_diameter: %.6g (%s)", result["orifice_diameter"],
             "within tolerance" if result["converged"] else "NOT within tolerance")


def figures(spec, inputs, outputs, threads):
    import h5py

    from dpht.figures import scene as fig

    window = tuple(spec["window"])
    with staged(outputs) as out:  # with the CSV of each figure beside it
        fig.cross_section(inputs["positions"], inputs["thermal"], inputs["walls"], out["cross_section"])
        fig.wall_heat_flux(inputs["thermal"], inputs["walls"], out["wall_heat_flux"], window=window, zones=spec["heated_zones"])
        fig.wall_heat_history(inputs["thermal"], out["wall_heat_history"])
        fig.engineering(inputs["positions"], inputs["thermal"], inputs["walls"], out["engineering"], window=window,
                        zones=spec["heated_zones"])
        fig.temperature_profiles(
            inputs["positions"], inputs["thermal"], out["temperature_profiles"], window=window, radial_band=tuple(spec["radial_band"])
        )
        with h5py.File(inputs["thermal"]) as f:  # the solid fractions the thermal run used, measured or given
            used = json.loads(f.attrs["summary"])["solid_fraction"]
        fig.htc_curves(out["htc_curves"], **spec["htc"], solid_fraction={region: r["value"] for region, r in used.items()})


def variant_summary(spec, inputs, outputs, threads):
    """results/<run>/<variant>/summary.json: the stage keys a design variant used, the summaries (.json
    inputs) of its geometry, DEM and thermal runs and the names of its figures (the other inputs),
    so one file says where everything of the variant is. With the ``headline_md`` and
    ``headline_csv`` outputs also the variant's headline (:mod:`dpht.headline`: wall heat by mode,
    outlet temperature, h_w, Nu_w, mass flow, energy balance, error estimate, cost), kept in the
    summary too; read from its figures' CSV files and the thermal run's thermal.h5 beside its summary."""
    import csv
    import io

    from dpht import headline
    from dpht.thermal.effects import table

    figures = sorted(Path(file).name for file in inputs.values() if not file.endswith(".json"))
    summary = {"stage_keys": spec["stage_keys"], "figures": figures}
    for name, file in inputs.items():
        if file.endswith(".json"):
            summary[name] = json.loads(Path(file).read_text())
    if "effects" in outputs:  # the report's table of the effects the scene called for, and why
        rows = table(summary["thermal"].get("effects", []))
        text = io.StringIO()
        writer = csv.DictWriter(text, fieldnames=["effect", "on", "by", "estimate", "threshold", "reason"], lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        write_text(outputs["effects"], text.getvalue())
    if "headline_md" in outputs:
        variant = Path(outputs["summary"]).parent.name
        numbers = headline.from_outputs(variant, engineering_png=inputs["figure_engineering"],
                                        wall_heat_flux_png=inputs["figure_wall_heat_flux"],
                                        thermal_h5=Path(inputs["thermal"]).with_name("thermal.h5"),
                                        dem_summary=summary["dem"], thermal_summary=summary["thermal"])  # fmt: skip
        summary["headline"] = headline.record(numbers)
        write_text(outputs["headline_md"], headline.markdown(numbers))
        write_text(outputs["headline_csv"], headline.csv_text(numbers))
    write_json(outputs["summary"], summary)
    log.info("stage keys: %s", ", ".join(f"{stage} {key}" for stage, key in spec["stage_keys"].items() if key))


def compare(spec, inputs, outputs, threads):
    from dpht.figures import scene as fig

    runs = [(name, inputs[f"thermal_{name}"], inputs[f"walls_{name}"]) for name in spec["variants"]]
    with staged(outputs) as out:
        fig.compare_variants(runs, out["comparison"], window=tuple(spec["window"]))
        sections = [(name, inputs[f"positions_{name}"], thermal, walls) for name, thermal, walls in runs]
        fig.compare_cross_sections(sections, out["cross_sections"])


def calibrate_config(cfg: dict, workdir, *, target=None, tolerance=None, flow_time=None, max_runs=6, ranks=None,
                     mpi=None, log=print) -> dict:
    """:func:`dpht.dem.calibrate.calibrate_orifice` for one validated config variant, meshing each
    trial with gmsh (here, not in :mod:`dpht.dem`, which does not depend on the config or geometry).

    ``target`` (kg/s) and ``tolerance`` default to ``dem.target_mass_flow`` and
    ``dem.mass_flow_tolerance``; ``flow_time`` (s) shortens the trial runs; ``mpi`` is the MPI
    launcher (default :data:`dpht.dem.liggghts.DEFAULT_MPI`). The result also holds the target
    and tolerance used.
    """
    from dpht import geometry

    from dpht import config
    from dpht.dem import calibrate
    from dpht.dem.liggghts import DEFAULT_MPI
    from dpht.errors import ConfigError

    target = cfg["dem"].get("target_mass_flow") if target is None else target
    if target is None:
        raise ConfigError("dem.target_mass_flow: needed to calibrate the orifice (or give --target)")
    tolerance = cfg["dem"].get("mass_flow_tolerance", calibrate.MASS_FLOW_TOLERANCE) if tolerance is None else tolerance
    spec = config.dem_spec(cfg)
    if flow_time is not None:
        spec["dem"]["flow_time"] = flow_time
    result = calibrate.calibrate_orifice(
        spec,
        lambda trial, folder: geometry.build(trial["geometry"], trial["particles"]["diameter"], folder),
        target,
        Path(workdir),
        tolerance=tolerance,
        max_runs=max_runs,
        ranks=cfg["dem"]["ranks"] if ranks is None else ranks,
        mpi=mpi or DEFAULT_MPI,
        log=log,
    )
    return {**result, "target_mass_flow": target, "mass_flow_tolerance": tolerance}


# The design's stages; the studies' stages are found in their registry (dpht.studies).
STAGES = {
    f.__name__: f
    for f in (geometry, dem, htc_table, rdf_table, screening, thermal, segment, chain_summary, calibrate_orifice, figures,
              variant_summary, compare)
}


def stage_function(name: str):
    """The function of stage ``name``: a design stage, or a study's (:func:`dpht.studies.stage`), or None."""
    from dpht import studies

    return STAGES.get(name) or studies.stage(name)


class _StageLog(logging.FileHandler):
    """The rule's log file, appended to. If the file is removed or replaced while the stage runs,
    it is recreated (appending to whatever is there) with every line this stage has logged."""

    def __init__(self, path):
        super().__init__(path, mode="a", encoding="utf-8")
        self.lines: list[str] = []

    def _replaced(self) -> bool:
        try:
            named, open_ = os.stat(self.baseFilename), os.fstat(self.stream.fileno())
        except OSError:
            return True
        return (named.st_dev, named.st_ino) != (open_.st_dev, open_.st_ino)

    def write(self, line: str) -> None:
        if self._replaced():
            self.stream.close()
            self.stream = self._open()
            self.stream.write("".join(earlier + self.terminator for earlier in self.lines))
        self.lines.append(line)
        self.stream.write(line + self.terminator)
        self.flush()

    def emit(self, record) -> None:
        try:
            self.write(self.format(record))
        except Exception:
            self.handleError(record)


ERROR_MARK = "dpht: error in stage"  # starts the last record of a failed stage's log
LOG_HEADER = "=== stage"  # starts each run's part of a stage's log


class StageFailed(Exception):
    """A workflow stage failed; the message is the stage's own (see :func:`failure`)."""


def run(name: str, spec_json: str, io_json: str, log_path: str | None, errors_to_log_only: bool = False) -> int:
    """Run stage ``name``; returns the process exit code (128 + signal number when a signal
    stopped it). With ``errors_to_log_only`` (and a log) the error message is written to the log
    and not to the terminal (the workflow shows it)."""
    terminal = logging.StreamHandler(sys.stderr)
    handlers = [terminal]
    rule_log = log_path
    if log_path:
        log_path = claim_log(log_path)  # earlier attempts kept, a concurrent run's log never shared
        handlers.append(_StageLog(log_path))
        if errors_to_log_only:
            terminal.addFilter(lambda record: record.levelno < logging.ERROR)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S", handlers=handlers, force=True)
    if log_path:
        handlers[-1].write(f"{LOG_HEADER} {name}, pid {os.getpid()}, {time.strftime('%Y-%m-%d %H:%M:%S')} ===")
    function = stage_function(name)
    if function is None:
        from dpht import studies

        log.error("%s %s: unknown stage (stages: %s)", ERROR_MARK, name, ", ".join([*STAGES, *studies.STUDIES, *studies.KEYED]))
        return 2
    io = json.loads(io_json)
    for path in io["output"].values():
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    try:
        # MPI stages (rules with resources.mpi) also get {"launcher": resources.mpi, "ranks": resources.tasks}.
        mpi = {"mpi": io["mpi"]} if "mpi" in io else {}
        # Under the workflow (a log) the stage run's manifest records what it read and published (dpht.integrity).
        recorded = integrity.recorded(name, rule_log, io["input"], io["output"]) if log_path else contextlib.nullcontext()
        with processes.stop_on_signals(), recorded:
            processes.watch_workflow()
            function(json.loads(spec_json), io["input"], io["output"], io.get("threads", 1), **mpi)
    except USER_ERRORS as err:
        log.error("%s %s: %s", ERROR_MARK, name, err)
        return 1
    except Exception as err:  # a bug: the traceback goes to the log (and the message to the workflow)
        log.exception("%s %s: unexpected %s: %s (a bug in dpht; please report it with this log)",
                      ERROR_MARK, name, type(err).__name__, err)  # fmt: skip
        return 1
    except KeyboardInterrupt:
        log.error("%s %s: interrupted (SIGINT); run the workflow again to resume", ERROR_MARK, name)
        return 128 + signal.SIGINT
    except SystemExit as stop:
        if isinstance(stop.code, int) and stop.code > 128:
            log.error("%s %s: stopped by signal %d; run the workflow again to resume", ERROR_MARK, name, stop.code - 128)
        raise
    return 0


def failure(name: str, log_path, returncode: int) -> StageFailed:
    """The error of stage ``name`` that exited with ``returncode``: the message it wrote last into
    its log ``log_path`` (from :data:`ERROR_MARK` to the end), and where the log is."""
    try:
        lines = Path(log_path).read_text(errors="replace").splitlines()
    except OSError:
        lines = []
    # The log is appended to: only the last run's part (after its header) counts.
    start = max((k for k, line in enumerate(lines) if line.startswith(LOG_HEADER)), default=0)
    for k in range(len(lines) - 1, start - 1, -1):
        if ERROR_MARK in lines[k]:
            message = "\n".join([lines[k][lines[k].index(ERROR_MARK):], *lines[k + 1:]])
            return StageFailed(f"{message}\n(log: {log_path})")
    return StageFailed(f"stage {name} stopped with exit status {returncode} and no message (killed?); log: {log_path}")
