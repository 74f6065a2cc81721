"""The scenes a chain runs (docs/theory/chain.md): each segment of :class:`dpht.chain.segments.Chain`
as a scene config the workflow's stages run like any other, from the chain's scene ``c``.

- **The slices' DEM** is one run for every slice: ``chain.slice_length`` of the tube, packed
  without a seam, loaded to the wall stress of a tall tube (``wall_stress: weight``) and driven at
  the plug-flow velocity of the chain's mass flow, ``v = m / (rho phi A)`` with phi
  ``dem.fill_solid_fraction`` (what the slice is packed to): the Watkins slice
  (:mod:`dpht.thermal.slice`). Each slice's thermal run carries it from the top of its stretch over
  its length, the scene's wall temperature expressions evaluated at the height it has reached.
- **A resolved segment's DEM** depends on its shape only (:meth:`dpht.chain.segments.Segment.shape`),
  never on where it sits: its stretch, the inserts at their places in it, in a periodic tube driven
  at the chain's mass flow (``dem.drive.mass_flow``, ``orifice: true``): from z = 0 up, the
  periodic outlet, a plate at PLATE diameters (the scene's orifice plate for the segment that holds
  it; otherwise a ledge of one diameter at the wall that carries the poured bed and meters
  nothing), RUN_OUT diameters of plain tube (none under the real plate), the segment's stretch from
  z = b, the bed HEAD diameters above it and FREE diameters of empty tube where the recycled
  particles re-enter. Its outlet is the plane z = b (:mod:`dpht.thermal.outlet`); its geometry's
  heated zone is the stretch [b, b + L].
- **A resolved segment's thermal run** sees the tube where the segment sits: its wall zones are the
  DEM's with the heated zone cut where the scene's heated range ends inside the stretch (the same
  zones, other triangles: the DEM run is shared), and every wall temperature expression is the
  scene's with z replaced by z + (bottom - b), the scene's z of the segment's own.

The scene's ``thermal.walls.adiabatic_wall`` must be adiabatic: the run-out and head of a resolved
segment's DEM are no part of the tube, and share that zone.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

from dpht.chain.segments import JOINT_TOLERANCE, RESOLVED, Chain, Segment
from dpht.errors import ConfigError
from dpht.geometry.errors import GeometryError
from dpht.geometry.layout import layout
from dpht.geometry.tube import ADIABATIC, HEATED, ORIFICE
from dpht.util.expr import shifted

PLATE, RUN_OUT, HEAD, FREE = 2.0, 3.0, 2.0, 2.0  # particle diameters (module docstring)
SLICE_PLATE = 0.05  # particle diameters: the slice's orifice plate height (not in its driven DEM)
WALL_VARIABLES = ("x", "y", "z")
DEM_SETTINGS_DROPPED = ("target_mass_flow", "mass_flow_tolerance")  # the chain's DEM runs are driven at its flow


@dataclass(frozen=True)
class SegmentScene:
    """One segment's scene: ``config`` (its thermal run's: geometry with its wall zones, thermal
    section) and ``dem_config`` (its DEM run's: shared by the segments of one shape, or by every
    slice), the ``plane`` (m, z in its DEM) a resolved segment hands over across (None: a slice)."""

    segment: Segment
    config: dict
    dem_config: dict
    plane: float | None


def mass_flow(c: dict) -> float:
    """The chain's mass flow (kg/s): ``dem.drive.mass_flow`` of its scene."""
    drive = c["dem"].get("drive") or {}
    if "mass_flow" not in drive:
        raise ConfigError("dem.drive.mass_flow: a chain runs every segment at one mass flow (kg/s), given here; "
                          f"the scene's dem.drive is {drive or None}")  # fmt: skip
    return float(drive["mass_flow"])


def scenes(c: dict, chain: Chain, bound: float) -> list[SegmentScene]:
    """Every segment's scene, in flow order (ConfigError naming the key when the scene cannot be a
    chain); ``bound``: K, the scene's wall temperature farthest from its inlet temperature (:func:`_starting`)."""
    walls = c["thermal"]["walls"]
    if walls.get(ADIABATIC, "adiabatic") != "adiabatic":
        raise ConfigError(f"thermal.walls.{ADIABATIC}: a chain needs it adiabatic (a resolved segment's DEM tube "
                          "reaches beyond its stretch, in that zone)")  # fmt: skip
    flow = mass_flow(c)
    c = {k: v for k, v in c.items() if k != "chain"}
    slice_dem = _slice_dem(c, chain, flow)
    found = [_resolved(c, s, flow) if s.kind == RESOLVED else _slice(c, s, slice_dem) for s in chain.segments]
    inlet = c["thermal"]["inlet_temperature"]
    return [_starting(scene, inlet if k == 0 else bound) for k, scene in enumerate(found)]


def _starting(scene: SegmentScene, temperature: float) -> SegmentScene:
    """``scene`` with ``thermal.initial_temperature`` set: the first segment's particles start at the
    inlet temperature; every later segment's start at the field of the one above (those without a
    position in its first frame at ``temperature``, the wall temperature farthest from the inlet's,
    so that its tables span every temperature a field can hold)."""
    thermal = {**scene.config["thermal"], "initial_temperature": temperature}
    return SegmentScene(scene.segment, {**scene.config, "thermal": thermal}, scene.dem_config, scene.plane)


