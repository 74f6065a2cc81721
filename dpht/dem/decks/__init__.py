"""LIGGGHTS decks: the templates in this package (``*.in``) rendered from the DEM parameters.

Placeholders are ``@{name}``; ``${name}`` is left for LIGGGHTS' own variables (``-var``: ``pz``, the
processor slabs along the tube axis, :meth:`DemParams.z_slabs`, so a run resumed on another number
of ranks reads the same decks). Two decks run in one work directory, whose layout they fix::

    settle.in   fill the tube above the orifice (closed by a temporary plane), settle, write
                settle/settled.restart; for a driven slice (dem.drive without orifice: DemParams.packed)
                the text of pack.in instead: pack the periodic tube without a seam (frictionless,
                in a shrinking box)
    flow.in     remove the plane; particles leave through the orifice and re-enter at the top
                through the periodic boundary z = 0 | L; dumps flow/post/dump.<step>.txt every
                dem.dump_interval steps, restarts flow/restart/flow.<step>.restart
    meshes/     walls.stl, the wall STLs the decks read, one file (so the decks do not depend on paths)

header.in is the LIGGGHTS set-up the decks share and model.in the contact model, materials, walls
and output. The STL zones (:attr:`DemParams.mesh_zones`, in that order) are one ``fix mesh/surface``
(ID ``mesh_walls``) read from one file holding their triangles zone after zone: LIGGGHTS spends time
per mesh and particle on every step, so one mesh for the orifice plate and a mixer ran 1.8 times as
fast as one each (README, The mixer study). The tube's cylinder is LIGGGHTS' ``zcylinder`` primitive
unless ``dem.tube_wall`` is "mesh".
"""

from __future__ import annotations

import string
from importlib import resources

from dpht.dem import dumps
from dpht.dem.params import PACK_DAMPING_TIME, DemParams, next_prime

# Hertz normal contact, tangential history, rolling friction epsd2: pairs and walls (DPHT paper, Table 2).
CONTACT_MODEL = "model hertz tangential history rolling_friction epsd2"
GRAVITY = 9.81  # m/s2, along -z
INSERT_SPEED = 0.5  # m/s downwards, so each event's particles clear the region for the next one
# LIGGGHTS refuses Young's moduli below this in SI units unless told the particles are soft on purpose
# (a softened DEM modulus buys a longer step; the thermal stage corrects contact conduction for it).
SOFT_MODULUS = 5.0e6  # Pa
SKIN = 0.25  # neighbour skin in particle diameters; 0.1-0.25 ran equally fast here, 0.4 slower
# Axes (x, y, z) whose periodic boundary (`boundary f f p`) only recycles particles from the outlet
# back to the inlet: the real tube has a hopper above and an outlet below, so no heat crosses it.
# Written to the positions file (attribute `recycled`, dpht.dem.dumps), read by the thermal stage;
# the same for a driven run (dem.drive): whether it stands for a whole tube (particles re-enter at
# the inlet temperature) or for a travelling slice of one (thermal.slice: the same particles all the
# way down, periodic for heat) is the thermal stage's reading of it.
RECYCLED = (False, False, True)
# The thermo output (columns as dpht.dem.liggghts.THERMO_COLUMNS); a driven flow adds the controller's
# acceleration averaged over each thermo interval (DRIVE_COLUMN).
THERMO_STYLE = "step atoms time c_iz_sum c_z_max f_ts_check[1] f_ts_check[2]"

SETTLE_DIR, FLOW_DIR, MESH_DIR = "settle", "flow", "meshes"
WALL_MESH = "walls.stl"  # in MESH_DIR: the triangles of every mesh zone, zone after zone
WALL_MESH_ID = "mesh_walls"
SETTLED_RESTART = f"{SETTLE_DIR}/settled.restart"
RESTART_GLOB = "flow.*.restart"


class _DeckTemplate(string.Template):
    delimiter = "@"  # LIGGGHTS uses $ for its own variables


def _fmt(value) -> str:
    return str(value) if isinstance(value, int) else repr(float(value))


def _template(name: str) -> _DeckTemplate:
    return _DeckTemplate(resources.files(__name__).joinpath(name).read_text())


def _wall_fixes(params: DemParams) -> str:
    """The mesh zones as one mesh/surface and its wall (none in a driven slice with the primitive tube),
    and the primitive tube."""
    lines = []
    if params.mesh_zones:
        lines.append(f"fix {WALL_MESH_ID} all mesh/surface file {MESH_DIR}/{WALL_MESH} type 2")
        lines.append(f"fix walls all wall/gran {CONTACT_MODEL} mesh n_meshes 1 meshes {WALL_MESH_ID}")
    if params.tube_wall == "primitive":
        lines.append(_tube_primitive(params))
    return "\n".join(lines)


def _tube_primitive(params: DemParams) -> str:
    """The tube wall as LIGGGHTS' exact cylinder."""
    return f"fix tube_wall all wall/gran {CONTACT_MODEL} primitive type 2 zcylinder {_fmt(params.tube_radius)} 0.0 0.0"


