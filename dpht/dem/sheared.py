"""The sheared periodic box: a cubic periodic box of particles in homogeneous simple shear.

The scene of the ParScale paper's Section 4 (Radl, Forgber, Aigner & Kloss 2015, "ParScale - an open
source library for the modeling of intra-particle transport processes"; Table 2, Fig. 5): a cubic
periodic box of edge H = ``sheared_box.size`` particle diameters (15 in the paper) at a solid
fraction, sheared with Lees-Edwards boundaries, the flow along x and its gradient along y, at the
shear rate of the particle Peclet number (paper, Eq. 9)

    Pe = (d_p / 2)^2 / (lambda_p / (rho_p c_p)) * gamma_dot,

lambda_p and c_p taken at ``sheared_box.reference_temperature``. LIGGGHTS runs it (``decks/shear.in``):
the particles are inserted loosely into a larger orthogonal box, which shrinks to the cube, frictionless
and damped (as a packed tube slice, dpht.dem.decks); the box is then made triclinic and tilted at the
shear rate with ``fix deform 1 xy erate <rate> remap v``, the particles first given the mean shear
velocity profile (``velocity ramp``), as LIGGGHTS' fix deform manual advises without a thermostat.
Its sources support this for granular particles: the granular neighbour lists without Newton's third
law (the only ones pairs with contact history take) work in a triclinic box, and ``remap v`` offsets
the x velocity of a particle crossing the y faces, and of the ghosts across them (``communicate
single vel yes``), by the box's shear velocity. But LIGGGHTS-PUBLIC 3.8.0 builds no ghost particles
in any triclinic box (:func:`triclinic_ghosts`): no contact across a periodic face, and the sheared
bed loses particles; :func:`run_sheared_box` refuses such a LIGGGHTS. Positions are dumped over
``sheared_box.strain`` after ``sheared_box.steady_strain`` and gathered into a positions file with
the tilt of every frame (dpht.dem.dumps), taken at full precision from the thermo output.

:func:`flow_profile` measures what makes the box a homogeneous shear flow: the mean x velocity
across y (from the unwrapped displacements between frames) linear with the slope of the set shear
rate, and the solid fraction held, uniform across y.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.closures.heat_capacity import specific_heat
from dpht.closures.htc import solid_conductivity
from dpht.dem import dumps
from dpht.dem.decks import CONTACT_MODEL, SKIN, SOFT_MODULUS, THERMO_STYLE, _fmt, _friction_fixes, _template
from dpht.dem.liggghts import DEFAULT_MPI, POSITIONS, read_thermo, run_liggghts
from dpht.dem.params import (
    GRAVITY, PACK_DAMPING_TIME, PACK_INSERT_SOLID_FRACTION, _ceil_to, check_seed, next_prime, spec_number, spec_value,
)
from dpht.errors import ConfigError, DPHTError, ExternalToolError
from dpht.util.files import publish

DECK = "shear.in"
PROBE = "triclinic_probe.in"
SCREEN = "screen.txt"
POST = "post"  # the dumps, in the work directory
TILT_COLUMN = "xy"  # the thermo column after dpht.dem.liggghts.THERMO_COLUMNS: the box tilt (m)
# Every periodic axis of the box is physically periodic (positions file attribute ``recycled``).
RECYCLED = (False, False, False)
MIN_SIZE = 4.0  # box edge in diameters: below this a particle meets its own images across the box


@dataclass(frozen=True)
class ShearedBoxParams:
    """What the deck and the run need (SI units), from the config sections particles, contact, dem
    and sheared_box (:meth:`from_spec`)."""

    diameter: float
    density: float
    youngs: float
    poisson: float
    restitution: float  # particle-particle
    friction: float
    rolling: float
    edge: float  # m, the cube's edge
    n_particles: int
    peclet: float  # Eq. 9
    shear_rate: float  # 1/s, from the Peclet number
    steady_strain: float  # sheared before the first dump
    strain: float  # sheared while dumping
    timestep: float
    settle_time: float  # s, packing: half shrinking the box, half at rest
    dump_interval: int
    seed: int

    @classmethod
    def from_spec(cls, spec: dict) -> "ShearedBoxParams":
        """``spec``: the config sections particles, contact, dem (timestep, settle_time,
        dump_interval, seed) and sheared_box (size in diameters, solid_fraction, peclet,
        reference_temperature in K, steady_strain, strain)."""
        if not isinstance(spec, dict):
            raise ConfigError(f"sheared box spec must be a mapping of config sections, got {type(spec).__name__}")
        diameter = spec_number(spec, "particles.diameter")
        density = spec_number(spec, "particles.density")
        size = spec_number(spec, "sheared_box.size")
        if size < MIN_SIZE:
            raise ConfigError(f"sheared_box.size = {size!r}: expected at least {MIN_SIZE:g} particle diameters")
        solid_fraction = spec_number(spec, "sheared_box.solid_fraction", high=0.645)
        temperature = spec_number(spec, "sheared_box.reference_temperature")
        conductivity = float(solid_conductivity(spec_value(spec, "particles.conductivity"), temperature))
        capacity = density * float(specific_heat(spec_value(spec, "particles.specific_heat"))(temperature))
        if not (math.isfinite(capacity) and capacity > 0.0):
            raise ConfigError(f"particles.specific_heat is {capacity / density!r} J/(kg K) at "
                              f"sheared_box.reference_temperature = {temperature} K: expected a positive number")
        peclet = spec_number(spec, "sheared_box.peclet")
        edge = size * diameter
        n_particles = round(solid_fraction * edge**3 / (math.pi / 6.0 * diameter**3))
        params = cls(
            diameter=diameter,
            density=density,
            youngs=spec_number(spec, "particles.youngs_modulus_dem"),
            poisson=spec_number(spec, "particles.poisson_ratio", high=0.5),
            restitution=spec_number(spec, "contact.restitution.pp", high=1.0),
            friction=_non_negative(spec, "contact.friction.pp"),
            rolling=_non_negative(spec, "contact.rolling_friction.pp"),
            edge=edge,
            n_particles=n_particles,
            peclet=peclet,
            shear_rate=peclet * conductivity / (capacity * (0.5 * diameter) ** 2),  # Eq. 9
            steady_strain=_non_negative(spec, "sheared_box.steady_strain"),
            strain=spec_number(spec, "sheared_box.strain"),
            timestep=spec_number(spec, "dem.timestep"),
            settle_time=spec_number(spec, "dem.settle_time"),
            dump_interval=spec_number(spec, "dem.dump_interval", integer=True),
            seed=spec_number(spec, "dem.seed", low=10000, integer=True),
        )
        if n_particles < 2:
            raise ConfigError(f"sheared_box.solid_fraction = {solid_fraction} fills the box with {n_particles} particles")
        check_seed(params.seed)
        return params

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    @property
    def solid_fraction(self) -> float:
        """The box's solid fraction with its whole number of particles."""
        return self.n_particles * math.pi / 6.0 * self.diameter**3 / self.edge**3

    @property
    def pack_edge(self) -> float:
        """m: the edge of the box the particles are inserted into, at PACK_INSERT_SOLID_FRACTION."""
        return self.edge * max(1.0, self.solid_fraction / PACK_INSERT_SOLID_FRACTION) ** (1.0 / 3.0)

    def steps(self) -> dict[str, int]:
        """Step counts: end of the box's shrinking (half dem.settle_time) and of the rest after it,
        of the shear before the first dump and of the run (both on dump steps)."""
        compress_end = max(2, round(0.5 * self.settle_time / self.timestep))
        rest_end = max(compress_end + 1, round(self.settle_time / self.timestep))
        per_strain = 1.0 / (self.shear_rate * self.timestep)
        steady_end = _ceil_to(rest_end + round(self.steady_strain * per_strain), self.dump_interval)
        shear_end = steady_end + _ceil_to(max(1, round(self.strain * per_strain)), self.dump_interval)
        return {"compress_end": compress_end, "rest_end": rest_end, "steady_end": steady_end, "shear_end": shear_end}

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The sheared cube's lower and upper corner (m)."""
        return np.zeros(3), np.full(3, self.edge)