def check(c: dict, bound: float) -> None:
    """ConfigError naming the segment and the key when a segment's scene cannot be built (its
    geometry as the geometry stage checks it)."""
    d = c["particles"]["diameter"]
    for k, scene in enumerate(scenes(c, Chain.of(c), bound)):
        for config in (scene.config, scene.dem_config):
            try:
                layout(config["geometry"], d)
            except GeometryError as err:
                raise ConfigError(f"chain: segment {k} ({scene.segment.kind}, z {scene.segment.bottom:.6g}-"
                                  f"{scene.segment.top:.6g} m) cannot be built: {err}") from None


def _dem(c: dict, drive: dict, fill_height: float) -> dict:
    dem = {k: v for k, v in c["dem"].items() if k not in DEM_SETTINGS_DROPPED}
    time_constant = (c["dem"].get("drive") or {}).get("time_constant")
    return {**dem, "drive": {**drive, **({} if time_constant is None else {"time_constant": time_constant})},
            "fill_height": fill_height}  # fmt: skip


def _slice_dem(c: dict, chain: Chain, flow: float) -> dict:
    d, D = c["particles"]["diameter"], c["geometry"]["tube"]["inner_diameter"]
    length = chain.slice_length
    phi = c["dem"]["fill_solid_fraction"]
    velocity = flow / (c["particles"]["density"] * phi * math.pi * D * D / 4)
    tube = {**c["geometry"]["tube"], "length": length, "orifice_height": SLICE_PLATE * d, "heated": [0.0, length]}
    geometry = {**{k: v for k, v in c["geometry"].items() if k != "mixers"}, "tube": tube}
    return {**c, "geometry": geometry,
            "dem": _dem(c, {"velocity": velocity, "wall_stress": "weight"}, length - SLICE_PLATE * d - 1.5 * d)}  # fmt: skip


def _slice(c: dict, s: Segment, dem_config: dict) -> SegmentScene:
    """A slice carried from the top of its stretch over its length (its wall heated or adiabatic all the way)."""
    low, high = c["geometry"]["tube"]["heated"]
    heated = low - JOINT_TOLERANCE <= 0.5 * (s.bottom + s.top) <= high + JOINT_TOLERANCE
    walls = {HEATED: c["thermal"]["walls"][HEATED] if heated else "adiabatic", ADIABATIC: "adiabatic", ORIFICE: "adiabatic"}
    thermal = {**c["thermal"], "walls": walls, "slice": {"inlet_height": s.top, "distance": s.length, "frames": "mirror"}}
    return SegmentScene(s, {**dem_config, "thermal": thermal}, dem_config, None)


def _resolved(c: dict, s: Segment, flow: float) -> SegmentScene:
    d = c["particles"]["diameter"]
    scene_tube = c["geometry"]["tube"]
    # Lengths rounded to a nanometre, as Segment.shape: equal shapes give equal DEM runs bit for bit.
    plate = _nm(PLATE * d)
    b = plate if s.outlet else _nm(plate + RUN_OUT * d)  # the segment's bottom in its DEM
    stretch = _nm(s.length)
    length = _nm(b + stretch + (HEAD + FREE) * d)
    offset = b - s.bottom  # DEM z - scene z
    hole = scene_tube["orifice_diameter"] if s.outlet else scene_tube["inner_diameter"] - 2 * d
    tube = {**scene_tube, "length": length, "orifice_height": plate, "orifice_diameter": hole, "heated": [b, _nm(b + stretch)]}
    mixers = []
    for insert in s.inserts:
        mixer = copy.deepcopy(c["geometry"]["mixers"][insert.index])
        mixer["height"] = _nm(mixer["height"] + offset)
        mixers.append(mixer)
    geometry = {**{k: v for k, v in c["geometry"].items() if k != "mixers"}, "tube": tube, **({"mixers": mixers} if mixers else {})}
    dem_config = {**c, "geometry": geometry,
                  "dem": _dem(c, {"mass_flow": flow, "orifice": True}, _nm(b + stretch + HEAD * d - plate))}  # fmt: skip
    # Its thermal run: the scene's heated range in the segment's z, within its stretch.
    top = tube["heated"][1]
    low, high = (min(max(b, _nm(z + offset)), top) for z in scene_tube["heated"])
    walls = {zone: _moved(condition, -offset, f"thermal.walls.{zone}") for zone, condition in c["thermal"]["walls"].items()}
    if not s.outlet:
        walls[ORIFICE] = "adiabatic"  # the ledge carrying the poured bed is no part of the tube
    if high - low <= JOINT_TOLERANCE:
        walls[HEATED] = "adiabatic"  # the segment lies outside the heated range: its DEM's zones, none heated
        thermal_geometry = geometry
    else:
        thermal_geometry = {**geometry, "tube": {**tube, "heated": [low, high]}}
    thermal = {**c["thermal"], "walls": walls}
    return SegmentScene(s, {**dem_config, "geometry": thermal_geometry, "thermal": thermal}, dem_config, b)


def _nm(length: float) -> float:
    """m, rounded to a nanometre."""
    return round(length, 9)


def _moved(condition, offset: float, key: str):
    """A wall condition with its temperature expression of z evaluated at z + ``offset``."""
    if condition == "adiabatic":
        return condition
    return {**condition, "temperature": shifted(condition["temperature"], "z", offset, WALL_VARIABLES, f"{key}.temperature")}
