"""What a config's run will do and cost on this machine, before it runs (``dpht check``, ``dpht run``).

Per scene that runs a DEM and a thermal stage (the design variants, the Watkins scenes, the mixer
study's variants): the particles the DEM will insert (its fill estimate, :attr:`DemParams.n_particles`),
its steps and frames, its time step as a fraction of the Rayleigh time, the thermal frames, the
warnings the DEM stage will log (:func:`dpht.dem.liggghts.parameter_warnings`), and the wall time
of both stages at the rates measured here (:data:`RATES`). The jobs that would run are Snakemake's
own dry run of the project's Snakefile (:func:`dry_run`), so they are the jobs ``dpht run`` and
``snakemake`` run, cached stages left out.

The plan is built and read in one place, :func:`load_plan` (:func:`dpht.plan.from_workflow`),
:func:`scenes` and :func:`design_targets`, the only functions here that know the :class:`dpht.plan.Plan`.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from dpht.errors import DPHTError

PROJECT = Path(__file__).resolve().parent.parent
SNAKEFILE = PROJECT / "Snakefile"
BASE_CONFIG = Path("config/config.yaml")  # the Snakefile's `configfile:`, relative to the working folder


@dataclass(frozen=True)
class Rates:
    """Wall-time rates of the stages on this machine, and where they were measured."""

    dem_particle_steps_per_rank_s: float  # particles x DEM steps per second and MPI rank of a LIGGGHTS run
    dem_overhead_s: float  # per DEM job: start-up, meshes, gathering the dumps
    thermal_particle_frames_per_s: float  # particles x thermal frames per second of a thermal run (2 threads)
    thermal_overhead_s: float  # per thermal job: set-up, error estimate, writing
    compile_s: dict  # stage -> s of numba compiling on a cold cache (the first run only)
    measured: str  # the runs, the dates and the machine's load


# The rates are those of the longest runs measured here (docs/manual/performance.md, 2 December 2026,
# the whole default run on two otherwise quiet cores), which the short runs of config/quick.yaml
# agree with; the overheads and compile times are the quick runs' (3 December 2026).
RATES = Rates(
    dem_particle_steps_per_rank_s=2.0e6,
    dem_overhead_s=2.0,
    thermal_particle_frames_per_s=4.5e5,
    thermal_overhead_s=4.0,
    compile_s={"screening": 60.0, "thermal": 10.0},
    measured="DEM: the mixer study's three runs of about 10,400 particles x 181,200-183,200 steps, one rank each and "
             "two side by side, 13.9-18.1 min (1.7-2.3e6 particle-steps/s; docs/manual/performance.md, 2 December 2026, "
             "`snakemake --cores 2`); "
             "config/quick.yaml's base tube here, 422 x 41,000 steps in 7.07 s (2.45e6/s, load 3.5; 0.8e6/s at load 8). "
             "Thermal: the Watkins slice, 16,463 particles x 4,819 frames in 3.0 min (4.4e5 particle-frames/s), the "
             "mixer study's 10,400 x 435 in 8-9 s, the default tube's 2,807 x 151 in 2 s (docs/manual/performance.md). "
             "Compiling: "
             "`snakemake results/quick/base/summary.json --cores 2 --configfile config/quick.yaml` on a cold cache, "
             "3 December 2026, load 3.5: the screening job 64 s, most of it compiling, the thermal run about 10 s more",
)


# --- the plan -----------------------------------------------------------------------------------


def scenes(plan) -> dict[str, tuple[dict, dict]]:
    """Every scene of ``plan`` that runs a DEM and a thermal stage, label -> (its merged config,
    its stage keys): the design variants (by name) and the scenes of the studies planned (labelled
    ``<study> <label>``, e.g. ``watkins watkins``, ``mixers flat_plate``)."""
    found = {name: (plan.configs[name], plan.keys[name]) for name in plan.variants}
    for study, planned in plan.studies.items():  # registered again: the same keys, no run setting replaced
        found.update({f"{study} {label}": (c, plan.register_scenes({label: c}, study=True)[label])
                      for label, c in planned.scenes.items()})  # fmt: skip
    return found


def design_targets(plan) -> list[str]:
    """The targets of the design variants alone (their figures, summaries and headlines, and their
    comparison), without the studies (radiation, intra-particle, Watkins, mixers)."""
    from dpht import paths

    studies = {t for name in plan.asked for t in plan.study_targets(name)}
    targets = [t for t in plan.targets() if t not in studies]
    return targets + [paths.HEADLINE_MD.format(run=plan.name, variant=v) for v in plan.compared]  # a chain has none


def workflow_files(configs: Sequence[str | Path], directory: Path) -> list[Path]:
    """The config files the workflow merges, in order: the Snakefile's config/config.yaml of the
    working folder ``directory`` (when there is one and it is not given) and then ``configs``."""
    here = Path(directory).resolve() == Path.cwd()  # then the paths as the user spelled them, for messages

    def spelled(path) -> Path:
        return Path(path) if here else Path(path).resolve()

    given = [spelled(c) for c in configs]
    base = spelled(Path(directory) / BASE_CONFIG)
    return ([base] if base.is_file() and base.resolve() not in {c.resolve() for c in given} else []) + given


def load_plan(configs: Sequence[str | Path], directory: Path = Path(".")):
    """The workflow's plan of ``configs`` run in ``directory``, as ``snakemake --configfile CONFIGS``
    builds it there (validated and pre-flight checked: :func:`dpht.plan.from_workflow`)."""
    from dpht import config
    from dpht.plan import from_workflow

    if not Path(directory).is_dir():
        raise DPHTError(f"working folder {directory}: no such folder")
    files = workflow_files(configs, directory)
    with contextlib.chdir(directory):  # files named in the config are relative to it, as under Snakemake
        return from_workflow(config.Sources(files).merged(), files, files[len(files) - len(configs):])


# --- one scene ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scene:
    """What one scene's DEM and thermal stages will do, and their estimated wall times (s)."""

    label: str
    dem_key: str
    thermal_key: str
    particles: int  # the DEM's fill estimate
    ranks: int
    dem_steps: int  # fill, settle and flow
    settle_steps: int
    dem_frames: int
    thermal_frames: int
    rayleigh_fraction: float  # dem.timestep / Rayleigh time
    warnings: tuple[str, ...]
    dem_s: float
    thermal_s: float