def _non_negative(spec: dict, key: str) -> float:
    value = spec_number(spec, key, low=-math.inf)
    if value < 0:
        raise ConfigError(f"{key} = {value!r}: expected a value >= 0")
    return value


def render_deck(params: ShearedBoxParams) -> str:
    """The text of ``decks/shear.in`` for ``params``; identical for identical params."""
    steps = params.steps()
    seed_template = next_prime(params.seed)
    friction = (params.friction, params.friction), (params.rolling, params.rolling)
    thermo = (f"thermo_style custom {THERMO_STYLE} {TILT_COLUMN}\nthermo {params.dump_interval}\n"
              "thermo_modify flush yes lost ignore norm no format float %.15g")  # fmt: skip
    # The model of the tube decks (decks/model.in) for particles alone: no walls, the wall material
    # that of the particles; frictionless while packing.
    model_values = {
        "skin": SKIN * params.diameter,
        "binsize": 0.5 * (1.0 + SKIN) * params.diameter,
        "soft_particles": "soft_particles yes" if params.youngs < SOFT_MODULUS else "",
        "youngs_p": params.youngs,
        "youngs_w": params.youngs,
        "poisson_p": params.poisson,
        "poisson_w": params.poisson,
        "restitution_pp": params.restitution,
        "restitution_pw": params.restitution,
        "friction_fixes": _friction_fixes((0.0, 0.0), (0.0, 0.0)),
        "contact_model": CONTACT_MODEL,
        "timestep": params.timestep,
        "gravity": GRAVITY,
        "wall_fixes": "",
        "thermo_every": params.dump_interval,
        "thermo": thermo,
    }
    half_velocity = 0.5 * params.shear_rate * params.edge
    values = {
        "model": _template("model.in").substitute({k: _text(v) for k, v in model_values.items()}).rstrip(),
        "pack_edge": params.pack_edge,
        "pack_inner": params.pack_edge - params.radius,
        "edge": params.edge,
        "radius": params.radius,
        "density": params.density,
        "n_particles": params.n_particles,
        "seed_insert": params.seed,
        "seed_template": seed_template,
        "seed_distribution": next_prime(seed_template),
        "pack_damping": params.density * math.pi / 6.0 * params.diameter**3 / PACK_DAMPING_TIME,
        "pack_damping_time": PACK_DAMPING_TIME,
        "friction_fixes": _friction_fixes(*friction),
        "velocity_low": -half_velocity,
        "velocity_high": half_velocity,
        "shear_rate": params.shear_rate,
        "dump_every": params.dump_interval,
        "dump_files": f"{POST}/{dumps.DUMP_GLOB}",
        **steps,
    }
    return _template(DECK).substitute({k: _text(v) for k, v in values.items()})


