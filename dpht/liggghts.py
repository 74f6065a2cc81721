"""The DEM stage: LIGGGHTS decks rendered from the config, run as a subprocess, resumable.

Two decks (templates in ``dpht/decks``) run in one work directory::

    settle.in   fill the tube above the orifice (closed by a temporary plane), settle, write
                settle/settled.restart                                (reused while unchanged)
    flow.in     remove the plane; particles leave through the orifice and re-enter at the top
                through the periodic boundary z = 0 | L; dumps flow/post/dump.<step>.txt every
                dem.dump_interval steps, restarts flow/restart/flow.<step>.restart
    meshes/     copies of the wall STLs the decks read (so the decks do not depend on paths)

The tube wall is by default LIGGGHTS' exact ``zcylinder`` primitive and only the other zones
(the orifice plate) are STL meshes: on this machine the 0.5 d gmsh tube mesh (13,800 triangles)
made a 3,000-particle step 4x slower (5.6 ms against 1.4 ms). ``dem.tube_wall: mesh`` uses the
tube STLs instead. The thermal stage always uses the meshed zones.

Resume: a flow restart file counts as complete only when a thermo line at or after its step was
printed (LIGGGHTS writes dumps, then restarts, then thermo, in that order within a step, and the
screen is line-buffered), so a file cut short by a kill is never read. An interrupted flow
continues from the newest complete restart; dumps from that step on are deleted and rewritten.
Each stage stores a digest of its deck and meshes: a changed config re-runs only what depends on it.

After the flow the dumps are gathered into one HDF5 file (:mod:`dpht.dumps`) and deleted.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import math
import os
import shutil
import string
import signal
import subprocess
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Callable

import h5py

from . import dumps
from .errors import ConfigError, DPHTError, ExternalToolError

WALL_ZONES = ("heated_wall", "adiabatic_wall", "orifice")  # STL files <zone>.stl from the geometry stage
TUBE_ZONES = ("heated_wall", "adiabatic_wall")  # the cylinder, replaced by a primitive unless tube_wall = "mesh"
TUBE_WALLS = ("primitive", "mesh")
# Hertz normal contact, tangential history, rolling friction epsd2: pairs and walls (DPHT paper, Table 2).
CONTACT_MODEL = "model hertz tangential history rolling_friction epsd2"
GRAVITY = 9.81  # m/s2, along -z
# Mean solid fraction of the poured bed, to size the fill for dem.fill_height. Measured here with
# the default contact properties: 0.53 for 1 mm particles in the 9 mm tube (a 43.8 mm bed for
# 42 mm asked), 0.47 in a shallow 8 mm-wide bed. The summary reports the settled bed height.
FILL_SOLID_FRACTION = 0.55
INSERT_INTERVAL = 0.01  # s between insertion events
INSERT_VOLUME_FRACTION = 0.2  # particles requested per event, as a solid fraction of the empty region
INSERT_SPEED = 0.5  # m/s downwards, so each event's particles clear the region for the next one
INSERT_EVENTS_MARGIN = 3  # events run per event needed, since later events find less free space
SKIN = 0.25  # neighbour skin in particle diameters
RAYLEIGH_WARN, RAYLEIGH_MAX = 0.2, 0.5  # dem.timestep as a fraction of the Rayleigh time
TAIL_LINES = 30
PROGRESS_SECONDS = 10.0

SETTLE_DIR, FLOW_DIR, MESH_DIR = "settle", "flow", "meshes"
SETTLED_RESTART = f"{SETTLE_DIR}/settled.restart"
RESTART_GLOB = "flow.*.restart"
SCREEN_GLOB = "screen.*.txt"  # one screen file per flow attempt


# --------------------------------------------------------------------------------------------
# Parameters


def _get(spec: dict, key: str):
    node = spec
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConfigError(f"DEM spec: missing key {key!r}")
        node = node[part]
    return node


def _number(spec: dict, key: str, *, low: float = 0.0, high: float = math.inf, integer: bool = False):
    value = _get(spec, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{key} = {value!r}: expected a finite number")
    if integer and value != int(value):
        raise ConfigError(f"{key} = {value!r}: expected an integer")
    if not low < value <= high:
        raise ConfigError(f"{key} = {value!r}: expected a value in ({low}, {high}]")
    return int(value) if integer else float(value)


def _is_prime(n: int) -> bool:
    return n > 1 and all(n % k for k in range(2, math.isqrt(n) + 1))


def _next_prime(n: int) -> int:
    n += 1
    while not _is_prime(n):
        n += 1
    return n


def _ceil_to(value: int, multiple: int) -> int:
    return -(-value // multiple) * multiple


def rayleigh_time(radius: float, density: float, youngs_modulus: float, poisson_ratio: float) -> float:
    """Rayleigh wave time (s) across a particle: pi r sqrt(rho/G) / (0.1631 nu + 0.8766), G = E/(2(1+nu)).

    The usual DEM time-step bound (the form LIGGGHTS' fix check/timestep/gran evaluates).
    """
    shear_modulus = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    return math.pi * radius * math.sqrt(density / shear_modulus) / (0.1631 * poisson_ratio + 0.8766)


@dataclass(frozen=True)
class DemParams:
    """Everything the decks and the run need, derived from the config sections (SI units)."""

    diameter: float
    density: float
    youngs_p: float
    poisson_p: float
    youngs_w: float
    poisson_w: float
    restitution: tuple[float, float]  # (pp, pw)
    friction: tuple[float, float]
    rolling: tuple[float, float]
    tube_diameter: float
    length: float
    orifice_height: float
    orifice_diameter: float
    timestep: float
    fill_height: float
    settle_time: float
    flow_time: float
    dump_interval: int
    restart_interval: int
    seed: int
    precision: str
    tube_wall: str

    @classmethod
    def from_spec(cls, spec: dict) -> "DemParams":
        if not isinstance(spec, dict):
            raise ConfigError(f"DEM spec must be a mapping of config sections, got {type(spec).__name__}")
        pair = {
            name: (_number(spec, f"contact.{name}.pp", high=high), _number(spec, f"contact.{name}.pw", high=high))
            for name, high in (("restitution", 1.0), ("friction", math.inf), ("rolling_friction", math.inf))
        }
        dem = _get(spec, "dem")
        if not isinstance(dem, dict):
            raise ConfigError(f"dem must be a mapping, got {type(dem).__name__}")
        precision = dem.get("position_precision", "float64")
        if precision not in dumps.PRECISIONS:
            raise ConfigError(f"dem.position_precision = {precision!r}: expected one of {dumps.PRECISIONS}")
        tube_wall = dem.get("tube_wall", "primitive")
        if tube_wall not in TUBE_WALLS:
            raise ConfigError(f"dem.tube_wall = {tube_wall!r}: expected one of {TUBE_WALLS}")
        params = cls(
            diameter=_number(spec, "particles.diameter"),
            density=_number(spec, "particles.density"),
            youngs_p=_number(spec, "particles.youngs_modulus_dem"),
            poisson_p=_number(spec, "particles.poisson_ratio", high=0.5),
            youngs_w=_number(spec, "wall.youngs_modulus_dem"),
            poisson_w=_number(spec, "wall.poisson_ratio", high=0.5),
            restitution=pair["restitution"],
            friction=pair["friction"],
            rolling=pair["rolling_friction"],
            tube_diameter=_number(spec, "geometry.tube.inner_diameter"),
            length=_number(spec, "geometry.tube.length"),
            orifice_height=_number(spec, "geometry.tube.orifice_height"),
            orifice_diameter=_number(spec, "geometry.tube.orifice_diameter"),
            timestep=_number(spec, "dem.timestep"),
            fill_height=_number(spec, "dem.fill_height"),
            settle_time=_number(spec, "dem.settle_time"),
            flow_time=_number(spec, "dem.flow_time"),
            dump_interval=_number(spec, "dem.dump_interval", integer=True),
            restart_interval=_number(spec, "dem.restart_interval", integer=True),
            seed=_number(spec, "dem.seed", low=10000, integer=True),
            precision=precision,
            tube_wall=tube_wall,
        )
        params._check()
        return params

    def _check(self) -> None:
        d = self.diameter
        if self.tube_diameter <= 2.0 * d:
            raise ConfigError(f"geometry.tube.inner_diameter = {self.tube_diameter} m must exceed 2 particle diameters")
        if not d < self.orifice_diameter < self.tube_diameter:
            raise ConfigError(
                f"geometry.tube.orifice_diameter = {self.orifice_diameter} m must lie between the particle "
                f"diameter {d} m and the tube diameter {self.tube_diameter} m"
            )
        top = self.orifice_height + self.fill_height
        if top > self.length - d:
            raise ConfigError(
                f"geometry.tube.orifice_height + dem.fill_height = {top} m must stay a particle diameter below "
                f"the top of the periodic tube (geometry.tube.length = {self.length} m)"
            )
        if self.restart_interval % self.dump_interval:
            raise ConfigError(
                f"dem.restart_interval = {self.restart_interval} must be a multiple of dem.dump_interval = "
                f"{self.dump_interval}, so a resumed run continues the dump sequence without a gap"
            )
        if not _is_prime(self.seed):
            raise ConfigError(f"dem.seed = {self.seed}: LIGGGHTS needs a prime > 10000, e.g. {_next_prime(self.seed)}")

    # Derived quantities ------------------------------------------------------------------

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    @property
    def mesh_zones(self) -> tuple[str, ...]:
        """Wall zones LIGGGHTS reads as STL meshes."""
        return WALL_ZONES if self.tube_wall == "mesh" else tuple(z for z in WALL_ZONES if z not in TUBE_ZONES)

    @property
    def particle_mass(self) -> float:
        """kg."""
        return self.density * math.pi * self.diameter**3 / 6.0

    @property
    def rayleigh_time(self) -> float:
        return rayleigh_time(self.radius, self.density, self.youngs_p, self.poisson_p)

    @property
    def n_particles(self) -> int:
        """Particles to insert so the settled bed reaches about dem.fill_height above the orifice plate."""
        bed_volume = math.pi * (0.5 * self.tube_diameter) ** 2 * self.fill_height
        return round(FILL_SOLID_FRACTION * bed_volume * 6.0 / (math.pi * self.diameter**3))

    def steps(self) -> dict[str, int]:
        """Step counts: insertion events, end of fill/settle/flow (settle and flow end on dump steps)."""
        insert_every = max(1, round(INSERT_INTERVAL / self.timestep))
        per_event = max(1, math.floor(INSERT_VOLUME_FRACTION * self._fill_region_volume() / self._particle_volume()))
        fill_end = INSERT_EVENTS_MARGIN * math.ceil(self.n_particles / per_event) * insert_every
        settle_end = _ceil_to(fill_end + round(self.settle_time / self.timestep), self.dump_interval)
        flow_end = settle_end + _ceil_to(max(1, round(self.flow_time / self.timestep)), self.dump_interval)
        return {
            "insert_every": insert_every,
            "per_event": per_event,
            "fill_end": fill_end,
            "settle_end": settle_end,
            "flow_end": flow_end,
        }

    def _particle_volume(self) -> float:
        return math.pi * self.diameter**3 / 6.0

    def _fill_region(self) -> tuple[float, float, float]:
        """Insertion cylinder (radius, z_lo, z_hi): inside the tube, from the plate to the top."""
        gap = 1.1 * self.radius
        return 0.5 * self.tube_diameter - gap, self.orifice_height + gap, self.length - gap

    def _fill_region_volume(self) -> float:
        radius, z_lo, z_hi = self._fill_region()
        return math.pi * radius**2 * (z_hi - z_lo)


# --------------------------------------------------------------------------------------------
# Decks


class _DeckTemplate(string.Template):
    delimiter = "@"  # LIGGGHTS uses $ for its own variables


def _fmt(value) -> str:
    return str(value) if isinstance(value, int) else repr(float(value))


def _template(name: str) -> _DeckTemplate:
    return _DeckTemplate(resources.files("dpht.decks").joinpath(name).read_text())


def _wall_fixes(params: DemParams) -> str:
    zones = params.mesh_zones
    lines = [f"fix {zone} all mesh/surface file {MESH_DIR}/{zone}.stl type 2" for zone in zones]
    lines.append(f"fix walls all wall/gran {CONTACT_MODEL} mesh n_meshes {len(zones)} meshes {' '.join(zones)}")
    if params.tube_wall == "primitive":
        radius = _fmt(0.5 * params.tube_diameter)
        lines.append(f"fix tube_wall all wall/gran {CONTACT_MODEL} primitive type 2 zcylinder {radius} 0.0 0.0")
    return "\n".join(lines)


def render_decks(params: DemParams) -> dict[str, str]:
    """The deck texts ``{"settle.in": ..., "flow.in": ...}``; identical for identical params."""
    steps = params.steps()
    fill_radius, fill_zlo, fill_zhi = params._fill_region()
    half_width = 0.5 * params.tube_diameter + params.diameter  # wall mesh strictly inside the box
    seed_template = _next_prime(params.seed)
    values = {
        "contact_model": CONTACT_MODEL,
        "wall_fixes": _wall_fixes(params),
        "skin": SKIN * params.diameter,
        "youngs_p": params.youngs_p,
        "youngs_w": params.youngs_w,
        "poisson_p": params.poisson_p,
        "poisson_w": params.poisson_w,
        "restitution_pp": params.restitution[0],
        "restitution_pw": params.restitution[1],
        "friction_pp": params.friction[0],
        "friction_pw": params.friction[1],
        "rolling_pp": params.rolling[0],
        "rolling_pw": params.rolling[1],
        "timestep": params.timestep,
        "gravity": GRAVITY,
        "thermo_every": params.dump_interval,
        "xlo": -half_width,
        "xhi": half_width,
        "ylo": -half_width,
        "yhi": half_width,
        "length": params.length,
        "orifice_height": params.orifice_height,
        "seed_insert": params.seed,
        "seed_template": seed_template,
        "seed_distribution": _next_prime(seed_template),
        "density": params.density,
        "radius": params.radius,
        "fill_radius": fill_radius,
        "fill_zlo": fill_zlo,
        "fill_zhi": fill_zhi,
        "n_particles": params.n_particles,
        "insert_rate": steps["per_event"] / (steps["insert_every"] * params.timestep),
        "insert_every": steps["insert_every"],
        "insert_velocity": -INSERT_SPEED,
        "fill_end": steps["fill_end"],
        "settle_end": steps["settle_end"],
        "settled_restart": SETTLED_RESTART,
        "restart_every": params.restart_interval,
        "restart_files": f"{FLOW_DIR}/restart/{RESTART_GLOB}",
        "dump_every": params.dump_interval,
        "dump_files": f"{FLOW_DIR}/post/{dumps.DUMP_GLOB}",
        "flow_end": steps["flow_end"],
    }
    values = {key: _fmt(value) if not isinstance(value, str) else value for key, value in values.items()}
    model = _template("model.in").substitute(values).rstrip()
    return {name: _template(name).substitute(values, model=model) for name in ("settle.in", "flow.in")}


# --------------------------------------------------------------------------------------------
# Running LIGGGHTS


# The thermo_style columns of decks/model.in, in order (LIGGGHTS truncates f_ID[i] in its header).
THERMO_COLUMNS = ("step", "atoms", "time", "iz_sum", "z_max", "rayleigh_fraction", "hertz_fraction")


class _ThermoParser:
    """Thermo rows (dicts keyed by THERMO_COLUMNS) from screen text fed in pieces."""

    def __init__(self):
        self._in_table = False
        self._partial = ""

    def feed(self, text: str) -> list[dict]:
        lines = (self._partial + text).split("\n")
        self._partial = lines.pop()
        rows = []
        for line in lines:
            words = line.split()
            if words[:2] == ["Step", "Atoms"]:
                self._in_table = len(words) == len(THERMO_COLUMNS)
            elif self._in_table and len(words) == len(THERMO_COLUMNS):
                try:
                    rows.append(dict(zip(THERMO_COLUMNS, map(float, words))))
                except ValueError:
                    continue
        return rows


def read_thermo(screen: Path) -> list[dict]:
    """All thermo rows printed in a LIGGGHTS screen file (none if it does not exist)."""
    if not Path(screen).is_file():
        return []
    return _ThermoParser().feed(Path(screen).read_text(errors="replace") + "\n")


def _tail(path: Path, n: int = TAIL_LINES) -> str:
    """The last ``n`` lines, preceded by any earlier ERROR lines (warnings can push them out)."""
    try:
        lines = Path(path).read_text(errors="replace").splitlines()
    except OSError:
        return "(no output)"
    errors = [line for line in lines[:-n] if "ERROR" in line]
    return "\n".join(errors + lines[-n:]) if lines else "(empty)"


def _command(deck: str, ranks: int, variables: dict[str, str]) -> tuple[list[str], dict[str, str]]:
    executable = shutil.which("liggghts")
    if executable is None:
        raise ExternalToolError(
            "LIGGGHTS executable 'liggghts' not found on PATH; install it with "
            "'apt-get install --no-install-recommends liggghts' (see the Makefile)"
        )
    # Line-buffered stdout: LIGGGHTS aborts through MPI_Abort without flushing, which would
    # otherwise lose the ERROR line. Screen goes to stdout: '-screen none' segfaults with meshes.
    command = ["stdbuf", "-oL", "-eL"] if shutil.which("stdbuf") else []
    command += [executable, "-in", deck, "-log", "none"]
    for name, value in variables.items():
        command += ["-var", name, value]
    env = dict(os.environ)
    if ranks > 1:
        if shutil.which("mpirun") is None:
            raise ExternalToolError(
                f"{ranks} MPI ranks requested but 'mpirun' is not on PATH (apt-get install openmpi-bin)"
            )
        mpi = ["mpirun", "-np", str(ranks)]
        if ranks > (os.cpu_count() or 1):
            mpi.append("--oversubscribe")
        if os.geteuid() == 0:
            env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
        # Idle ranks yield the core instead of spinning: twice as fast here when the cores are shared.
        env.setdefault("OMPI_MCA_mpi_yield_when_idle", "1")
        command = mpi + command
    return command, env


def run_liggghts(
    deck: str,
    cwd: Path,
    screen: Path,
    *,
    ranks: int = 1,
    variables: dict[str, str] | None = None,
    on_thermo: Callable[[dict], None] | None = None,
    pass_fds: tuple[int, ...] = (),
) -> float:
    """Run LIGGGHTS on ``deck`` (relative to ``cwd``), screen output to ``screen``; returns wall time (s).

    ``on_thermo`` is called with each thermo row as it is printed. A non-zero exit raises
    ExternalToolError with the tail of the screen file. The child stays in the caller's process
    group (Ctrl-C or a group kill stops it too) and is terminated if this function is interrupted.
    """
    command, env = _command(deck, ranks, variables or {})
    parser = _ThermoParser()
    start = time.monotonic()
    with _sigterm_raises(), open(screen, "wb") as out, open(screen, "rb") as follow:
        proc = subprocess.Popen(command, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, env=env, pass_fds=pass_fds)
        try:
            while True:
                finished = proc.poll() is not None
                for row in parser.feed(follow.read().decode(errors="replace")):
                    if on_thermo:
                        on_thermo(row)
                if finished:
                    break
                time.sleep(0.5)
        finally:
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
    if proc.returncode != 0:
        code = proc.returncode
        how = f"was killed by signal {-code}" if code < 0 else f"exited with code {code}"
        raise _tool_error(f"LIGGGHTS {how} running {deck} in {cwd}.", screen)
    return time.monotonic() - start


def _tool_error(what: str, screen: Path) -> ExternalToolError:
    return ExternalToolError(
        f"{what}\n--- last {TAIL_LINES} lines of {screen} ---\n{_tail(screen)}\n--- full screen output: {screen}"
    )


@contextmanager
def _sigterm_raises():
    """In the main thread, turn SIGTERM into SystemExit so that LIGGGHTS is stopped on the way out.

    Python's default SIGTERM action exits without unwinding, which would orphan LIGGGHTS.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def leave(signum, frame):
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, leave)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class _Progress:
    """Log one thermo row at most every PROGRESS_SECONDS, plus the last one.

    Times are counted from ``start_step`` (LIGGGHTS' own clock restarts at every read_restart).
    """

    def __init__(self, label: str, start_step: int, end_step: int, timestep: float, log):
        self.label, self.start, self.end, self.timestep, self.log = label, start_step, end_step, timestep, log
        self.last = -math.inf

    def __call__(self, row: dict) -> None:
        now = time.monotonic()
        step = int(row["step"])
        if now - self.last < PROGRESS_SECONDS and step < self.end:
            return
        self.last = now
        elapsed, total = (step - self.start) * self.timestep, (self.end - self.start) * self.timestep
        self.log(
            f"DEM {self.label}: step {step}/{self.end}, t = {elapsed:.3f}/{total:.3f} s, "
            f"{int(row['atoms'])} particles, {-int(row['iz_sum'])} through the orifice"
        )