def scene(label: str, cfg: dict, keys: dict, rates: Rates = RATES) -> Scene:
    """The :class:`Scene` of a merged config ``cfg`` (checked already: :func:`load_plan`) and its
    stage ``keys``, with the DEM stage's parameters and thermal frames as the pre-flight check
    computes them (:func:`dpht.preflight.dem_params`, :func:`dpht.preflight.thermal_times`)."""
    from dpht import preflight
    from dpht.dem.liggghts import parameter_warnings
    from dpht.geometry.layout import layout

    params = preflight.dem_params(cfg, layout(cfg["geometry"], cfg["particles"]["diameter"]))
    steps = params.steps()
    frames = preflight.thermal_times(cfg, params).size
    n = params.n_particles
    return Scene(
        label=label, dem_key=keys["dem"], thermal_key=keys["thermal"], particles=n, ranks=cfg["dem"]["ranks"],
        dem_steps=steps["flow_end"], settle_steps=steps["settle_end"],
        dem_frames=(steps["flow_end"] - steps["settle_end"]) // params.dump_interval + 1, thermal_frames=frames,
        rayleigh_fraction=params.timestep / params.rayleigh_time, warnings=tuple(parameter_warnings(params)),
        dem_s=rates.dem_overhead_s + n * steps["flow_end"] / (rates.dem_particle_steps_per_rank_s * cfg["dem"]["ranks"]),
        thermal_s=rates.thermal_overhead_s + n * frames / rates.thermal_particle_frames_per_s,
    )  # fmt: skip


# --- the jobs -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Jobs:
    """Snakemake's dry run: jobs per rule (in its order), their total, and the stage keys of the
    keyed jobs (rule -> keys, e.g. the DEM and thermal runs that are not cached)."""

    counts: dict
    total: int
    keys: dict


def snakemake_command(configs: Sequence[str | Path], directory: Path, targets: Sequence[str] = (),
                      options: Sequence[str] = ()) -> list[str]:  # fmt: skip
    """The snakemake command running the project's Snakefile on ``configs`` in ``directory``."""
    return [sys.executable, "-m", "snakemake", "--snakefile", str(SNAKEFILE), "--directory", str(directory),
            *options, *targets, "--configfile", *(str(Path(c).resolve()) for c in configs)]  # fmt: skip


def environment() -> dict:
    """The environment of the snakemake process: this dpht first on the Python path, so that the
    Snakefile and the stages import the dpht that plans them."""
    path = os.environ.get("PYTHONPATH")
    return {**os.environ, "PYTHONPATH": str(PROJECT) + (os.pathsep + path if path else "")}


_RULE = re.compile(r"^(?:local)?(?:rule|checkpoint|localcheckpoint) (\w+):$")
_KEY = re.compile(r"^\s+wildcards: .*\bkey=([0-9a-f]{12})\b")