def _text(value) -> str:
    return value if isinstance(value, str) else _fmt(value)


@dataclass(frozen=True)
class FlowProfile:
    """The measured flow of a sheared box, across its gradient direction y (bins of equal height).

    Each particle's velocity over each dump interval is its unwrapped x displacement over the
    interval's time, in the frame of the periodic image it starts in (the unwrapped position of a
    particle in image iy moves with the image at iy times the box's shear velocity, the tilt's rate),
    sampled at its height at the interval's start. ``shear_rate`` (1/s) and
    ``offset`` (m/s, at mid-height) are the least-squares line through all samples; per bin,
    ``heights`` (m) and ``velocity`` (m/s) are the samples' mean height and velocity, and
    ``linearity`` is the largest deviation of a bin's velocity from the line, over the velocity
    difference across the box (shear rate x edge). ``solid_fraction`` (bins,): mean over the frames
    of the exact sphere volume in each bin (periodic images included) over its volume; ``lost``:
    particles missing from any frame.
    """

    heights: np.ndarray
    velocity: np.ndarray
    solid_fraction: np.ndarray
    shear_rate: float
    offset: float
    linearity: float
    lost: int

    def summary(self) -> dict:
        return {"y_m": self.heights.tolist(), "velocity_m_s": self.velocity.tolist(),
                "solid_fraction": self.solid_fraction.tolist(), "shear_rate_1_s": self.shear_rate,
                "offset_m_s": self.offset, "linearity": self.linearity, "lost_particles": self.lost}  # fmt: skip


