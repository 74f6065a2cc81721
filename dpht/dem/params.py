"""DEM parameters: the config sections checked and turned into what the decks and the run need.

The wall zones and mixers come from the geometry stage's summary (``geometry.json``, one
``<zone>.stl`` per zone next to it). The tube's cylinder is by default LIGGGHTS' exact ``zcylinder``
primitive (``dem.tube_wall: mesh`` uses its STLs instead; the run summary records which, and the
thermal stage measures distances to the same surfaces):
on this machine the 0.5 d gmsh tube mesh (13,800 triangles) made a 3,000-particle step 4x slower
(5.6 ms against 1.4 ms). Particles are inserted in one cylinder per free slab between the orifice
plate, the mixers and the top; the fill count leaves out the mixers' volume.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

from dpht.defaults import default, setting
from dpht.dem import dumps
from dpht.errors import ConfigError, DPHTError

GEOMETRY_SUMMARY = "geometry.json"  # the geometry stage's summary, next to its zone STLs
TUBE_ZONES = ("heated_wall", "adiabatic_wall")  # the cylinder, replaced by a primitive unless tube_wall = "mesh"
TUBE_WALLS = ("primitive", "mesh")
ORIFICE_ZONE = "orifice"  # left out of a driven slice's DEM (dem.drive without orifice, DemParams.packed)
INSERT_INTERVAL = 0.01  # s between insertion events
INSERT_VOLUME_FRACTION = 0.2  # particles requested per event, as a solid fraction of the empty region
INSERT_EVENTS_MARGIN = 3  # events run per event needed, since later events find less free space
GRAVITY = 9.81  # m/s2, along -z (the decks' gravity)
# Packing a driven slice (dem.drive, decks/pack.in): the particles are inserted into a periodic box
# this much taller than the tube at this solid fraction (random insertion without overlaps places
# them easily up to about 0.3), which then shrinks to the tube's length; a viscous drag with this
# decay time (s) drains the compression's kinetic energy.
PACK_INSERT_SOLID_FRACTION = 0.15
PACK_DAMPING_TIME = 0.005
# Loading a packed slice to a wall stress (dem.drive.wall_stress, decks/pack.in). A random packing at
# rest carries no load; the real tube's wall carries the bed's weight. So the packed slice, its
# contact friction restored, is shortened in steps of LOAD_STRAIN (each over LOAD_STEP_TIME s, then
# LOAD_REST_TIME s at rest) until the particles' Hertz overlaps with the tube wall press on it with
# at least the target stress; at most LOAD_INCREMENTS steps (a summary warning if the target is not
# reached). It packs with friction PACK_FRICTION, not frictionless: measured on 4-diameter Watkins
# slices at 0.60, a frictionless packing came to rest with gaps (no contacts after 1.1% of
# shortening with friction), one packed at 0.1 at the edge of contact (3 per particle), so that the
# load builds from the solid fraction asked for: 198 Pa at the wall after 1.1%.
PACK_FRICTION = 0.1
LOAD_STRAIN = 0.001
LOAD_STEP_TIME = 0.005
LOAD_REST_TIME = 0.0025
LOAD_INCREMENTS = 25
# Processor grid (DemParams.z_slabs): LIGGGHTS-PUBLIC 3.8 has no load balancing (no `balance`, no
# `fix balance`; its processors page says the grid is never changed on the fly), so the grid is
# chosen before each run. Slabs along the tube axis cut the fewest particle contacts; they are used
# as long as the busiest slab holds at most MAX_SLAB_IMBALANCE times the mean share of a bed filling
# the fill height uniformly and every slab is MIN_SLAB diameters thick; the other ranks split the
# cross-section. Measured on a 14 mm bed in a 50 mm periodic tube at 2 ranks: slabs put every
# particle on one rank, a cross-section split ran 1.4x faster (benchmarks/dem.py --partial).
MAX_SLAB_IMBALANCE = 1.2
MIN_SLAB = 4.0  # particle diameters


def spec_value(spec: dict, key: str):
    """The value at the dotted ``key`` ("dem.timestep") of the config sections ``spec``."""
    node = spec
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConfigError(f"DEM spec: missing key {key!r}")
        node = node[part]
    return node


def spec_number(spec: dict, key: str, *, low: float = 0.0, high: float = math.inf, integer: bool = False):
    """The number at ``key``, checked to lie in (low, high] (and to be whole if ``integer``)."""
    value = spec_value(spec, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{key} = {value!r}: expected a finite number")
    if integer and value != int(value):
        raise ConfigError(f"{key} = {value!r}: expected an integer")
    if not low < value <= high:
        raise ConfigError(f"{key} = {value!r}: expected a value in ({low}, {high}]")
    return int(value) if integer else float(value)


def _flag(value, key: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{key} = {value!r}: expected true or false")
    return value


def _flow_time(spec: dict) -> float:
    """dem.flow_time (s), >= 0: 0 is a static bed (settle only)."""
    value = spec_number(spec, "dem.flow_time", low=-math.inf)
    if value < 0:
        raise ConfigError(f"dem.flow_time = {value!r}: expected a value >= 0 s (0: a static bed, settle only)")
    return value


def _is_prime(n: int) -> bool:
    return n > 1 and all(n % k for k in range(2, math.isqrt(n) + 1))


def next_prime(n: int) -> int:
    n += 1
    while not _is_prime(n):
        n += 1
    return n


def check_seed(seed: int) -> None:
    """ConfigError naming ``dem.seed`` unless it is a prime (LIGGGHTS' random generators need one)."""
    if not _is_prime(seed):
        raise ConfigError(f"dem.seed = {seed}: LIGGGHTS needs a prime > 10000, e.g. {next_prime(seed)}")


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
    built, wanted = geometry.get("geometry") or {}, spec_value(spec, "geometry")
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
    # dem.fill_solid_fraction: the mean solid fraction of the poured bed, to size the fill for
    # dem.fill_height. Measured here with the default contact properties: 0.53 for 1 mm particles in
    # the 9 mm tube (a 43.8 mm bed for 42 mm asked), 0.47 in a shallow 8 mm-wide bed, near the
    # schema's default. The summary reports the settled bed height.
    fill_solid_fraction: float
    drive_time_constant: float  # s, dem.drive.time_constant (read only with a drive)
    drive_velocity: float | None = None  # m/s downwards, the mean axial velocity held by dem.drive
    drive_mass_flow: float | None = None  # kg/s, the mass flow held by dem.drive (instead of a velocity)
    drive_orifice: bool = False  # dem.drive.orifice: a driven tube with its orifice plate, not a slice
    wall_stress: float = 0.0  # Pa, the wall's normal stress a packed slice is loaded to (dem.drive.wall_stress)

    @classmethod
    def from_spec(cls, spec: dict, geometry: dict) -> "DemParams":
        """``spec``: the config sections particles, wall, contact, geometry, dem; ``geometry``: the
        geometry stage's summary (:func:`read_geometry`) of the same geometry."""
        if not isinstance(spec, dict):
            raise ConfigError(f"DEM spec must be a mapping of config sections, got {type(spec).__name__}")
        pair = {
            name: tuple(spec_number(spec, f"contact.{name}.{pair}", high=high) for pair in ("pp", "pw"))
            for name, high in (("restitution", 1.0), ("friction", math.inf), ("rolling_friction", math.inf))
        }
        dem = spec_value(spec, "dem")
        if not isinstance(dem, dict):
            raise ConfigError(f"dem must be a mapping, got {type(dem).__name__}")
        precision = setting(dem, "dem.position_precision")
        if precision not in dumps.PRECISIONS:
            raise ConfigError(f"dem.position_precision = {precision!r}: expected one of {dumps.PRECISIONS}")
        tube_wall = setting(dem, "dem.tube_wall")
        if tube_wall not in TUBE_WALLS:
            raise ConfigError(f"dem.tube_wall = {tube_wall!r}: expected one of {TUBE_WALLS}")
        zones, mixers = _layout(spec, geometry)
        drive = dem.get("drive")
        if drive is not None and (not isinstance(drive, dict) or ("velocity" in drive) == ("mass_flow" in drive)):
            raise ConfigError(f"dem.drive must be a mapping with velocity (m/s) or mass_flow (kg/s), got {drive!r}")
        drive = drive or {}
        params = cls(
            diameter=spec_number(spec, "particles.diameter"),
            density=spec_number(spec, "particles.density"),
            youngs_p=spec_number(spec, "particles.youngs_modulus_dem"),
            poisson_p=spec_number(spec, "particles.poisson_ratio", high=0.5),
            youngs_w=spec_number(spec, "wall.youngs_modulus_dem"),
            poisson_w=spec_number(spec, "wall.poisson_ratio", high=0.5),
            restitution=pair["restitution"],
            friction=pair["friction"],
            rolling=pair["rolling_friction"],
            tube_diameter=spec_number(spec, "geometry.tube.inner_diameter"),
            length=spec_number(spec, "geometry.tube.length"),
            orifice_height=spec_number(spec, "geometry.tube.orifice_height"),
            orifice_diameter=spec_number(spec, "geometry.tube.orifice_diameter"),
            timestep=spec_number(spec, "dem.timestep"),
            fill_height=spec_number(spec, "dem.fill_height"),
            settle_time=spec_number(spec, "dem.settle_time"),
            flow_time=_flow_time(spec),
            dump_interval=spec_number(spec, "dem.dump_interval", integer=True),
            restart_interval=spec_number(spec, "dem.restart_interval", integer=True),
            seed=spec_number(spec, "dem.seed", low=10000, integer=True),
            precision=precision,
            tube_wall=tube_wall,
            zones=zones,
            mixers=mixers,
            fill_solid_fraction=(spec_number(spec, "dem.fill_solid_fraction", low=0.3, high=0.64)
                                 if "fill_solid_fraction" in dem else default("dem.fill_solid_fraction")),
            drive_velocity=spec_number(spec, "dem.drive.velocity") if "velocity" in drive else None,
            drive_mass_flow=spec_number(spec, "dem.drive.mass_flow") if "mass_flow" in drive else None,
            drive_time_constant=(spec_number(spec, "dem.drive.time_constant")
                                 if "time_constant" in drive else default("dem.drive.time_constant")),
            drive_orifice=_flag(drive.get("orifice", False), "dem.drive.orifice"),
        )
        load = setting(drive, "dem.drive.wall_stress")
        if load:
            params = replace(params, wall_stress=params.weight_wall_stress if load == "weight"
                             else spec_number(spec, "dem.drive.wall_stress"))
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
        if self.wall_stress and not self.packed:
            raise ConfigError(
                f"dem.drive.wall_stress = {self.wall_stress:.6g} Pa loads a packed slice (decks/pack.in); a driven "
                "tube with dem.drive.orifice true is poured onto its plate, which carries its bed: leave wall_stress out"
            )
        if self.packed and self.mixers:
            raise ConfigError(
                f"dem.drive without orifice packs a slice in a box shrinking through the tube (decks/pack.in), which "
                f"geometry.mixers ({', '.join(m.key for m in self.mixers)}) would block: drive a tube with mixers with "
                "dem.drive.orifice true (poured onto its plate)"
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
        check_seed(self.seed)

    # Derived quantities ------------------------------------------------------------------

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    @property
    def tube_radius(self) -> float:
        return 0.5 * self.tube_diameter

    @property
    def driven(self) -> bool:
        """A flow held by the controller of dem.drive (a driven slice or tube), not by gravity alone."""
        return self.drive_velocity is not None or self.drive_mass_flow is not None

    @property
    def packed(self) -> bool:
        """A driven periodic slice of a long tube (dem.drive without orifice): no orifice plate in its
        flow, its bed packed without a seam to dem.fill_solid_fraction over the whole periodic length
        (decks/pack.in) rather than poured onto the plate. A driven tube with dem.drive.orifice true
        keeps its plate and its outlet, and is poured onto the plate to dem.fill_height like an
        orifice flow."""
        return self.driven and not self.drive_orifice

    @property
    def mesh_zones(self) -> tuple[str, ...]:
        """Wall zones LIGGGHTS reads as STL meshes: all but the cylinder's unless tube_wall is "mesh", and
        not the orifice plate of a driven slice."""
        skip = (() if self.tube_wall == "mesh" else TUBE_ZONES) + ((ORIFICE_ZONE,) if self.packed else ())
        return tuple(z for z in self.zones if z not in skip)

    @property
    def wall_kinds(self) -> dict[str, str]:
        """How LIGGGHTS represents each wall zone: "mesh" (its STL) or "primitive" (the exact surface
        geometry.walls records for it); the thermal stage measures distances to the same."""
        return {zone: "mesh" if zone in self.mesh_zones else "primitive" for zone in self.zones}

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
    def loaded(self) -> bool:
        """Whether a packed bed is then loaded to dem.drive.wall_stress (decks/pack.in)."""
        return self.packed and self.wall_stress > 0.0

    @property
    def weight_wall_stress(self) -> float:
        """Pa: the wall's normal stress in a tall tube of this bed sliding down it, its weight carried
        by the wall friction: rho_p phi g D / (4 mu_w) (dem.drive.wall_stress "weight"), the deep-bed
        limit of Janssen's analysis (per metre of tube, the weight rho_p phi g pi D^2 / 4 equals the
        friction mu_w sigma_w pi D)."""
        return self.density * self.fill_solid_fraction * GRAVITY * self.tube_diameter / (4.0 * self.friction[1])

    @property
    def wall_hertz(self) -> float:
        """N/m^1.5: the Hertz normal force of a particle on the tube wall per overlap^1.5,
        4/3 E* sqrt(r) with 1/E* = (1 - nu_p^2)/E_p + (1 - nu_w^2)/E_w (LIGGGHTS' model hertz)."""
        effective = 1.0 / ((1.0 - self.poisson_p**2) / self.youngs_p + (1.0 - self.poisson_w**2) / self.youngs_w)
        return 4.0 / 3.0 * effective * math.sqrt(self.radius)

    @property
    def pack_length(self) -> float:
        """m: the periodic box the particles of a packed bed are inserted into, before it shrinks to
        the tube's length."""
        return self.length * max(1.0, self.fill_solid_fraction / PACK_INSERT_SOLID_FRACTION)

    @property
    def n_particles(self) -> int:
        """Particles to insert so the settled bed reaches about dem.fill_height above the orifice plate;
        a packed bed (a driven slice, :attr:`packed`) holds dem.fill_solid_fraction over the tube's whole
        periodic length."""
        volume = math.pi * self.tube_radius**2 * self.length if self.packed else self.bed_volume
        return round(self.fill_solid_fraction * volume / self._particle_volume())

    def steps(self) -> dict[str, int]:
        """Step counts: insertion events, end of fill (as planned) and of insertion (at the latest),
        end of settle and flow (both on dump steps). A packed bed inserts all its particles at once
        (step 1), shrinks its box over the first half of dem.settle_time (``compress_end``) and
        comes to rest over the second."""
        if self.packed:
            compress_end = max(2, round(0.5 * self.settle_time / self.timestep))
            rest_end = max(compress_end + 1, round(self.settle_time / self.timestep))
            settle_end, load = rest_end, {}
            if self.loaded:  # LOAD_INCREMENTS shortenings and rests, then one more rest
                load = {"load_steps": max(1, round(LOAD_STEP_TIME / self.timestep)),
                        "load_rest": max(1, round(LOAD_REST_TIME / self.timestep))}
                settle_end += (LOAD_INCREMENTS + 1) * load["load_rest"] + LOAD_INCREMENTS * load["load_steps"]
            settle_end = _ceil_to(settle_end, self.dump_interval)
            return {"insert_every": 1, "per_event": self.n_particles, "fill_end": 1, "insert_end": 1,
                    "compress_end": compress_end, "rest_end": rest_end, **load, "settle_end": settle_end,
                    "flow_end": settle_end + self._flow_steps()}
        insert_every = max(1, round(INSERT_INTERVAL / self.timestep))
        per_event = max(1, math.floor(INSERT_VOLUME_FRACTION * self._fill_region_volume() / self._particle_volume()))
        fill_end = INSERT_EVENTS_MARGIN * math.ceil(self.n_particles / per_event) * insert_every
        settle_end = _ceil_to(fill_end + round(self.settle_time / self.timestep), self.dump_interval)
        flow_end = settle_end + self._flow_steps()
        # A bed filled close to the top of the tube leaves the last events little room until it
        # compacts (the default scene's took 17 events for its 2,807 particles, 12 were planned):
        # insertion goes on, while particles are missing, through the first half of the settling.
        insert_end = fill_end + insert_every * ((settle_end - fill_end) // (2 * insert_every))
        return {
            "insert_every": insert_every,
            "per_event": per_event,
            "fill_end": fill_end,
            "insert_end": insert_end,
            "settle_end": settle_end,
            "flow_end": flow_end,
        }

    def _flow_steps(self) -> int:
        """Steps of the flow, on dump steps; dem.flow_time 0: a static bed, settle only (its positions
        file holds the settled bed)."""
        return _ceil_to(max(1, round(self.flow_time / self.timestep)), self.dump_interval) if self.flow_time > 0 else 0

    def z_slabs(self, ranks: int) -> int:
        """Ranks along the tube axis (the Pz of LIGGGHTS' ``processors * * Pz``) for ``ranks`` MPI ranks:
        the largest divisor of ``ranks`` within MAX_SLAB_IMBALANCE and MIN_SLAB (see there)."""
        bottom, top = (0.0, self.length) if self.packed else (self.orifice_height,
                                                               min(self.length, self.orifice_height + self.fill_height))

        def imbalance(pz: int) -> float:
            slab = self.length / pz
            busiest = max(min(top, (k + 1) * slab) - max(bottom, k * slab) for k in range(pz))
            return busiest * pz / (top - bottom)

        fitting = [
            pz
            for pz in range(1, ranks + 1)
            if ranks % pz == 0
            and (pz == 1 or (self.length / pz >= MIN_SLAB * self.diameter and imbalance(pz) <= MAX_SLAB_IMBALANCE))
        ]
        return max(fitting)

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


def mass_flow_target(spec: dict) -> tuple[float, float] | None:
    """(dem.target_mass_flow in kg/s, dem.mass_flow_tolerance relative), or None without a target."""
    dem = spec_value(spec, "dem")
    if dem.get("target_mass_flow") is None:
        return None
    tolerance = spec_number(spec, "dem.mass_flow_tolerance") if "mass_flow_tolerance" in dem else default("dem.mass_flow_tolerance")
    return spec_number(spec, "dem.target_mass_flow"), tolerance
