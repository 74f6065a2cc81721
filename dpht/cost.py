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
    return targets + [paths.HEADLINE_MD.format(run=plan.name, variant=v) for v in plan.variants]


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
    from geometry.layout import layout

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


def estimate(found: Iterable[Scene], jobs: Jobs, cores: int, cold: bool, rates: Rates = RATES) -> Estimate:
    """The :class:`Estimate` of the DEM and thermal runs among ``jobs`` (each stage key once,
    however many scenes share it) on ``cores`` cores: a DEM run occupies its ranks, a thermal run
    its threads; ``cold``: numba's cache is (the first screening and thermal jobs compile)."""
    dem, thermal = {}, {}
    for s in found:
        if s.dem_key in jobs.keys.get("dem", ()):
            dem[s.dem_key] = (s.dem_s, min(s.ranks, cores))
        if s.thermal_key in jobs.keys.get("thermal", ()):
            thermal[s.thermal_key] = (s.thermal_s, min(THERMAL_THREADS, cores))
    compiling = sum(rates.compile_s.values()) if cold and (thermal or "screening" in jobs.counts) else 0.0
    core_seconds = sum(t * n for t, n in [*dem.values(), *thermal.values()])
    return Estimate(len(dem), sum(t for t, _ in dem.values()), len(thermal), sum(t for t, _ in thermal.values()),
                    compiling, core_seconds / cores + compiling)  # fmt: skip


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