def flow_profile(positions: dumps.PositionsFile, bins: int) -> FlowProfile:
    """The measured :class:`FlowProfile` of a sheared box's positions file (all its frames)."""
    lo, hi = (np.asarray(positions.attrs[k], float) for k in ("box_lo", "box_hi"))
    height = hi[1] - lo[1]
    edges = lo[1] + height * np.arange(bins + 1) / bins
    sums = np.zeros((3, bins))  # per bin: samples, their heights above mid-height, their velocities
    moments = np.zeros(2)  # over all samples: height^2, height x velocity
    solid = np.zeros(bins)
    lost = np.zeros(positions.n_particles, dtype=bool)
    previous = None
    for frame in positions.frames():
        lost |= frame.lost
        here = ~frame.lost
        solid += _slab_volumes(frame.positions[here, 1], positions.radius, edges, height)
        now = dumps.unwrapped(frame.positions, frame.image, lo, hi, frame.tilt)
        if previous is not None:
            y0, u0, iy0, t0, tilt0 = previous
            # The tilt's change, less the flips by whole x lengths (under half an x length per interval).
            sheared = frame.tilt - tilt0 - (hi[0] - lo[0]) * round((frame.tilt - tilt0) / (hi[0] - lo[0]))
            both = here & np.isfinite(y0)
            y = y0[both] - lo[1] - 0.5 * height
            v = (now[both, 0] - u0[both, 0] - iy0[both] * sheared) / (frame.time - t0)
            which = np.clip(np.floor((y / height + 0.5) * bins).astype(np.int64), 0, bins - 1)
            sums += [np.bincount(which, w, bins) for w in (np.ones_like(y), y, v)]
            moments += [y @ y, y @ v]
        previous = (np.where(here, frame.positions[:, 1], np.nan), now, frame.image[:, 1], frame.time, frame.tilt)
    if np.any(sums[0] == 0):
        raise DPHTError(f"positions file {positions.path}: {positions.n_frames} frames and {bins} bins leave a bin "
                        "without a particle displacement; dump more of the shear or use fewer bins")  # fmt: skip
    n, y_sum, v_sum = sums.sum(axis=1)
    slope = (n * moments[1] - y_sum * v_sum) / (n * moments[0] - y_sum**2)
    offset = (v_sum - slope * y_sum) / n
    heights, velocity = sums[1] / sums[0], sums[2] / sums[0]
    linearity = float(np.max(np.abs(velocity - slope * heights - offset)) / (abs(slope) * height))
    slab_volume = (hi[0] - lo[0]) * (hi[2] - lo[2]) * height / bins
    return FlowProfile(heights + lo[1] + 0.5 * height, velocity, solid / (positions.n_frames * slab_volume),
                       float(slope), float(offset), linearity, int(lost.sum()))  # fmt: skip


def _slab_volumes(y: np.ndarray, radius: float, edges: np.ndarray, period: float) -> np.ndarray:
    """Volume (m3) of the spheres centred at heights ``y`` inside each slab between ``edges``,
    periodic in y with ``period``: spherical caps, the images one period up and down included."""
    volume = np.zeros(edges.size - 1)
    for shift in (-period, 0.0, period):
        u = np.clip(edges[:, None] - (y + shift)[None, :], -radius, radius)
        below = np.pi * (radius**2 * u - u**3 / 3.0)  # of each sphere, below each edge
        volume += (below[1:] - below[:-1]).sum(axis=1)
    return volume


