"""Workflow stages: one function per Snakemake rule, called as ``python -m dpht stage NAME``.

Each stage takes its parameters (``spec``, JSON from the rule's ``params``), its input and output
paths and a thread count; the MPI stages (DEM, orifice calibration) also the rule's MPI launcher
and rank count (``resources.mpi``, ``resources.tasks``). Errors the user can fix
(:data:`dpht.errors.USER_ERRORS`) are logged as one clear message, to the terminal and the rule's
log, and the stage exits non-zero. Under the workflow the message goes to the log only, and the
rule raises :class:`StageFailed` with it (:func:`failure`), so that the message is the error
Snakemake shows, once, without the command line.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

from dpht.errors import USER_ERRORS

log = logging.getLogger("dpht")


def geometry(spec, inputs, outputs, threads):
    from geometry import build, picture

    outdir = Path(outputs["walls"]).parent
    summary = build(spec["geometry"], spec["particle_diameter"], outdir)
    picture(outdir, outputs["picture"])
    log.info("geometry: %s", json.dumps({z: v["triangles"] for z, v in summary["zones"].items()}))


def dem(spec, inputs, outputs, threads, mpi):
    from dpht.dem.liggghts import run_dem

    out = Path(outputs["positions"])
    summary = run_dem(
        spec, Path(inputs["walls"]).parent, out.parent / "work", out, ranks=mpi["ranks"], log=log.info, mpi=mpi["launcher"]
    )
    Path(outputs["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


def htc_table(spec, inputs, outputs, threads):
    from dpht.closures import htc

    htc.save_table(outputs["table"], htc.table_from_spec(spec))


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
    rdf.save(outputs["table"], tables)


def thermal(spec, inputs, outputs, threads):
    from dpht.thermal.stage import run

    summary = run(
        spec,
        inputs["positions"],
        inputs["walls"],
        {"pfp": inputs["pfp"], "pfw": inputs["pfw"]},
        outputs["thermal"],
        rdf_table=inputs.get("rdf"),
        xdmf=outputs["xdmf"],
        threads=threads,
    )
    Path(outputs["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


def calibrate_orifice(spec, inputs, outputs, threads, mpi):
    out = Path(outputs["result"])
    result = calibrate_config(spec, out.parent / "runs", ranks=mpi["ranks"], mpi=mpi["launcher"], log=log.info)
    out.write_text(json.dumps(result, indent=2, sort_keys=True) + "\n")
    log.info("geometry.tube.orifice_diameter: %.6g (%s)", result["orifice_diameter"],
             "within tolerance" if result["converged"] else "NOT within tolerance")


def radiation_study(spec, inputs, outputs, threads):
    from dpht.figures.radiation_study import radiation_models_figure
    from dpht.radiation.study import run_study

    summary, times, histories = run_study(spec, inputs["rdf"], Path(outputs["table"]).parent, progress=log.info, threads=threads)
    radiation_models_figure(times, histories, summary["models"], summary["cross_section_m2"], outputs["figure"])
    Path(outputs["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


def intraparticle_study(spec, inputs, outputs, threads):
    import numba

    from dpht.studies.intraparticle import run_study

    if threads:
        numba.set_num_threads(threads)
    summary = run_study(spec["base"], spec["study"], Path(outputs["sweep"]).parent, progress=log.info)
    Path(outputs["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


def figures(spec, inputs, outputs, threads):
    from dpht.figures import scene as fig

    window = tuple(spec["window"])
    fig.cross_section(inputs["positions"], inputs["thermal"], inputs["walls"], outputs["cross_section"])
    fig.wall_heat_flux(inputs["thermal"], inputs["walls"], outputs["wall_heat_flux"], window=window, zones=spec["heated_zones"])
    fig.wall_heat_history(inputs["thermal"], outputs["wall_heat_history"])
    fig.temperature_profiles(
        inputs["positions"], inputs["thermal"], outputs["temperature_profiles"], window=window, radial_band=tuple(spec["radial_band"])
    )
    fig.htc_curves(outputs["htc_curves"], **spec["htc"])


def variant_summary(spec, inputs, outputs, threads):
    """results/<variant>/summary.json: the stage keys a design variant used, the summaries (.json
    inputs) of its geometry, DEM and thermal runs and the names of its figures (the other inputs),
    so one file says where everything of the variant is."""
    figures = sorted(Path(file).name for file in inputs.values() if not file.endswith(".json"))
    summary = {"stage_keys": spec["stage_keys"], "figures": figures}
    for name, file in inputs.items():
        if file.endswith(".json"):
            summary[name] = json.loads(Path(file).read_text())
    Path(outputs["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True))
    log.info("stage keys: %s", ", ".join(f"{stage} {key}" for stage, key in spec["stage_keys"].items() if key))


def compare(spec, inputs, outputs, threads):
    from dpht.figures import scene as fig

    runs = [(name, inputs[f"thermal_{name}"], inputs[f"walls_{name}"]) for name in spec["variants"]]
    fig.compare_variants(runs, outputs["comparison"], window=tuple(spec["window"]))
    sections = [(name, inputs[f"positions_{name}"], thermal, walls) for name, thermal, walls in runs]
    fig.compare_cross_sections(sections, outputs["cross_sections"])


def calibrate_config(cfg: dict, workdir, *, target=None, tolerance=None, flow_time=None, max_runs=6, ranks=None,
                     mpi=None, log=print) -> dict:
    """:func:`dpht.dem.calibrate.calibrate_orifice` for one validated config variant, meshing each
    trial with gmsh (here, not in :mod:`dpht.dem`, which does not depend on the config or geometry).

    ``target`` (kg/s) and ``tolerance`` default to ``dem.target_mass_flow`` and
    ``dem.mass_flow_tolerance``; ``flow_time`` (s) shortens the trial runs; ``mpi`` is the MPI
    launcher (default :data:`dpht.dem.liggghts.DEFAULT_MPI`). The result also holds the target
    and tolerance used.
    """
    import geometry

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


STAGES = {
    f.__name__: f
    for f in (geometry, dem, htc_table, rdf_table, thermal, calibrate_orifice, radiation_study, intraparticle_study, figures,
              variant_summary, compare)
}


ERROR_MARK = "dpht: error in stage"  # starts the last record of a failed stage's log


class StageFailed(Exception):
    """A workflow stage failed; the message is the stage's own (see :func:`failure`)."""


