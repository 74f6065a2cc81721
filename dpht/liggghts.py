"""The DEM stage: LIGGGHTS decks rendered from the config, run as a subprocess, resumable.

Two decks (templates in ``dpht/decks``) run in one work directory::

    settle.in   fill the tube above the orifice (closed by a temporary plane), settle, write
                settle/settled.restart                                (reused while unchanged)
    flow.in     remove the plane; particles leave through the orifice and re-enter at the top
                through the periodic boundary z = 0 | L; dumps flow/post/dump.<step>.txt every
                dem.dump_interval steps, restarts flow/restart/flow.<step>.restart
    meshes/     copies of the wall STLs the decks read (so the decks do not depend on paths)

The wall zones come from the geometry stage (its ``geometry.json`` and one ``<zone>.stl`` each):
every zone is a ``fix mesh/surface`` (ID ``mesh_<zone>``) except the tube's cylinder, which is by
default LIGGGHTS' exact ``zcylinder`` primitive: on this machine the 0.5 d gmsh tube mesh (13,800
triangles) made a 3,000-particle step 4x slower (5.6 ms against 1.4 ms). ``dem.tube_wall: mesh``
uses the tube STLs instead. The thermal stage always uses the meshed zones. Mixers (closed solids
with their z ranges in ``geometry.json``) are kept out of the insertion region, which is one
cylinder per free slab between orifice plate, mixers and the top; particles inserted above a
mixer settle through its passages, and the fill count leaves out the mixers' volume.

Resume: a flow restart file counts as complete only when a thermo line at or after its step was
printed (LIGGGHTS writes dumps, then restarts, then thermo, in that order within a step, and the
screen is line-buffered), so a file cut short by a kill is never read. An interrupted flow
continues from the newest complete restart; dumps from that step on are deleted and rewritten.
Each stage stores a digest of its deck and meshes: a changed config re-runs only what depends on it.

After the flow the dumps are gathered into one HDF5 file (:mod:`dpht.dumps`) and deleted. Its
run summary adds the solid fraction at the wall and in the bulk, the passages through each mixer
and, given ``dem.target_mass_flow``, whether the flow is within ``dem.mass_flow_tolerance`` of it;
:func:`calibrate_orifice` searches the orifice diameter for a target flow.
"""

from __future__ import annotations

import copy
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
import numpy as np

from . import dumps
from .errors import ConfigError, DPHTError, ExternalToolError

GEOMETRY_SUMMARY = "geometry.json"  # the geometry stage's summary, next to its zone STLs
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
MASS_FLOW_TOLERANCE = 0.1  # default dem.mass_flow_tolerance, relative
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
class MixerExtent:
    """A mixer as the DEM sees it, from the geometry summary: its z range (m) and solid volume (m^3)."""

    key: str
    zone: str
    z_bottom: float
    z_top: float
    volume: float


def read_geometry(mesh_dir: Path) -> dict:
    """The geometry stage's summary (``geometry.json``) in ``mesh_dir``: wall zones and mixers."""
    path = Path(mesh_dir) / GEOMETRY_SUMMARY
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise DPHTError(f"{path} is missing: the DEM takes its wall zones and mixers from the geometry stage") from None
    except (OSError, ValueError) as err:
        raise DPHTError(f"{path}: unreadable geometry summary ({err})") from None


