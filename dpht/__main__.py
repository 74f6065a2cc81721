"""Command line: ``python -m dpht <command>`` (also installed as ``dpht``).

Commands:
  check CONFIG ...    validate config files, check all they ask for as the workflow does first, and
                      preview the run: particles, steps, frames, cost here, jobs (docs/manual/designing.md)
  run CONFIG          run a config end to end (the project's Snakefile, --configfile CONFIG)
  verify [NAME ...]   run the verification cases (``--list`` to list them)
  stage NAME          run one workflow stage (called by the Snakemake rules)
  rdf POSITIONS       radiation distribution factors of one bed by Monte Carlo ray tracing
  export FOLDER       a thermal run as a self-contained folder for ParaView
  calibrate-orifice   find geometry.tube.orifice_diameter for a target mass flow
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path

from dpht.cost import duration
from dpht.errors import USER_ERRORS, DPHTError


def _verify(args) -> int:
    from dpht.verification import harness as verify

    if args.list:
        for name, case in verify.cases().items():
            print(f"{name:<34s} {case.description} [{case.unit}]")
        return 0
    if args.out:
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise DPHTError(f"verify --out {args.out}: cannot make the folder ({err.strerror})") from None
    try:
        outcomes = verify.run(args.names, out=args.out)
    except KeyError as err:
        raise DPHTError(str(err.args[0])) from None
    skipped = [o.name for o in outcomes if o.skipped]
    failed = [o.name for o in outcomes if not o.passed and not o.skipped]
    ran = len(outcomes) - len(skipped)
    print(f"{ran - len(failed)}/{ran} passed" + (f"; FAILED: {', '.join(failed)}" if failed else "")
          + (f"; skipped (a program is missing): {', '.join(skipped)}" if skipped else ""))
    for outcome in outcomes:  # the cases' own lines last, e.g. cooled-sphere's "mean relative error: VALUE"
        for line in outcome.notes:
            print(line)
    return 1 if failed else 0




def _scene_lines(s) -> list[str]:
    from dpht.dem.liggghts import RAYLEIGH_MAX, RAYLEIGH_WARN

    return [f"  DEM: {s.particles:,} particles (fill estimate), {s.dem_steps:,} steps (settled at step "
            f"{s.settle_steps:,}), {s.dem_frames} frames, {s.ranks} rank{'s' * (s.ranks > 1)}; time step "
            f"{s.rayleigh_fraction:.3f} of the Rayleigh time (warned above {RAYLEIGH_WARN}, refused above {RAYLEIGH_MAX})",
            f"  thermal: {s.thermal_frames} frames of {s.particles:,} particles",
            f"  estimate here: DEM ~{duration(s.dem_s)}, thermal ~{duration(s.thermal_s)}",
            *(f"  {warning}" for warning in s.warnings)]  # fmt: skip


def _chain_lines(c: dict) -> list[str]:
    """A scene's chain (:class:`dpht.chain.segments.Chain`), its segments in flow order in particle
    diameters, for ``check``; none without a ``chain`` section."""
    from dpht.chain.segments import RESOLVED, Chain

    if "chain" not in c:
        return []
    chain, d = Chain.of(c), c["particles"]["diameter"]

    def what(s) -> str:
        inside = [f"mixers[{i.index}]" for i in s.inserts] + ["the orifice plate"] * s.outlet
        return f"{s.kind} {s.top / d:.1f}-{s.bottom / d:.1f} d" + (f" ({', '.join(inside)})" if inside else "")

    shapes = chain.shapes(c["geometry"])
    resolved = sum(s.kind == RESOLVED for s in chain.segments)
    slices = len(chain.segments) > resolved
    return [f"  chain: {len(chain.segments)} segments from z = {chain.inlet / d:.1f} d down to {chain.outlet / d:.1f} d "
            f"(hand-over field {chain.field.rings} rings x {chain.field.sectors} sector(s); slices "
            f"{chain.slice_length / d:.3g} d): " + ", ".join(map(what, chain.segments)),
            f"    {resolved} resolved segment(s) of {len(shapes)} shape(s): {len(shapes) + slices} DEM run(s) (one per "
            f"resolved shape{', one for every slice' * slices}), {len(chain.segments)} segment jobs in flow order, "
            "summed up in chain.json"]  # fmt: skip


def _preview(args, plan, targets, cores: int):
    """What the run of ``plan`` will do (:mod:`dpht.cost`): (its scenes, Snakemake's jobs, their
    cost estimate); the last two None with ``--no-jobs``."""
    from dpht import cost

    found = [cost.scene(label, c, keys) for label, (c, keys) in cost.scenes(plan).items()]
    if args.no_jobs:
        return found, None, None
    jobs = cost.dry_run(args.configs, Path(args.directory), targets)
    cold = not cost.kernels_cached()
    return found, jobs, cost.estimate(found, jobs, cores, cold)


def _estimate_lines(jobs, estimate) -> list[str]:
    from dpht.cost import RATES

    lines = [f"jobs to run (snakemake --dry-run): {jobs.total}"
             + (": " + ", ".join(f"{rule} {n}" for rule, n in jobs.counts.items()) if jobs.counts else " (all done)")]
    if jobs.total:
        lines.append(f"estimated here: {estimate.dem_runs} DEM run(s) ~{duration(estimate.dem_s)}, {estimate.thermal_runs} "
                     f"thermal run(s) ~{duration(estimate.thermal_s)}"
                     + (f", numba compiling ~{duration(estimate.compile_s)} (its cache is cold)" if estimate.compile_s else "")
                     + f"; about {duration(estimate.wall_s)} of wall time for these on the cores given (the other jobs are "
                       "not estimated)")  # fmt: skip
        if "screening" in jobs.counts:
            lines.append("  (Snakemake plans the HTC tables after the screening jobs, its checkpoints: a few more jobs may follow)")
        lines.append(f"  (at {RATES.dem_particle_steps_per_rank_s:.2g} DEM particle-steps/s per rank and "
                     f"{RATES.thermal_particle_frames_per_s:.2g} thermal particle-frames/s, measured here: dpht/cost.py, RATES)")
    return lines


def _check(args) -> int:
    from dpht import cost

    plan = cost.load_plan(args.configs, Path(args.directory))
    targets = cost.design_targets(plan) if args.designs else []
    found, jobs, estimate = _preview(args, plan, targets, args.cores)
    by_label = {s.label: s for s in found}
    for name, keys in plan.keys.items():
        print(f"{name}: " + ", ".join(f"{stage} {key}" for stage, key in keys.items() if key))
        print("\n".join(_scene_lines(by_label[name]) + _chain_lines(plan.configs[name])))
    for s in found:
        if s.label not in plan.keys:
            print(f"{s.label}: dem {s.dem_key}, thermal {s.thermal_key}")
            print("\n".join(_scene_lines(s)))
    files = [str(f) for f in cost.workflow_files(args.configs, Path(args.directory))]
    print(f"{', '.join(files)}: valid; {len(plan.runs)} stage runs planned for {len(plan.variants)} variant(s)")
    if jobs is not None:
        print("\n".join(_estimate_lines(jobs, estimate)))
    return 0


def _run(args) -> int:
    import subprocess
    import time

    from dpht import cost, integrity

    plan = cost.load_plan(args.configs, Path(args.directory))  # its errors before Snakemake starts
    targets = args.targets or (cost.design_targets(plan) if args.designs else [])
    found, jobs, estimate = _preview(args, plan, targets, args.cores)
    dem_runs = {}
    for s in found:
        dem_runs.setdefault(s.dem_key, []).append(s.label)
    print("DEM runs (their progress lines carry the key): "
          + "; ".join(f"{key} {', '.join(labels)}" for key, labels in dem_runs.items()), file=sys.stderr)  # fmt: skip
    if jobs is not None:
        for line in _estimate_lines(jobs, estimate):
            print(line, file=sys.stderr)
        if jobs.total and not args.dry_run:
            finish = time.strftime("%H:%M", time.localtime(time.time() + estimate.wall_s))
            print(f"dpht run: {jobs.total} jobs; by the estimate above, its DEM and thermal runs are done about {finish}",
                  file=sys.stderr)  # fmt: skip
    options = ["--cores", str(args.cores), *(["--dry-run"] if args.dry_run else [])]
    env = {**cost.environment(), **({integrity.HASH_ALL: "1"} if args.hash_all else {})}
    return subprocess.run(cost.snakemake_command(args.configs, Path(args.directory), targets, options),
                          env=env).returncode  # fmt: skip


def _stage(args) -> int:
    from dpht import stages

    return stages.run(args.name, args.spec, args.io, args.log, errors_to_log_only=args.errors_to_log_only)


def _calibrate_orifice(args) -> int:
    from dpht import config
    from dpht.stages import calibrate_config

    result = calibrate_config(
        config.variant(config.load(args.config), args.variant),
        args.workdir,
        target=args.target,
        tolerance=args.tolerance,
        flow_time=args.flow_time,
        max_runs=args.max_runs,
        ranks=args.ranks,
        mpi=args.mpi,
        log=lambda line: print(line, file=sys.stderr),
    )
    print(f"target {result['target_mass_flow'] * 1e3:.4g} g/s, tolerance {result['mass_flow_tolerance']:.0%}")
    for run in result["runs"]:
        print(f"  orifice_diameter {run['orifice_diameter']:.6g} m: {run['mass_flow_kg_s'] * 1e3:.4g} g/s "
              f"({run['relative_error']:+.1%})")
    verdict = "within tolerance" if result["converged"] else "NOT within tolerance"
    print(f"geometry.tube.orifice_diameter: {result['orifice_diameter']:.6g}  # {verdict}")
    return 0 if result["converged"] else 1


def _rdf(args) -> int:
    from dpht.radiation.bed_rdf import rdf_command

    return rdf_command(args)


def _export(args) -> int:
    from dpht import export

    sources = export.find_sources(args.folder, positions=args.positions, walls=args.walls)
    out = export.export(sources, args.out or args.folder / "paraview")
    print(f"{out}: open {out / export.PARTICLES} and {out / export.WALLS} in ParaView")
    return 0


EXPORT_CONTENTS = (
    "Particles (position, radius, temperature, id) and the wall mesh (zone, surface, area, normal, wall temperature, heat "
    "flux into the particles in W/m^2 per particle-wall mode and in total) per thermal frame, as particles.pvd and "
    "walls.pvd with their .vtp files and a README.md; every path is relative, so the folder can be copied elsewhere."
)
RDF_OVERLAP_RULE = (
    "Overlapping spheres: the tracer treats every sphere as whole, so the cap of a sphere buried in a neighbour "
    "(delta/4R of its surface for an overlap delta) still emits, and its rays cross the neighbour unseen. Overlaps "
    "up to --max-overlap are traced as they are; deeper ones, and spheres cut deeper by a plane wall, are refused."
)


def bounded(kind: type, low: float | None = None, high: float | None = None, *, above: bool = False,
            below: bool = False):
    """An argparse type: a finite ``kind`` (int or float) >= ``low`` (> with ``above``) and <= ``high``
    (< with ``below``), refused with the option, the value and what it expects when the command line
    is read, before any work; an integer may be written as 1e6."""
    bounds = [f"{'>' if above else '>='} {low:g}"] if low is not None else []
    bounds += [f"{'<' if below else '<='} {high:g}"] if high is not None else []
    expected = " ".join([f"{'an integer' if kind is int else 'a number'}", " and ".join(bounds)]).strip()

    def parse(text: str):
        try:
            value = int(text) if kind is int and text.strip().lstrip("+-").isdigit() else float(text)
        except ValueError:
            value = math.nan
        if kind is int and isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        inside = (low is None or (value > low if above else value >= low)) and (
            high is None or (value < high if below else value <= high))
        if not (isinstance(value, kind) and math.isfinite(value) and inside):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    return parse


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m dpht", description=__doc__.split("\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)

    p = commands.add_parser("check", help="validate config files, check everything they ask for and preview the run "
                                          "(particles, steps, cost, jobs), before any job")  # fmt: skip
    p.add_argument("configs", nargs="+", metavar="CONFIG",
                   help="config files, later ones override earlier ones, all over config/config.yaml of the working "
                        "folder when it has one (as snakemake --configfile merges them)")  # fmt: skip
    _run_options(p)
    p.set_defaults(func=_check)

    p = commands.add_parser("run", help="run a config end to end: the project's Snakefile with --configfile CONFIG")
    p.add_argument("configs", nargs=1, metavar="CONFIG", help="config file, over config/config.yaml of the working folder")
    p.add_argument("targets", nargs="*", metavar="TARGET", help="files to make (default: the workflow's, rule all)")
    p.add_argument("--dry-run", "-n", action="store_true", help="show the jobs, run none")
    p.add_argument("--hash-all", action="store_true",
                   help="hash every result of earlier runs at the start, not only those whose file times or size "
                        "changed (DPHT_HASH_ALL=1)")  # fmt: skip
    _run_options(p)
    p.set_defaults(func=_run)

    p = commands.add_parser("verify", help="run verification cases against exact or reference solutions")
    p.add_argument("names", nargs="*", help="cases to run (default: all)")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    p.add_argument("--out", type=Path, help="folder for the CSV files and figures of the cases that write them")
    p.set_defaults(func=_verify)

    p = commands.add_parser("stage", help="run one workflow stage (used by the Snakemake rules)")
    p.add_argument("name")
    p.add_argument("--spec", required=True, help="stage parameters as JSON")
    p.add_argument("--io", required=True, help="input/output paths and threads as JSON")
    p.add_argument("--log", help="also write progress and errors to this file")
    p.add_argument("--errors-to-log-only", action="store_true", help="write the error message to --log only")
    p.set_defaults(func=_stage)

    p = commands.add_parser("rdf", help="RDF matrix of one bed by Monte Carlo ray tracing (CSV, N x (N+2))",
                            description=RDF_OVERLAP_RULE)
    # Negative numbers such as -5e-4 are values, not options (argparse's own test misses exponents):
    # with the plane normal -1e-3 or a negative radius, the message is ours, not "expected one argument".
    p._negative_number_matcher = re.compile(r"^-\.?\d")
    p.add_argument("positions", help="text file with 'x y z' (m) per particle and line")
    p.add_argument("--radius", type=float, required=True, help="particle radius, m")
    p.add_argument("--emissivity", type=float, required=True, help="particle emissivity, (0, 1]")
    p.add_argument("--rays", type=bounded(int, 1), required=True, help="rays emitted per particle (1e6 is 1000000)")
    p.add_argument("--wall-plane", type=float, nargs=6, action="append", metavar=("PX", "PY", "PZ", "NX", "NY", "NZ"),
                   help="an infinite plane wall through P with normal N (repeatable)")  # fmt: skip
    p.add_argument("--wall-mesh", action="append", metavar="FILE", help="a wall from a mesh file in m (repeatable)")
    p.add_argument("--wall-emissivity", type=float, default=1.0, help="emissivity of all walls, [0, 1] (default 1)")
    p.add_argument("--box", type=float, nargs=6, metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"), help="periodic box, m")
    p.add_argument("--periodic", default="", help="periodic axes, e.g. 'xy' (needs --box)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--max-overlap", type=float, default=0.05,
                   help="deepest overlap between spheres, or of a sphere and a plane wall, traced as it is, in radii "
                        "(default 0.05); deeper ones are refused")  # fmt: skip
    p.add_argument("--out", required=True, help="output CSV: row i = RDFs to particles 0..N-1, walls, lost")
    p.set_defaults(func=_rdf)

    p = commands.add_parser("export", help="a thermal run as a self-contained folder for ParaView (.pvd of .vtp files)",
                            description=EXPORT_CONTENTS)
    p.add_argument("folder", type=Path,
                   help="a variant's results (results/<variant>) or a thermal run (results/thermal/<key>)")
    p.add_argument("--out", type=Path,
                   help="folder to write (default: FOLDER/paraview); an earlier export there is replaced")
    p.add_argument("--positions", type=Path, help="the DEM run's positions.h5 (default: from the variant's summary)")
    p.add_argument("--walls", type=Path, help="the geometry run's walls.h5 (default: from the variant's summary)")
    p.set_defaults(func=_export)

    p = commands.add_parser(
        "calibrate-orifice", help="find the orifice diameter giving a target mass flow (a few short DEM runs)"
    )
    p.add_argument("config", help="config file (e.g. config/config.yaml)")
    p.add_argument("--target", type=bounded(float, 0, above=True), help="mass flow in kg/s (default: dem.target_mass_flow)")
    p.add_argument("--variant", default="base", help="design variant to calibrate (default: base)")
    p.add_argument("--tolerance", type=bounded(float, 0, 1, above=True, below=True),
                   help="relative (default: dem.mass_flow_tolerance or 0.1)")
    p.add_argument("--flow-time", type=bounded(float, 0, above=True), help="s of flow per run (default: dem.flow_time)")
    p.add_argument("--max-runs", type=bounded(int, 1), default=6, help="DEM runs at most (default: 6)")
    p.add_argument("--ranks", type=bounded(int, 1), help="MPI ranks (default: dem.ranks)")
    p.add_argument("--mpi", default="mpirun", help="MPI launcher for ranks > 1, e.g. srun (default: mpirun)")
    p.add_argument("--workdir", default="results/calibrate-orifice", help="folder for the trial runs")
    p.set_defaults(func=_calibrate_orifice)
    return parser


def _run_options(p) -> None:
    """The options ``check`` and ``run`` share: they plan the same run."""
    p.add_argument("--directory", "-d", default=".", help="working folder: results/ and its config/config.yaml "
                                                          "(default: the current folder)")  # fmt: skip
    p.add_argument("--cores", "-c", type=bounded(int, 1), default=os.cpu_count() or 1,
                   help="cores for Snakemake (default: all of this machine's)")  # fmt: skip
    p.add_argument("--designs", action="store_true",
                   help="only the design variants' outputs (figures, summaries, headlines, comparison), not the studies")
    p.add_argument("--no-jobs", action="store_true", help="skip Snakemake's dry run (the jobs and their cost)")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except USER_ERRORS as err:
        print(f"dpht: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