def parse_dry_run(text: str) -> Jobs:
    """The :class:`Jobs` of a dry run's output (its first "Job stats" table, and each job's rule
    and ``key`` wildcard)."""
    if "Nothing to be done" in text and "Job stats:" not in text:
        return Jobs({}, 0, {})
    try:
        table = text.split("Job stats:", 1)[1].split("\n\n", 1)[0]
    except IndexError:
        raise DPHTError(f"snakemake's dry run printed no job table:\n{text[-2000:]}") from None
    counts, total = {}, None
    for line in table.splitlines()[3:]:
        name, count = line.split()
        if name == "total":
            total = int(count)
        else:
            counts[name] = int(count)
    keys, rule = {}, None
    for line in text.splitlines():
        if match := _RULE.match(line):
            rule = match.group(1)
        elif rule and (match := _KEY.match(line)):
            keys.setdefault(rule, set()).add(match.group(1))
    return Jobs(counts, total if total is not None else sum(counts.values()), keys)


def dry_run(configs: Sequence[str | Path], directory: Path, targets: Sequence[str] = ()) -> Jobs:
    """The jobs ``snakemake --dry-run`` plans for ``configs`` in ``directory`` (the jobs ``dpht run``
    would run)."""
    result = subprocess.run(snakemake_command(configs, directory, targets, ["--dry-run"]), capture_output=True,
                            text=True, env=environment())  # fmt: skip
    if result.returncode != 0:
        raise DPHTError(f"snakemake's dry run failed:\n{(result.stderr or result.stdout)[-3000:]}")
    return parse_dry_run(result.stdout + result.stderr)


THERMAL_THREADS = 2  # the thermal rule's threads (workflow/rules/thermal.smk)


@dataclass(frozen=True)
class Estimate:
    """Estimated wall times (s) of the DEM and thermal runs a dry run plans."""

    dem_runs: int
    dem_s: float  # one after the other
    thermal_runs: int
    thermal_s: float
    compile_s: float  # numba compiling, when its cache is cold
    wall_s: float  # on ``cores`` cores: core-seconds / cores, plus compiling


def planned_runs(found: Iterable[Scene], jobs: Jobs, cores: int) -> dict[tuple[str, str], tuple[float, int]]:
    """``(stage, key)`` -> (estimated wall time s, cores it occupies) of each DEM and thermal run
    among ``jobs`` (each stage key once, however many scenes share it) on ``cores`` cores: a DEM run
    occupies its ranks, a thermal run its threads."""
    runs = {}
    for s in found:
        if s.dem_key in jobs.keys.get("dem", ()):
            runs[("dem", s.dem_key)] = (s.dem_s, min(s.ranks, cores))
    for s in found:
        if s.thermal_key in jobs.keys.get("thermal", ()):
            runs[("thermal", s.thermal_key)] = (s.thermal_s, min(THERMAL_THREADS, cores))
    return runs


def estimate(found: Iterable[Scene], jobs: Jobs, cores: int, cold: bool, rates: Rates = RATES) -> Estimate:
    """The :class:`Estimate` of the DEM and thermal runs among ``jobs`` (:func:`planned_runs`) on
    ``cores`` cores; ``cold``: numba's cache is (the first screening and thermal jobs compile)."""
    runs = planned_runs(found, jobs, cores)
    dem = [t for (stage, _), (t, _) in runs.items() if stage == "dem"]
    thermal = [t for (stage, _), (t, _) in runs.items() if stage == "thermal"]
    compiling = sum(rates.compile_s.values()) if cold and (thermal or "screening" in jobs.counts) else 0.0
    core_seconds = sum(t * n for t, n in runs.values())
    return Estimate(len(dem), sum(dem), len(thermal), sum(thermal), compiling, core_seconds / cores + compiling)


# --- the overall progress of a workflow run --------------------------------------------------------