def triclinic_ghosts(workdir: Path) -> int:
    """Ghost particles LIGGGHTS builds in a triclinic periodic box holding two particles that touch
    through its x faces (``decks/triclinic_probe.in``, well under a second): 0 where its triclinic
    boxes are broken, as LIGGGHTS-PUBLIC 3.8.0's are (every triclinic box tried, granular or
    atomic, any tilt or units: no particle interacts across a periodic face, and a sheared bed
    loses particles)."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / PROBE).write_text(_template(PROBE).template)
    screen = workdir / "probe.screen.txt"
    run_liggghts(PROBE, workdir, screen)
    counts = [line.split()[1] for line in screen.read_text(errors="replace").splitlines() if line.startswith("Nghost:")]
    if not counts:
        raise ExternalToolError(f"LIGGGHTS printed no ghost count running {PROBE} in {workdir}; see {screen}")
    return round(float(counts[-1]))


def run_sheared_box(spec: dict, workdir: Path, out_h5: Path, *, bins: int = 6, ranks: int = 1,
                    mpi: str = DEFAULT_MPI, log=print) -> dict:  # fmt: skip
    """Pack and shear the box of ``spec`` (:meth:`ShearedBoxParams.from_spec`) with LIGGGHTS in
    ``workdir``, gather its dumps into the positions file ``out_h5`` (a copy of the work directory's)
    and return its summary: the parameters and the measured :func:`flow_profile` in ``bins`` layers.
    Runs from the start each time (a box of 4,000 particles takes minutes). Refuses to run on a
    LIGGGHTS whose triclinic boxes have no ghost particles (:func:`triclinic_ghosts`)."""
    params = ShearedBoxParams.from_spec(spec)
    workdir, out_h5 = Path(workdir), Path(out_h5)
    if triclinic_ghosts(workdir) == 0:
        raise ExternalToolError(
            "this LIGGGHTS builds no ghost particles across the periodic faces of a triclinic box (LIGGGHTS-PUBLIC "
            "3.8.0 does not), so a sheared box run with it would have no contacts across its faces and lose "
            f"particles; see {workdir / 'probe.screen.txt'}. The sheared box needs a DEM code whose triclinic boxes work"
        )
    (workdir / POST).mkdir(parents=True, exist_ok=True)  # LIGGGHTS fails silently without it
    for path in dumps.dump_files(workdir / POST).values():
        path.unlink()
    (workdir / DECK).write_text(render_deck(params))
    steps = params.steps()
    log(f"sheared box: {params.n_particles} particles in a {params.edge / params.diameter:g} d cube at solid fraction "
        f"{params.solid_fraction:.4f}, shear rate {params.shear_rate:.6g} 1/s (Pe {params.peclet:g}), "
        f"steps {steps['shear_end']} of {params.timestep:g} s")  # fmt: skip
    wall = run_liggghts(DECK, workdir, workdir / SCREEN, ranks=ranks, mpi=mpi)
    lo, hi = params.box
    boxes = {int(row["step"]): dumps.Box(lo, hi, row[TILT_COLUMN])
             for row in read_thermo(workdir / SCREEN, TILT_COLUMN) if TILT_COLUMN in row}  # fmt: skip
    files = dumps.dump_files(workdir / POST)
    if not files or max(files) != steps["shear_end"]:
        raise DPHTError(f"LIGGGHTS ran {DECK} in {workdir} without dumping up to step {steps['shear_end']}; "
                        f"see {workdir / SCREEN}")  # fmt: skip
    work_h5 = workdir / POSITIONS
    partial = work_h5.with_name(work_h5.name + ".part")
    dumps.write_positions(
        partial, dumps.read_dumps(files.values(), boxes), radius=params.radius, density=params.density,
        timestep=params.timestep, dump_interval=params.dump_interval,
        attrs={"recycled": list(RECYCLED), "shear_rate": params.shear_rate, "peclet": params.peclet},
    )  # fmt: skip
    with dumps.PositionsFile(partial) as positions:
        profile = flow_profile(positions, bins)
    summary = {"params": asdict(params), "solid_fraction": params.solid_fraction, "wall_time_s": round(wall, 2),
               "profile": profile.summary()}  # fmt: skip
    dumps.set_summary(partial, summary)
    with h5py.File(partial, "r+") as h5:
        h5.attrs[dumps.CONTENT_DIGEST] = dumps.content_digest(h5)
    partial.replace(work_h5)
    for path in files.values():
        path.unlink()
    publish(work_h5, out_h5)
    log(f"sheared box: measured shear rate {profile.shear_rate:.6g} 1/s ({profile.shear_rate / params.shear_rate:.3f} "
        f"of the set one), profile linear to {profile.linearity:.3f}, {profile.lost} lost, {wall:.0f} s")  # fmt: skip
    return summary
