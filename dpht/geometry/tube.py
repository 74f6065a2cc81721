"""The tube with an orifice plate: validated dimensions and its OpenCASCADE surfaces in gmsh.

Conventions shared with the DEM and thermal stages: units m; tube axis z through x = y = 0; flow
towards -z. The wall is an open cylinder of radius D/2 from z = 0 to z = length, whose ends lie on
the periodic boundaries of the DEM domain. It is cut at z = orifice_height and at both ends of the
heated range, so that no triangle straddles two zones. The orifice plate is a flat annulus at
z = orifice_height sharing its outer circle with the cylinder (conformal mesh, no gap).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from dpht.geometry.errors import GeometryConfigError
from dpht.geometry.walls import Primitive

from dpht.geometry import checks

HEATED, ADIABATIC, ORIFICE = "heated_wall", "adiabatic_wall", "orifice"
CYLINDER, PLATE = "tube", "orifice_plate"  # the tube's surfaces (geometry.walls): its zones lie on these
KEY = "geometry.tube"
_KEYS = ("inner_diameter", "length", "orifice_height", "orifice_diameter", "heated")


def towards_axis(centroid: np.ndarray) -> np.ndarray:
    """Reference direction for the cylinder normals: radially inwards, into the particles."""
    return np.column_stack([-centroid[:, 0], -centroid[:, 1], np.zeros(len(centroid))])


def upwards(centroid: np.ndarray) -> np.ndarray:
    """Reference direction for the orifice-plate normals: +z, towards the bed resting on the plate."""
    return np.tile([0.0, 0.0, 1.0], (len(centroid), 1))


@dataclass(frozen=True)
class WallPatch:
    """gmsh surfaces that make up (part of) one wall zone, the wall surface (geometry.walls) they
    lie on, and the side their normals must face."""

    zone: str
    surfaces: tuple[int, ...]
    facing: Callable[[np.ndarray], np.ndarray]
    wall_surface: str


@dataclass(frozen=True)
class Tube:
    """Tube dimensions in m; build with :meth:`from_config` to get them checked."""

    inner_diameter: float
    length: float
    orifice_height: float
    orifice_diameter: float
    heated: tuple[float, float]

    @classmethod
    def from_config(cls, cfg: dict, particle_diameter: float, min_passage: float, element_size: float) -> Tube:
        """Check the ``geometry.tube`` mapping; GeometryConfigError names the offending key.

        ``min_passage``: smallest orifice diameter in particle diameters. ``element_size`` (m) sets
        how close two cuts of the cylinder may be without being equal (closer ones give slivers).
        """
        checks.keys(cfg, KEY, _KEYS)
        size = {name: checks.number(cfg[name], f"{KEY}.{name}") for name in _KEYS[:4]}
        for name in ("inner_diameter", "length", "orifice_diameter"):
            if size[name] <= 0:
                raise GeometryConfigError(f"{KEY}.{name} must be positive (m), got {size[name]}")
        length, d_tube, d_hole = size["length"], size["inner_diameter"], size["orifice_diameter"]
        if not 0 < size["orifice_height"] < length:
            raise GeometryConfigError(f"{KEY}.orifice_height must lie in (0, length = {length}) m, got {cfg['orifice_height']}")
        if d_hole >= d_tube:
            raise GeometryConfigError(f"{KEY}.orifice_diameter ({d_hole} m) must be smaller than inner_diameter ({d_tube} m)")
        if d_hole < min_passage * particle_diameter:
            raise GeometryConfigError(
                f"{KEY}.orifice_diameter ({d_hole} m) must be at least geometry.min_passage = {min_passage} "
                f"particle diameters ({min_passage * particle_diameter} m)"
            )
        heated = cfg["heated"]
        if not isinstance(heated, (list, tuple)) or len(heated) != 2:
            raise GeometryConfigError(f"{KEY}.heated must be a pair [z0, z1] (m), got {heated!r}")
        z0, z1 = (checks.number(z, f"{KEY}.heated") for z in heated)
        if not 0 <= z0 < z1 <= length:
            raise GeometryConfigError(f"{KEY}.heated must satisfy 0 <= z0 < z1 <= length = {length} m, got {list(heated)}")
        tube = cls(d_tube, length, size["orifice_height"], d_hole, (z0, z1))
        gaps = np.diff(tube.cuts())
        if np.any(gaps < 1e-3 * element_size):
            raise GeometryConfigError(
                f"{KEY}: heated ends and orifice_height are closer than {1e-3 * element_size:.3g} m to each "
                f"other or to the tube ends (cuts at {list(tube.cuts())}); make them equal or further apart"
            )
        return tube

    @property
    def radius(self) -> float:
        return 0.5 * self.inner_diameter

    @property
    def orifice_radius(self) -> float:
        return 0.5 * self.orifice_diameter

    def cuts(self) -> tuple[float, ...]:
        """Heights (m) where the cylinder is cut into segments, from 0 to length."""
        return tuple(sorted({0.0, self.orifice_height, *self.heated, self.length}))

    def segment_zone(self, z_bottom: float, z_top: float) -> str:
        z0, z1 = self.heated
        return HEATED if z0 <= z_bottom and z_top <= z1 else ADIABATIC

    def exact_areas(self) -> dict[str, float]:
        """Areas (m^2) of the smooth zones: cylinder pi*D*dz, annulus pi*(R^2 - r^2)."""
        areas = {HEATED: 0.0, ADIABATIC: 0.0}
        cuts = self.cuts()
        for za, zb in zip(cuts[:-1], cuts[1:]):
            areas[self.segment_zone(za, zb)] += math.pi * self.inner_diameter * (zb - za)
        areas[ORIFICE] = math.pi * (self.radius**2 - self.orifice_radius**2)
        return areas

    def primitives(self) -> list[Primitive]:
        """The exact surfaces of the zones: one cylinder piece per segment between cuts, and the
        orifice plate's annulus."""
        cuts = self.cuts()
        pieces = [Primitive.cylinder(self.segment_zone(za, zb), self.radius, za, zb) for za, zb in zip(cuts[:-1], cuts[1:])]
        return pieces + [Primitive.annulus(ORIFICE, self.orifice_height, self.orifice_radius, self.radius)]

    def volume_above_orifice(self) -> float:
        """Volume (m^3) inside the smooth cylinder between the plate and z = length."""
        return math.pi * self.radius**2 * (self.length - self.orifice_height)

    def add_to_model(self) -> list[WallPatch]:
        """Add the wall surfaces to the current gmsh model (OCC kernel, not yet synchronised).

        Each cylinder segment is a ruled loft between circles created at the exact cut heights
        (extruding instead accumulates round-off: the top ring landed 1 ulp above z = length), so
        consecutive segments and the plate share their circles and the mesh is conformal across zones.
        """
        import gmsh

        occ = gmsh.model.occ
        cuts = self.cuts()
        circle_at = {z: occ.addCircle(0.0, 0.0, z, self.radius) for z in cuts}
        wires = [occ.addWire([circle_at[z]]) for z in cuts]
        segments: dict[str, list[int]] = {HEATED: [], ADIABATIC: []}
        for (za, zb), bottom, top in zip(zip(cuts[:-1], cuts[1:]), wires[:-1], wires[1:]):
            lofted = occ.addThruSections([bottom, top], makeSolid=False, makeRuled=True)
            segments[self.segment_zone(za, zb)] += [tag for dim, tag in lofted if dim == 2]
        hole = occ.addCircle(0.0, 0.0, self.orifice_height, self.orifice_radius)
        plate = occ.addPlaneSurface([occ.addCurveLoop([circle_at[self.orifice_height]]), occ.addCurveLoop([hole])])
        patches = [WallPatch(zone, tuple(tags), towards_axis, CYLINDER) for zone, tags in segments.items() if tags]
        return patches + [WallPatch(ORIFICE, (plate,), upwards, PLATE)]