def _thermo(params: DemParams, columns: str = THERMO_STYLE) -> str:
    """Thermo output every dump interval (thermo_style resets thermo_modify, so both are given)."""
    return f"thermo_style custom {columns}\nthermo {params.dump_interval}\nthermo_modify flush yes lost ignore norm no"


def _drive(params: DemParams) -> str:
    """The controller of a driven flow (dem.drive), or nothing: gravity balanced, and a uniform
    acceleration -(v_mean + velocity)/time_constant on every particle, so the mean axial velocity
    relaxes to -velocity and wall drag is made up by the whole bed, as the weight does in a tall tube.
    With dem.drive.mass_flow the velocity is mass_flow x length / (mass of all particles): the mean
    mass flow through every cross-section of the periodic tube. The net body acceleration (the
    effective gravity, m/s^2 downwards), averaged over each thermo interval, is printed as the last
    thermo column."""
    if not params.driven:
        return "# Orifice flow: gravity drives the bed through the orifice plate."
    if params.drive_mass_flow is not None:
        velocity = f"{_fmt(params.drive_mass_flow * params.length)}/mass(all)"
        what = "the mean mass flow held at mass_flow"
    else:
        velocity = _fmt(params.drive_velocity)
        what = "the mean axial velocity held at -velocity"
    tau = _fmt(params.drive_time_constant)
    return "\n".join((
        f"# Drive (dem.drive): gravity balanced, {what}.",
        f"variable drive_error equal vcm(all,z)+{velocity}",
        f"variable drive_force atom mass*({_fmt(GRAVITY)}-v_drive_error/{tau})",
        "fix drive all addforce 0.0 0.0 v_drive_force",
        f"variable drive_acceleration equal v_drive_error/{tau}",
        f"fix drive_mean all ave/time 1 {params.dump_interval} {params.dump_interval} v_drive_acceleration",
        _thermo(params, f"{THERMO_STYLE} f_drive_mean"),
    ))


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
    seed_template = next_prime(params.seed)
    values = {
        "contact_model": CONTACT_MODEL,
        "wall_fixes": _wall_fixes(params),
        "skin": SKIN * params.diameter,
        "binsize": 0.5 * (1.0 + SKIN) * params.diameter,
        "soft_particles": "soft_particles yes" if min(params.youngs_p, params.youngs_w) < SOFT_MODULUS else "",
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
        "thermo": _thermo(params),
        "xlo": -half_width,
        "xhi": half_width,
        "ylo": -half_width,
        "yhi": half_width,
        "length": params.length,
        "orifice_height": params.orifice_height,
        "seed_insert": params.seed,
        "seed_template": seed_template,
        "seed_distribution": next_prime(seed_template),
        "density": params.density,
        "radius": params.radius,
        "diameter": params.diameter,
        "fill_regions": _fill_regions(params),
        "n_particles": params.n_particles,
        "insert_rate": steps["per_event"] / (steps["insert_every"] * params.timestep),
        "insert_every": steps["insert_every"],
        "insert_velocity": -INSERT_SPEED,
        "insert_end": steps["insert_end"],
        "settle_end": steps["settle_end"],
        "settled_restart": SETTLED_RESTART,
        "settled_dump": f"{SETTLE_DIR}/post/dump.{steps['settle_end']}.txt",
        "restart_every": params.restart_interval,
        "restart_files": f"{FLOW_DIR}/restart/{RESTART_GLOB}",
        "dump_every": params.dump_interval,
        "dump_files": f"{FLOW_DIR}/post/{dumps.DUMP_GLOB}",
        "flow_end": steps["flow_end"],
        "drive": _drive(params),
        "pack_length": params.pack_length,
        "pack_top": params.pack_length - params.radius,
        "fill_radius": params.fill_radius,
        "pack_damping": params.particle_mass / PACK_DAMPING_TIME,
        "pack_damping_time": PACK_DAMPING_TIME,
        "compress_end": steps.get("compress_end", 0),
    }
    return {key: _fmt(value) if not isinstance(value, str) else value for key, value in values.items()}


def _render(name: str, values: dict[str, str]) -> str:
    model = _template("model.in").substitute(values).rstrip()
    header = _template("header.in").substitute(values).rstrip()
    return _template(name).substitute(values, model=model, header=header)


# Contacts while packing a driven tube (pack.in): frictionless, so the bed packs without jamming.
_FRICTIONLESS = {f"{name}_{pair}": "0.0" for name in ("friction", "rolling") for pair in ("pp", "pw")}


def render_decks(params: DemParams) -> dict[str, str]:
    """The deck texts ``{"settle.in": ..., "flow.in": ...}``; identical for identical params."""
    values = _deck_values(params)
    settle = _render("pack.in", {**values, **_FRICTIONLESS}) if params.packed else _render("settle.in", values)
    return {"settle.in": settle, "flow.in": _render("flow.in", values)}


def render_check_deck(params: DemParams) -> str:
    """A deck running one particle for one thermo interval in the stage's model (the tube wall as the
    primitive cylinder, no meshes), printing LIGGGHTS' own time-step check at full precision."""
    values = {**_deck_values(params), "wall_fixes": _tube_primitive(params), "mid_height": _fmt(0.5 * params.length)}
    return _render("check.in", values)