def _layout(spec: dict, geometry: dict) -> tuple[tuple[str, ...], tuple[MixerExtent, ...]]:
    """Zone names and mixers of a geometry summary, checked to be built from the spec's geometry."""
    if not isinstance(geometry, dict):
        raise DPHTError(f"geometry summary must be a mapping (geometry.json), got {type(geometry).__name__}")
    built, wanted = geometry.get("geometry") or {}, _get(spec, "geometry")
    for key in ("tube", "mixers"):
        if (built.get(key) or None) != (wanted.get(key) or None):
            raise DPHTError(
                f"the geometry summary was built for geometry.{key} = {built.get(key)!r}, but the DEM spec has "
                f"{wanted.get(key)!r}: rebuild the geometry"
            )
    try:
        zones = tuple(str(zone) for zone in geometry["zone_names"])
        mixers = tuple(
            MixerExtent(m["key"], m["zone"], float(m["z_range"][0]), float(m["z_range"][1]), float(m["volume"]))
            for m in geometry.get("mixers", [])
        )
    except (KeyError, TypeError, IndexError, ValueError) as err:
        raise DPHTError(f"geometry summary: missing or malformed entry {err}") from None
    return zones, mixers


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
    zones: tuple[str, ...]  # every wall zone of the geometry, one STL each
    mixers: tuple[MixerExtent, ...]

    @classmethod
    def from_spec(cls, spec: dict, geometry: dict) -> "DemParams":
        """``spec``: the config sections particles, wall, contact, geometry, dem; ``geometry``: the
        geometry stage's summary (:func:`read_geometry`) of the same geometry."""
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
        zones, mixers = _layout(spec, geometry)
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
            zones=zones,
            mixers=mixers,
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
        if not self.fill_slabs():
            raise ConfigError(
                "geometry.mixers leave no free height of a particle diameter between the orifice plate, the "
                "mixers and the top of the tube in which to insert particles"
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
    def tube_radius(self) -> float:
        return 0.5 * self.tube_diameter

    @property
    def mesh_zones(self) -> tuple[str, ...]:
        """Wall zones LIGGGHTS reads as STL meshes: all but the cylinder's unless tube_wall is "mesh"."""
        return self.zones if self.tube_wall == "mesh" else tuple(z for z in self.zones if z not in TUBE_ZONES)

    @property
    def particle_mass(self) -> float:
        """kg."""
        return self.density * self._particle_volume()

    @property
    def rayleigh_time(self) -> float:
        return rayleigh_time(self.radius, self.density, self.youngs_p, self.poisson_p)

    @property
    def bed_volume(self) -> float:
        """Free volume (m^3) from the orifice plate up to dem.fill_height above it: the cylinder less
        the mixers, each counted in proportion to the part of its z range below the bed top."""
        bottom, top = self.orifice_height, self.orifice_height + self.fill_height
        volume = math.pi * self.tube_radius**2 * self.fill_height
        for mixer in self.mixers:
            inside = min(top, mixer.z_top) - max(bottom, mixer.z_bottom)
            volume -= mixer.volume * max(0.0, inside) / (mixer.z_top - mixer.z_bottom)
        return volume

    @property
    def n_particles(self) -> int:
        """Particles to insert so the settled bed reaches about dem.fill_height above the orifice plate."""
        return round(FILL_SOLID_FRACTION * self.bed_volume / self._particle_volume())

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

    @property
    def fill_radius(self) -> float:
        """Radius (m) of the insertion cylinders: inside the tube wall with a small clearance."""
        return self.tube_radius - 1.1 * self.radius

    def fill_slabs(self) -> tuple[tuple[float, float], ...]:
        """z intervals (m) of the insertion cylinders: from the orifice plate to the top of the domain,
        less the mixers' z ranges (with a clearance); gaps lower than a particle diameter are skipped.
        Particles inserted above a mixer settle through its passages."""
        gap = 1.1 * self.radius
        parts = sorted((m.z_bottom, m.z_top) for m in self.mixers if m.z_top > self.orifice_height)
        parts = [(self.orifice_height,) * 2] + parts + [(self.length,) * 2]
        slabs = [(top + gap, bottom - gap) for (_, top), (bottom, _) in zip(parts, parts[1:])]
        return tuple((lo, hi) for lo, hi in slabs if hi - lo >= self.diameter)

    def _fill_region_volume(self) -> float:
        return math.pi * self.fill_radius**2 * sum(hi - lo for lo, hi in self.fill_slabs())


# --------------------------------------------------------------------------------------------
# Decks


class _DeckTemplate(string.Template):
    delimiter = "@"  # LIGGGHTS uses $ for its own variables


def _fmt(value) -> str:
    return str(value) if isinstance(value, int) else repr(float(value))


def _template(name: str) -> _DeckTemplate:
    return _DeckTemplate(resources.files("dpht.decks").joinpath(name).read_text())


def _wall_fixes(params: DemParams) -> str:
    """One mesh/surface per STL zone (fix ID ``mesh_<zone>``, clear of the decks' other fix IDs)."""
    zones = params.mesh_zones
    ids = [f"mesh_{zone}" for zone in zones]
    lines = [f"fix {fid} all mesh/surface file {MESH_DIR}/{zone}.stl type 2" for fid, zone in zip(ids, zones)]
    lines.append(f"fix walls all wall/gran {CONTACT_MODEL} mesh n_meshes {len(ids)} meshes {' '.join(ids)}")
    if params.tube_wall == "primitive":
        lines.append(_tube_primitive(params))
    return "\n".join(lines)


def _tube_primitive(params: DemParams) -> str:
    """The tube wall as LIGGGHTS' exact cylinder."""
    return f"fix tube_wall all wall/gran {CONTACT_MODEL} primitive type 2 zcylinder {_fmt(params.tube_radius)} 0.0 0.0"


def _fill_regions(params: DemParams) -> str:
    """The insertion region ``fill``: one cylinder per free slab, their union if there are several."""
    slabs = params.fill_slabs()
    names = ["fill"] if len(slabs) == 1 else [f"fill_{k}" for k in range(1, len(slabs) + 1)]
    radius = _fmt(params.fill_radius)
    lines = [
        f"region {name} cylinder z 0.0 0.0 {radius} {_fmt(lo)} {_fmt(hi)} units box"
        for name, (lo, hi) in zip(names, slabs)
    ]
    if len(slabs) > 1:
        lines.append(f"region fill union {len(names)} {' '.join(names)}")
    return "\n".join(lines)


def _deck_values(params: DemParams) -> dict[str, str]:
    """Every deck placeholder's text."""
    steps = params.steps()
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
        "diameter": params.diameter,
        "fill_regions": _fill_regions(params),
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
    return {key: _fmt(value) if not isinstance(value, str) else value for key, value in values.items()}


def _render(name: str, values: dict[str, str]) -> str:
    model = _template("model.in").substitute(values).rstrip()
    return _template(name).substitute(values, model=model)


def render_decks(params: DemParams) -> dict[str, str]:
    """The deck texts ``{"settle.in": ..., "flow.in": ...}``; identical for identical params."""
    values = _deck_values(params)
    return {name: _render(name, values) for name in ("settle.in", "flow.in")}


def render_check_deck(params: DemParams) -> str:
    """A deck running one particle for one thermo interval in the stage's model (the tube wall as the
    primitive cylinder, no meshes), printing LIGGGHTS' own time-step check at full precision."""
    values = {**_deck_values(params), "wall_fixes": _tube_primitive(params), "mid_height": _fmt(0.5 * params.length)}
    return _render("check.in", values)


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
    with dumps.PositionsFile(partial) as positions:
        summary["solid_fraction"] = solid_fraction_report(params, positions, settle["bed_top_m"])
        summary["mixers"] = mixer_crossings(params, positions)
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
        log("DEM warning: no particle left through the orifice in the last quarter of the flow: the bed jammed")
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
        # A bed that stops flowing before the end (an orifice or mixer jams) shows no crossing in the end.
        "jammed": bool(stats.crossings[-1] == stats.crossings[(3 * stats.n_frames) // 4]),
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


def _mass_flow_target(spec: dict) -> tuple[float, float] | None:
    """(dem.target_mass_flow in kg/s, dem.mass_flow_tolerance relative), or None without a target."""
    dem = _get(spec, "dem")
    if dem.get("target_mass_flow") is None:
        return None
    tolerance = _number(spec, "dem.mass_flow_tolerance") if "mass_flow_tolerance" in dem else MASS_FLOW_TOLERANCE
    return _number(spec, "dem.target_mass_flow"), tolerance


def mass_flow_check(measured: float, target: float, tolerance: float) -> dict:
    """Compare a measured mass flow (kg/s) with its target; off target beyond the relative tolerance."""
    error = measured / target - 1.0
    return {
        "target_kg_s": target,
        "tolerance": tolerance,
        "measured_kg_s": measured,
        "relative_error": error,
        "off_target": bool(abs(error) > tolerance),
    }


def run_dem(spec: dict, mesh_dir: Path, workdir: Path, out_h5: Path, ranks: int = 1, log=print) -> dict:
    """Run the DEM stage (fill + settle, flow, gather) and return the run summary.

    ``spec`` holds the config sections ``particles``, ``wall``, ``contact``, ``geometry``, ``dem``;
    ``mesh_dir`` the geometry stage's output: ``geometry.json`` and one ``<zone>.stl`` per wall zone
    (tube, orifice plate, mixers); ``workdir`` keeps the rendered decks, LIGGGHTS output and restart
    files; ``out_h5`` receives the positions file. Calling again after an interruption resumes;
    after success it is a no-op, except that the second-half mass flow is checked again against
    the target (dem.target_mass_flow, dem.mass_flow_tolerance), which never re-runs LIGGGHTS.
    """
    mesh_dir, workdir, out_h5 = Path(mesh_dir), Path(workdir), Path(out_h5)
    params = DemParams.from_spec(spec, read_geometry(mesh_dir))
    target = _mass_flow_target(spec)
    if isinstance(ranks, bool) or not isinstance(ranks, int) or ranks < 1:
        raise DPHTError(f"ranks = {ranks!r}: expected a positive integer (MPI ranks)")
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
        else:
            settle = _settle(params, workdir, settle_key, ranks, log, lock)
            flow = _flow(params, workdir, flow_key, ranks, log, lock)
            summary = _gather(params, workdir, out_h5, gather_key, settle, flow, log)
        check = mass_flow_check(summary["mass_flow_second_half_kg_s"], *target) if target else None
        if summary.get("mass_flow_target", False) != check:
            summary["mass_flow_target"] = check
            dumps.set_summary(out_h5, summary)
    if check and check["off_target"]:
        log(
            f"DEM warning: mass flow {check['measured_kg_s'] * 1e3:.3f} g/s (second half) is "
            f"{check['relative_error']:+.1%} off the target {check['target_kg_s'] * 1e3:.3f} g/s "
            f"(dem.mass_flow_tolerance {check['tolerance']:.0%}); adjust geometry.tube.orifice_diameter, "
            "e.g. with 'python -m dpht calibrate-orifice'"
        )
    return summary


# --------------------------------------------------------------------------------------------
# Run report: solid fraction near the wall and in the bulk, passage through the mixers

SOLID_FRACTION_MARGIN = 2.0  # particle diameters between the sampled bed and the plate, bed top, mixers
PROFILE_BIN = 0.5  # radial bin width of the solid-fraction profile, particle diameters
_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_NODES, _WEIGHTS = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W  # Gauss-Legendre on [0, 1], per smooth piece


def _lens_area(c: np.ndarray, a: float, s: np.ndarray) -> np.ndarray:
    """Area (m^2) common to the disk of radius ``a`` about the origin and disks of radii ``s`` whose
    centres lie at distances ``c`` from it (arrays of equal shape)."""
    inner = c <= np.abs(a - s)
    outer = c >= a + s
    c_safe = np.where(inner | outer, 1.0, c)
    cos_a = np.clip((c_safe**2 + a**2 - s**2) / (2.0 * c_safe * a), -1.0, 1.0)
    cos_s = np.clip((c_safe**2 + s**2 - a**2) / (2.0 * c_safe * np.maximum(s, 1e-300)), -1.0, 1.0)
    kite = np.sqrt(np.maximum((-c_safe + a + s) * (c_safe + a - s) * (c_safe - a + s) * (c_safe + a + s), 0.0))
    lens = a**2 * np.arccos(cos_a) + s**2 * np.arccos(cos_s) - 0.5 * kite
    return np.where(outer, 0.0, np.where(inner, np.pi * np.minimum(a, s) ** 2, lens))


def sphere_in_cylinder(rho: np.ndarray, radius: float, a: float) -> np.ndarray:
    """Volume (m^3) of each sphere of ``radius`` centred at distance ``rho`` (m) from the z axis that
    lies inside the cylinder of radius ``a`` about that axis.

    V = 2 * integral_0^r A(z) dz, with A the lens area (:func:`_lens_area`) of the cylinder's cross-
    section and the sphere's slice of radius sqrt(r^2 - z^2). A has kinks where the slice circle
    touches the cylinder's (slice radius |a - rho| or a + rho): the integral is split there and each
    smooth piece integrated by Gauss-Legendre. Spheres wholly inside or outside are exact.
    """
    rho = np.asarray(rho, dtype=float)
    r = float(radius)
    volume = np.where(rho + r <= a, 4.0 / 3.0 * math.pi * r**3, 0.0)
    cut = (np.abs(rho - a) < r) & (a > 0.0)
    c = rho[cut][:, None]
    edges = np.hstack([
        np.zeros_like(c),
        np.sqrt(np.clip(r**2 - (a + c) ** 2, 0.0, None)),
        np.sqrt(np.clip(r**2 - (a - c) ** 2, 0.0, None)),
        np.full_like(c, r),
    ])
    widths = np.diff(edges, axis=1)  # (n, 3) pieces
    z = edges[:, :-1, None] + widths[:, :, None] * _NODES  # (n, 3, nodes)
    area = _lens_area(c[:, :, None], a, np.sqrt(np.clip(r**2 - z**2, 0.0, None)))
    volume[cut] = 2.0 * np.einsum("ij,ijk,k->i", widths, area, _WEIGHTS)
    return volume


def _sample_window(params: DemParams, bed_top: float) -> list[tuple[float, float]]:
    """z intervals (m) sampled for the solid fraction: the bed from the orifice plate to its settled
    top, less the mixers, all with a margin of SOLID_FRACTION_MARGIN particle diameters."""
    margin = SOLID_FRACTION_MARGIN * params.diameter
    start, stop = params.orifice_height + margin, bed_top - margin
    intervals = []
    for bottom, top in sorted((m.z_bottom, m.z_top) for m in params.mixers):
        if min(stop, bottom - margin) > start:
            intervals.append((start, min(stop, bottom - margin)))
        start = max(start, top + margin)
    if stop > start:
        intervals.append((start, stop))
    return intervals


def _profile_edges(params: DemParams) -> np.ndarray:
    """Radii (m) of the profile's annuli: PROFILE_BIN diameters wide counted inwards from the wall, so
    that R - d (near-wall band) and R - 2 d (bulk) are edges; the innermost bin may be narrower."""
    step, R = PROFILE_BIN * params.diameter, params.tube_radius
    edges = R - step * np.arange(math.ceil(R / step - 1e-9), -1, -1)
    edges[edges < 1e-9 * R] = 0.0
    return np.unique(edges)


def _annulus_solid(frame: dumps.PositionsFrame, radius: float, edges: np.ndarray, window) -> np.ndarray:
    """Solid volume (m^3) per window interval and annulus (n_intervals, n_annuli) of one frame, from
    the particles whose centres lie in each interval."""
    p = frame.positions[~frame.lost]
    solid = []
    for lo, hi in window:
        inside = (p[:, 2] >= lo) & (p[:, 2] < hi)
        rho = np.hypot(p[inside, 0], p[inside, 1])
        solid.append(np.diff([sphere_in_cylinder(rho, radius, a).sum() for a in edges]))
    return np.array(solid)


def solid_fraction_report(params: DemParams, positions: dumps.PositionsFile, bed_top: float) -> dict | None:
    """Solid fraction of the bed near the wall and in the bulk, settled (first frame) and flowing
    (mean over the second half of the frames, as the second-half mass flow).

    Estimator: in coaxial annuli over the sample window (:func:`_sample_window`), the volume of the
    particles (exact sphere-cylinder intersections, so a sphere straddling an edge is shared) over
    the annulus volume. Particles count by centre height: at the window's ends as many spheres stick
    out as stick in, on average. Near-wall band: the outer particle diameter, R - d < rho < R;
    bulk: rho < R - 2 d, clear of the wall's first two particle layers. Pooled over the window, and
    per window interval (mixers split the window; one that throttles the flow leaves the bed below
    it loose). None without a window.
    """
    window = _sample_window(params, bed_top)
    if not window:
        return None
    edges = _profile_edges(params)
    heights = np.array([hi - lo for lo, hi in window])
    shells = np.pi * np.diff(edges**2)[None, :] * heights[:, None]  # (n_intervals, n_annuli) m^3
    half = positions.n_frames // 2
    settled = _annulus_solid(positions.frame(0), params.radius, edges, window)
    flowing = np.mean([_annulus_solid(f, params.radius, edges, window) for f in positions.frames(half)], axis=0)
    d, R = params.diameter, params.tube_radius
    tol = 1e-9 * R
    wall, bulk = edges[:-1] >= R - d - tol, edges[1:] <= R - 2.0 * d + tol

    def regions(solid: np.ndarray, volume: np.ndarray) -> dict:
        return {
            name: float(solid[mask].sum() / volume[mask].sum()) if mask.any() else None
            for name, mask in (("bulk", bulk), ("near_wall", wall))
        }

    return {
        "estimator": (
            "particle volume (exact sphere-cylinder intersections) in coaxial annuli over the sample window, "
            "divided by the annulus volume; particles counted by centre height"
        ),
        "z_window_m": [list(interval) for interval in window],
        "near_wall_band_m": [R - d, R],
        "bulk_radius_m": max(0.0, R - 2.0 * d),
        "settled": regions(settled.sum(axis=0), shells.sum(axis=0)),
        "flowing": {**regions(flowing.sum(axis=0), shells.sum(axis=0)), "frames": [half, positions.n_frames - 1]},
        "by_interval": [
            {"z_m": list(z), "settled": regions(settled[k], shells[k]), "flowing": regions(flowing[k], shells[k])}
            for k, z in enumerate(window)
        ],
        "profile": {
            "r_edges_m": edges.tolist(),
            "settled": (settled.sum(axis=0) / shells.sum(axis=0)).tolist(),
            "flowing": (flowing.sum(axis=0) / shells.sum(axis=0)).tolist(),
        },
    }


def _net_crossings(first: dumps.PositionsFrame, last: dumps.PositionsFrame, level: float, length: float) -> int:
    """Net number of downward passages through the plane z = level (mod the periodic length) between
    two frames, over the particles present in both: from the unwrapped heights z + iz L."""
    both = ~(first.lost | last.lost)
    above = [np.floor((f.positions[both, 2] + f.image[both, 2] * length - level) / length) for f in (first, last)]
    return int(np.sum(above[0] - above[1]))


def mixer_crossings(params: DemParams, positions: dumps.PositionsFile) -> list[dict]:
    """Per mixer: net particle passages through the plane of its lowest point over the flow, i.e. how
    many particles got through it (compare with the orifice crossings)."""
    first, last = positions.frame(0), positions.frame(-1)
    return [
        {
            "key": m.key,
            "zone": m.zone,
            "z_range_m": [m.z_bottom, m.z_top],
            "crossings": _net_crossings(first, last, m.z_bottom, params.length),
        }
        for m in params.mixers
    ]


# --------------------------------------------------------------------------------------------
# Orifice calibration

# Beverloo correlation W = C rho_b sqrt(g) (D0 - k d)^2.5 (Beverloo, Leniger & van de Velde 1961):
# W^(1/2.5) is linear in the orifice diameter D0 whatever C and k are.
BEVERLOO_EXPONENT = 2.5
BEVERLOO_K = 1.5  # the usual k, only for the first step (one run cannot fix C and k)
MIN_ORIFICE = 3.0  # particle diameters: the narrowest orifice tried (the geometry's default min_passage)
ORIFICE_RESOLUTION = 1e-6  # m: trial diameters are rounded to it; closer to a bracket end counts as on it


def next_orifice_diameter(runs: list[tuple[float, float]], target: float, diameter: float,
                          bounds: tuple[float, float]) -> float:
    """Next orifice diameter (m) to try for the mass flow ``target`` (kg/s), after ``runs`` =
    [(orifice diameter m, measured flow kg/s), ...] in the order they were made.

    Beverloo's law makes W^(1/2.5) linear in D0, so the step is a secant in W^(1/2.5): through the
    runs at the ends of the bracket (the largest D0 flowing too slowly, the smallest flowing too
    fast; false position) when both flow, else through the last two flowing runs, else from a single
    run along the line through D0 = 1.5 ``diameter`` (particle diameter, m). A step that leaves the
    bracket (within the open interval ``bounds``), or comes within ORIFICE_RESOLUTION of its ends,
    is replaced by bisecting the bracket; jammed runs (no flow) only narrow the bracket.
    """
    slow = [run for run in runs if run[1] < target]
    fast = [run for run in runs if run[1] >= target]
    low = max([bounds[0]] + [orifice for orifice, _ in slow])
    high = min([bounds[1]] + [orifice for orifice, _ in fast])

    def u(flow: float) -> float:
        return flow ** (1.0 / BEVERLOO_EXPONENT)

    flowing = [run for run in runs if run[1] > 0.0]
    if slow and fast and max(slow)[1] > 0.0:
        pair = [max(slow), min(fast)]
    else:
        pair = flowing[-2:]
    guess = None
    if len(pair) == 2 and u(pair[0][1]) != u(pair[1][1]):
        (d_a, w_a), (d_b, w_b) = pair
        guess = d_b + (u(target) - u(w_b)) * (d_b - d_a) / (u(w_b) - u(w_a))
    elif flowing:
        orifice, flow = flowing[-1]
        offset = BEVERLOO_K * diameter
        guess = offset + (orifice - offset) * (target / flow) ** (1.0 / BEVERLOO_EXPONENT)
    if guess is None or not low + ORIFICE_RESOLUTION < guess < high - ORIFICE_RESOLUTION:
        guess = 0.5 * (low + high)
    return guess


def calibrate_orifice(
    spec: dict,
    mesh_builder: Callable[[dict, Path], object],
    target: float,
    workdir: Path,
    *,
    tolerance: float = MASS_FLOW_TOLERANCE,
    max_runs: int = 6,
    ranks: int = 1,
    log=print,
) -> dict:
    """Adjust geometry.tube.orifice_diameter until the DEM mass flow is within ``tolerance``
    (relative) of ``target`` (kg/s), as the DPHT paper did to match an experiment (Section 5).

    Every trial is a full DEM stage (:func:`run_dem`) of ``spec`` with the trial diameter (rounded to
    1 um) in ``workdir/orifice_<um>um``; ``mesh_builder(spec, folder)`` writes that trial's geometry
    (``geometry.json`` and zone STLs) into ``folder``. Trials already done are reused. The measured
    flow is the second-half mass flow. Returns the closest run's ``orifice_diameter`` (m) and
    ``mass_flow_kg_s``, ``converged``, and every run in order (diameter, flow, relative error).
    """
    if isinstance(target, bool) or not isinstance(target, (int, float)) or not target > 0:
        raise DPHTError(f"target mass flow = {target!r}: expected a positive number in kg/s")
    if not 0 < tolerance < 1:
        raise DPHTError(f"tolerance = {tolerance!r}: expected a relative tolerance in (0, 1)")
    if isinstance(max_runs, bool) or not isinstance(max_runs, int) or max_runs < 1:
        raise DPHTError(f"max_runs = {max_runs!r}: expected a positive integer")
    orifice = _number(spec, "geometry.tube.orifice_diameter")
    diameter = _number(spec, "particles.diameter")
    bounds = (MIN_ORIFICE * diameter, _number(spec, "geometry.tube.inner_diameter"))
    runs: list[tuple[float, float]] = []
    report = []
    while len(runs) < max_runs:
        orifice = round(orifice, 6)  # ORIFICE_RESOLUTION, a clean decimal in the trial config
        if any(orifice == done for done, _ in runs):
            log(f"calibrate: the next diameter {orifice * 1e3:.3f} mm was run already; stopping")
            break
        trial = copy.deepcopy(spec)
        trial["geometry"]["tube"]["orifice_diameter"] = orifice
        folder = Path(workdir) / f"orifice_{round(orifice * 1e6)}um"
        mesh_builder(trial, folder / "geometry")
        log(f"calibrate: run {len(runs) + 1}, orifice diameter {orifice * 1e3:.3f} mm")
        summary = run_dem(trial, folder / "geometry", folder / "dem", folder / "positions.h5", ranks=ranks, log=log)
        check = mass_flow_check(summary["mass_flow_second_half_kg_s"], target, tolerance)
        runs.append((orifice, check["measured_kg_s"]))
        report.append({"orifice_diameter": orifice, "mass_flow_kg_s": check["measured_kg_s"],
                       "relative_error": check["relative_error"]})
        log(f"calibrate: {orifice * 1e3:.3f} mm -> {check['measured_kg_s'] * 1e3:.4g} g/s "
            f"({check['relative_error']:+.1%} of the target {target * 1e3:.4g} g/s)")
        if not check["off_target"]:
            break
        orifice = next_orifice_diameter(runs, target, diameter, bounds)
    best = min(report, key=lambda run: abs(run["relative_error"]))
    return {
        "orifice_diameter": best["orifice_diameter"],
        "mass_flow_kg_s": best["mass_flow_kg_s"],
        "target_kg_s": target,
        "tolerance": tolerance,
        "converged": abs(best["relative_error"]) <= tolerance,
        "runs": report,
    }


# --------------------------------------------------------------------------------------------
# LIGGGHTS' own time-step check


def liggghts_rayleigh_fraction(params: DemParams, workdir: Path) -> float:
    """dem.timestep over the Rayleigh time as LIGGGHTS' fix check/timestep/gran reports it for the
    stage's model and materials (a run of :func:`render_check_deck` in ``workdir``; under a second)."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "check.in").write_text(render_check_deck(params))
    screen = workdir / "check.screen.txt"
    run_liggghts("check.in", workdir, screen)
    rows = read_thermo(screen)
    if not rows or rows[-1]["rayleigh_fraction"] <= 0.0:
        raise _tool_error("LIGGGHTS printed no time-step check running check.in.", screen)
    return rows[-1]["rayleigh_fraction"]