# --------------------------------------------------------------------------------------------
# Work directory state


def _digest(*parts: str | bytes) -> str:
    h = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


def _read_state(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _write_state(path: Path, state: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(state, indent=2, sort_keys=True) + "\n")
    tmp.replace(path)


class _WorkdirLock:
    """An exclusive lock on the work directory, inherited by LIGGGHTS so an orphaned run still holds it."""

    def __init__(self, workdir: Path):
        self.path = workdir / ".dem.lock"

    def __enter__(self) -> "_WorkdirLock":
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = self.path.read_text().strip() or "?"
            os.close(self.fd)
            raise DPHTError(
                f"DEM work directory {self.path.parent} is in use by another run (lock {self.path}, "
                f"taken by pid {holder}); wait for it, or end that process (and its LIGGGHTS) first"
            ) from None
        os.ftruncate(self.fd, 0)
        os.write(self.fd, str(os.getpid()).encode())
        return self

    def __exit__(self, *exc) -> None:
        os.close(self.fd)


def _stage_meshes(zones: tuple[str, ...], mesh_dir: Path, workdir: Path) -> bytes:
    """Copy the zone STLs into ``workdir/meshes``; returns their names and contents' digest."""
    target = workdir / MESH_DIR
    target.mkdir(exist_ok=True)
    h = hashlib.sha256()
    for zone in zones:
        source = mesh_dir / f"{zone}.stl"
        if not source.is_file() or source.stat().st_size == 0:
            raise DPHTError(f"wall mesh {source} is missing or empty; the DEM needs {', '.join(zones)} (.stl)")
        data = source.read_bytes()
        (target / source.name).write_bytes(data)
        h.update(zone.encode() + hashlib.sha256(data).digest())
    return h.digest()


# --------------------------------------------------------------------------------------------
# Stages


def _settle(params: DemParams, workdir: Path, key: str, ranks: int, log, lock: _WorkdirLock) -> dict:
    settle_dir = workdir / SETTLE_DIR
    state_path = settle_dir / "state.json"
    state = _read_state(state_path)
    if state.get("key") == key and (workdir / SETTLED_RESTART).is_file():
        log(f"DEM settle: reusing the settled bed in {settle_dir} ({state['particles']} particles)")
        return state
    shutil.rmtree(settle_dir, ignore_errors=True)
    shutil.rmtree(workdir / FLOW_DIR, ignore_errors=True)  # a new bed invalidates the flow
    settle_dir.mkdir()
    steps = params.steps()
    log(
        f"DEM settle: inserting {params.n_particles} particles (d = {params.diameter} m) in "
        f"{steps['fill_end']} steps, settling until step {steps['settle_end']}; ranks = {ranks}"
    )
    screen = settle_dir / "screen.txt"
    wall = run_liggghts(
        "settle.in",
        workdir,
        screen,
        ranks=ranks,
        variables={},
        on_thermo=_Progress("settle", 0, steps["settle_end"], params.timestep, log),
        pass_fds=(lock.fd,),
    )
    rows = read_thermo(screen)
    if not rows or int(rows[-1]["step"]) != steps["settle_end"] or not (workdir / SETTLED_RESTART).is_file():
        raise _tool_error(
            f"LIGGGHTS finished settle.in without reaching step {steps['settle_end']} or writing {SETTLED_RESTART}.",
            screen,
        )
    inserted = int(max(row["atoms"] for row in rows))
    state = {
        "key": key,
        "step": steps["settle_end"],
        "particles_target": params.n_particles,
        "particles_inserted": inserted,
        "particles": int(rows[-1]["atoms"]),
        "bed_top_m": rows[-1]["z_max"] + params.radius,
        "rayleigh_fraction_liggghts": rows[-1]["rayleigh_fraction"],
        "wall_time_s": round(wall, 2),
        "ranks": ranks,
    }
    bed = state["bed_top_m"] - params.orifice_height
    log(
        f"DEM settle: {state['particles']} particles settled in {wall:.0f} s; bed height {bed * 1e3:.1f} mm "
        f"above the orifice plate (dem.fill_height {params.fill_height * 1e3:.1f} mm)"
    )
    if inserted < params.n_particles:
        log(f"DEM settle: warning: only {inserted} of {params.n_particles} particles could be inserted")
    if state["particles"] < inserted:
        log(f"DEM settle: warning: {inserted - state['particles']} particles left the domain while settling")
    _write_state(state_path, state)
    return state


def _resume_point(flow_dir: Path, settle_end: int) -> tuple[int, str]:
    """Newest complete flow restart (step, path relative to the work directory), else the settled bed."""
    reached = max(
        (int(row["step"]) for screen in flow_dir.glob(SCREEN_GLOB) for row in read_thermo(screen)), default=-1
    )
    for step, path in reversed(dumps.numbered_files(flow_dir / "restart", RESTART_GLOB).items()):
        if step <= reached and path.stat().st_size > 0:
            return step, f"{FLOW_DIR}/restart/{path.name}"
    return settle_end, SETTLED_RESTART


def _flow(params: DemParams, workdir: Path, key: str, ranks: int, log, lock: _WorkdirLock) -> dict:
    flow_dir = workdir / FLOW_DIR
    state_path = flow_dir / "state.json"
    steps = params.steps()
    state = _read_state(state_path)
    if state.get("key") == key and state.get("complete") and dumps.dump_files(flow_dir / "post"):
        return state
    if state.get("key") != key or state.get("complete"):
        if state.get("key") == key:
            log("DEM flow: its dumps were gathered into a positions file that is gone or differs; running it again")
        shutil.rmtree(flow_dir, ignore_errors=True)
        state = {"key": key, "complete": False, "attempts": []}
    for sub in ("restart", "post"):
        (flow_dir / sub).mkdir(parents=True, exist_ok=True)  # LIGGGHTS fails silently without them
    start, restart_file = _resume_point(flow_dir, steps["settle_end"])
    for step, path in dumps.numbered_files(flow_dir / "restart", RESTART_GLOB).items():
        if step > start:
            path.unlink()
    for step, path in dumps.dump_files(flow_dir / "post").items():
        if step >= start:
            path.unlink()
    attempt = 1 + max(dumps.numbered_files(flow_dir, SCREEN_GLOB), default=0)
    screen = flow_dir / f"screen.{attempt}.txt"
    if start > steps["settle_end"]:
        log(f"DEM flow: resuming from {restart_file} (step {start} of {steps['settle_end']}..{steps['flow_end']})")
    else:
        log(
            f"DEM flow: steps {steps['settle_end']}..{steps['flow_end']}, dump every {params.dump_interval}; "
            f"ranks = {ranks}"
        )
    state["attempts"].append({"start_step": start, "screen": screen.name, "ranks": ranks, "wall_time_s": None})
    _write_state(state_path, state)
    wall = run_liggghts(
        "flow.in",
        workdir,
        screen,
        ranks=ranks,
        variables={"restart_file": restart_file},
        on_thermo=_Progress("flow", steps["settle_end"], steps["flow_end"], params.timestep, log),
        pass_fds=(lock.fd,),
    )
    state["attempts"][-1]["wall_time_s"] = round(wall, 2)
    rows = read_thermo(screen)
    if not rows or int(rows[-1]["step"]) != steps["flow_end"] or not dumps.dump_files(flow_dir / "post"):
        raise _tool_error(
            f"LIGGGHTS finished flow.in without reaching step {steps['flow_end']} or without writing dumps.", screen
        )
    state["complete"] = True
    state["hertz_fraction_max"] = max(
        row["hertz_fraction"] for path in flow_dir.glob(SCREEN_GLOB) for row in read_thermo(path)
    )
    _write_state(state_path, state)
    return state


def _gather(params: DemParams, workdir: Path, out_h5: Path, key: str, settle: dict, flow: dict, log) -> dict:
    files = dumps.dump_files(workdir / FLOW_DIR / "post")
    log(f"DEM gather: {len(files)} dump files -> {out_h5}")
    partial = out_h5.with_name(out_h5.name + ".part")
    stats = dumps.write_positions(
        partial,
        dumps.read_dumps(files.values()),
        radius=params.radius,
        density=params.density,
        timestep=params.timestep,
        dump_interval=params.dump_interval,
        precision=params.precision,
        attrs={"source_key": key},
    )
    steps = params.steps()
    if stats.steps[0] != steps["settle_end"] or stats.steps[-1] != steps["flow_end"]:
        raise DPHTError(
            f"dumps in {workdir / FLOW_DIR / 'post'} cover steps {stats.steps[0]}..{stats.steps[-1]}, "
            f"expected {steps['settle_end']}..{steps['flow_end']}"
        )
    summary = _summary(params, settle, flow, stats)
    dumps.set_summary(partial, summary)
    partial.replace(out_h5)
    for path in files.values():
        path.unlink()
    flow_rate = summary["mass_flow_kg_s"]
    log(
        f"DEM done: {summary['particles']} particles, {stats.n_frames} frames, mass flow {flow_rate * 1e3:.3f} g/s "
        f"({summary['orifice_crossings']} crossings), lost {summary['lost_particles']['count']}"
    )
    if summary["jammed"]:
        log("DEM warning: no particle left through the orifice in the second half of the flow: the bed jammed")
    if summary["lost_particles"]["count"]:
        log(f"DEM warning: lost particles (id: first step missing) {summary['lost_particles']['first_step']}")
    return summary


def _summary(params: DemParams, settle: dict, flow: dict, stats: dumps.GatherStats) -> dict:
    """The run summary stored in the positions file (JSON-serialisable)."""
    times = (stats.steps - stats.steps[0]) * params.timestep
    half = stats.n_frames // 2
    mass = params.particle_mass

    def rate(first: int) -> float:
        span = times[-1] - times[first]
        return float(mass * (stats.crossings[-1] - stats.crossings[first]) / span) if span > 0 else 0.0

    lost = dict(sorted(stats.lost_first_step.items()))
    return {
        "particles": stats.n_particles,
        "particles_target": settle["particles_target"],
        "particles_inserted": settle["particles_inserted"],
        "particle_mass_kg": mass,
        "bed_top_settled_m": settle["bed_top_m"],
        "frames": stats.n_frames,
        "flow_steps": [int(stats.steps[0]), int(stats.steps[-1])],
        "mass_flow_kg_s": rate(0),
        "mass_flow_second_half_kg_s": rate(half),
        "mass_flow_method": (
            "net particle crossings of the periodic boundary z = 0 below the orifice (image flag iz in the "
            "dumps) times the particle mass, over the whole flow phase; also over its second half"
        ),
        "orifice_crossings": int(stats.crossings[-1]),
        "jammed": bool(stats.crossings[-1] == stats.crossings[half]),
        "lost_particles": {
            "count": len(lost),
            "ids": list(lost),
            "first_step": {str(k): v for k, v in lost.items()},
        },
        "rayleigh_time_s": params.rayleigh_time,
        "rayleigh_fraction": params.timestep / params.rayleigh_time,
        "rayleigh_fraction_liggghts": settle["rayleigh_fraction_liggghts"],
        "hertz_fraction_max": flow["hertz_fraction_max"],
        "flow_attempts": [attempt["start_step"] for attempt in flow["attempts"]],
        # MPI ranks change the trajectories (summation order, insertion near subdomain borders).
        "ranks": {"settle": settle["ranks"], "flow": [attempt["ranks"] for attempt in flow["attempts"]]},
        "wall_time_s": {
            "settle": settle["wall_time_s"],
            "flow": round(sum(a["wall_time_s"] or 0.0 for a in flow["attempts"]), 2),
        },
    }


def _existing(out_h5: Path, key: str) -> dict | None:
    """The summary of ``out_h5`` if it was gathered from exactly this run, else None."""
    if not out_h5.is_file():
        return None
    try:
        with h5py.File(out_h5, "r") as h5:
            if h5.attrs.get("source_key") == key:
                return json.loads(h5.attrs["summary"])
    except (OSError, KeyError, ValueError):
        pass
    return None


def run_dem(spec: dict, mesh_dir: Path, workdir: Path, out_h5: Path, ranks: int = 1, log=print) -> dict:
    """Run the DEM stage (fill + settle, flow, gather) and return the run summary.

    ``spec`` holds the config sections ``particles``, ``wall``, ``contact``, ``geometry``, ``dem``;
    ``mesh_dir`` the zone STLs (``heated_wall.stl``, ``adiabatic_wall.stl``, ``orifice.stl``);
    ``workdir`` keeps the rendered decks, LIGGGHTS output and restart files; ``out_h5`` receives
    the positions file. Calling again after an interruption resumes; after success it is a no-op.
    """
    params = DemParams.from_spec(spec)
    if isinstance(ranks, bool) or not isinstance(ranks, int) or ranks < 1:
        raise DPHTError(f"ranks = {ranks!r}: expected a positive integer (MPI ranks)")
    mesh_dir, workdir, out_h5 = Path(mesh_dir), Path(workdir), Path(out_h5)
    fraction = params.timestep / params.rayleigh_time
    log(f"DEM: timestep {params.timestep} s = {fraction:.3f} of the Rayleigh time {params.rayleigh_time:.3e} s")
    if fraction > RAYLEIGH_MAX:
        raise ConfigError(
            f"dem.timestep = {params.timestep} s is {fraction:.2f} of the Rayleigh time {params.rayleigh_time:.3e} s; "
            f"keep it below {RAYLEIGH_WARN} (at most {RAYLEIGH_WARN * params.rayleigh_time:.2e} s)"
        )
    if fraction > RAYLEIGH_WARN:
        log(f"DEM warning: timestep above {RAYLEIGH_WARN} of the Rayleigh time; contacts may be inaccurate")
    if params.orifice_diameter < 5.0 * params.diameter:
        log("DEM warning: orifice narrower than 5 particle diameters; the bed may jam")
    workdir.mkdir(parents=True, exist_ok=True)
    out_h5.parent.mkdir(parents=True, exist_ok=True)
    with _WorkdirLock(workdir) as lock:
        mesh_digest = _stage_meshes(params.mesh_zones, mesh_dir, workdir)
        decks = render_decks(params)
        for name, text in decks.items():
            (workdir / name).write_text(text)
        settle_key = _digest(decks["settle.in"], mesh_digest)
        flow_key = _digest(settle_key, decks["flow.in"])
        gather_key = _digest(flow_key, json.dumps(asdict(params), sort_keys=True))
        summary = _existing(out_h5, gather_key)
        if summary is not None:
            log(f"DEM: {out_h5} is up to date")
            return summary
        settle = _settle(params, workdir, settle_key, ranks, log, lock)
        flow = _flow(params, workdir, flow_key, ranks, log, lock)
        return _gather(params, workdir, out_h5, gather_key, settle, flow, log)