class Overall:
    """One overall progress line of a workflow run, printed when it starts, when each stage job
    starts and ends, and when it ends (workflow/rules/common.smk)::

        overall: 2.1 min of 18.3 min estimated done (1/4 DEM and thermal runs), 3.0 min elapsed, ETA 23.1 min

    The total is the estimate ``dpht check`` previews (:func:`estimate`: the DEM and thermal runs
    of the jobs Snakemake will run, their share of the cores, and numba's compiling on a cold
    cache). A run is done when all its outputs were written after the workflow started; compiling
    is done once the first screening or thermal job is. The ETA is the estimate of what is not done
    scaled by the measured time so far over the estimate of what is done (elapsed / done, 1 before
    anything is done), so it follows this machine's load: the time of the jobs that are not
    estimated (geometry, tables, figures) and of runs still going counts in the elapsed time
    only. Each line stats the outputs of the estimated jobs, nothing more."""

    def __init__(self, found: Iterable[Scene], jobs: Jobs, outputs: dict, cores: int, cold: bool, clock=time.time):
        """``outputs``: ``(rule, key)`` -> the output files of each job Snakemake will run."""
        found = list(found)
        self.clock = clock
        self.start = clock()
        self.total = estimate(found, jobs, cores, cold)
        self.runs = {run: (t * n / cores, outputs.get(run, ())) for run, (t, n) in planned_runs(found, jobs, cores).items()}
        compiled_by = [files for (rule, _), files in outputs.items() if rule in ("screening", "thermal")]
        self.compiling = (self.total.compile_s, compiled_by)
        self.lock = threading.Lock()

    @classmethod
    def of_jobs(cls, plan, jobs: Iterable[tuple[str, str | None, Sequence[str]]], cores: int) -> Overall:
        """For ``plan`` and the jobs Snakemake will run, each ``(rule, key wildcard or None, output files)``."""
        jobs = list(jobs)
        counts, keys = {}, {}
        for rule, key, _ in jobs:
            counts[rule] = counts.get(rule, 0) + 1
            if key is not None:
                keys.setdefault(rule, set()).add(key)
        found = [scene(label, c, k) for label, (c, k) in scenes(plan).items()]
        outputs = {(rule, key): tuple(files) for rule, key, files in jobs if key is not None}
        return cls(found, Jobs(counts, len(jobs), keys), outputs, cores, not kernels_cached())

    def _written(self, files) -> bool:
        return bool(files) and all(os.path.exists(f) and os.path.getmtime(f) >= self.start for f in files)

    def done_s(self) -> float:
        """Estimated seconds of the work done so far."""
        done = sum(share for share, files in self.runs.values() if self._written(files))
        seconds, compiled_by = self.compiling
        return done + (seconds if any(self._written(files) for files in compiled_by) else 0.0)

    def line(self) -> str:
        elapsed = self.clock() - self.start
        total = self.total.wall_s
        if total == 0:
            return f"overall: no DEM or thermal run to do, {duration(elapsed)} elapsed"
        done = self.done_s()
        finished = sum(self._written(files) for _, files in self.runs.values())
        ratio = elapsed / done if done > 0 else 1.0
        return (f"overall: {duration(done)} of {duration(total)} estimated done ({finished}/{len(self.runs)} DEM and "
                f"thermal runs), {duration(elapsed)} elapsed, ETA {duration((total - done) * ratio)}")

    def report(self, event: str = "", stream=None) -> None:
        """Print the line (``event`` after it in brackets) to ``stream`` (standard error)."""
        with self.lock:
            print(self.line() + (f" [{event}]" if event else ""), file=stream or sys.stderr, flush=True)

    def explain(self) -> str:
        """How the line is computed, for the first line of a run."""
        e = self.total
        return (f"overall: estimated {duration(e.wall_s)} of wall time for {e.dem_runs} DEM and {e.thermal_runs} thermal "
                "run(s)" + (" and numba compiling" if e.compile_s else "") + " on these cores, as dpht check previews it "
                "(dpht/cost.py RATES; the other jobs are not estimated); the ETA is the estimate of what is left times "
                "the time elapsed over the estimate of what is done")


def duration(seconds: float) -> str:
    """``seconds`` for a reader: s below 90 s, min below 90 min, else h."""
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min" if seconds < 5400 else f"{seconds / 3600:.1f} h"


# --- numba's cache ------------------------------------------------------------------------------


def kernels_cached() -> bool:
    """Whether numba's on-disk cache holds compiled thermal kernels (:mod:`dpht.thermal.kernels`)
    of its present source (:func:`dpht.util.numba_cache.holds`). The kernels are composed per set of
    modes and compiled per composition, which a new set of modes compiles too, in seconds."""
    from dpht.thermal import kernels
    from dpht.util import numba_cache

    return numba_cache.holds(kernels.pair_side.__wrapped__)


def compile_notice(stage: str, log) -> None:
    """Log that numba is about to compile, and about how long it takes, when its cache of the
    thermal kernels is cold (:func:`kernels_cached`): the first run is otherwise silent for a minute."""
    if not kernels_cached():
        log(f"{stage}: compiling the thermal kernels (first run only, ~{RATES.compile_s[stage]:.0f} s on this machine)")