def run(name: str, spec_json: str, io_json: str, log_path: str | None, errors_to_log_only: bool = False) -> int:
    """Run stage ``name``; returns the process exit code. With ``errors_to_log_only`` (and a log)
    the error message is written to the log and not to the terminal (the workflow shows it)."""
    terminal = logging.StreamHandler(sys.stderr)
    handlers = [terminal]
    if log_path:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w"))
        if errors_to_log_only:
            terminal.addFilter(lambda record: record.levelno < logging.ERROR)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S", handlers=handlers, force=True)
    if name not in STAGES:
        log.error("%s %s: unknown stage (stages: %s)", ERROR_MARK, name, ", ".join(STAGES))
        return 2
    io = json.loads(io_json)
    for path in io["output"].values():
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    try:
        # MPI stages (rules with resources.mpi) also get {"launcher": resources.mpi, "ranks": resources.tasks}.
        mpi = {"mpi": io["mpi"]} if "mpi" in io else {}
        STAGES[name](json.loads(spec_json), io["input"], io["output"], io.get("threads", 1), **mpi)
    except USER_ERRORS as err:
        log.error("%s %s: %s", ERROR_MARK, name, err)
        return 1
    except Exception as err:  # a bug: the traceback goes to the log (and the message to the workflow)
        log.exception("%s %s: unexpected %s: %s (a bug in dpht; please report it with this log)",
                      ERROR_MARK, name, type(err).__name__, err)  # fmt: skip
        return 1
    return 0


def failure(name: str, log_path, returncode: int) -> StageFailed:
    """The error of stage ``name`` that exited with ``returncode``: the message it wrote last into
    its log ``log_path`` (from :data:`ERROR_MARK` to the end), and where the log is."""
    try:
        lines = Path(log_path).read_text(errors="replace").splitlines()
    except OSError:
        lines = []
    for k in range(len(lines) - 1, -1, -1):
        if ERROR_MARK in lines[k]:
            message = "\n".join([lines[k][lines[k].index(ERROR_MARK):], *lines[k + 1:]])
            return StageFailed(f"{message}\n(log: {log_path})")
    return StageFailed(f"stage {name} stopped with exit status {returncode} and no message (killed?); log: {log_path}")
