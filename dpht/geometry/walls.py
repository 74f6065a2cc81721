"""Wall-element table: the triangles of every wall zone, written by the geometry stage and read by
the thermal stage (wall temperature boundary conditions, particle-wall heat transfer).

File format (HDF5)::

    /            attrs: format = "dpht-walls-3",
                        zone_names (list of str; index = value stored in /zone),
                        surface_names (list of str; index = value stored in /surface),
                        geometry (JSON of the geometry config used), particle_diameter (m)
    /vertices    (M, 3, 3) float64  triangle corners, m
    /centroid    (M, 3)    float64  mean of the corners, m
    /normal      (M, 3)    float64  unit normal, right-handed with the corner order
    /area        (M,)      float64  m^2, > 0
    /zone        (M,)      int32    index into zone_names
    /surface     (M,)      int32    index into surface_names
    /primitives/zone     (K,)    int32    index into zone_names
    /primitives/kind     (K,)    int8     index into PRIMITIVE_KINDS (attribute kinds)
    /primitives/segment  (K, 4)  float64  r0, z0, r1, z1 (m), see :class:`Primitive`

Normals point into the particle region (for the tube: towards the axis; for the orifice plate:
+z, towards the bed resting on it).

Zones and surfaces are two partitions of the triangles. A *zone* carries a boundary condition (the
heated and adiabatic parts of the tube, the orifice plate, a mixer zone shared by several mixers);
a *surface* is one geometric part that a particle touches as one wall: the tube's cylinder (all its
zones), the orifice plate, each mixer solid. The thermal stage gives a particle one contact per
surface, at the nearest point of that surface (dpht.thermal.model). Format "dpht-walls-1" and
"-2" files have no surfaces and are read with one surface per zone (as are tables built without
``surface``).

Primitives are the exact surfaces that (parts of) zones are meshes of: the tube's cylinder pieces
and the orifice plate's annulus. The DEM can collide particles with the exact surface instead of
the triangles (LIGGGHTS' ``zcylinder`` for the tube, ``dem.tube_wall: primitive``); whoever then
measures particle-wall distances must use the same surface: the primitive where the DEM used it,
these very triangles (also written to ``<zone>.stl`` for LIGGGHTS) where it used the mesh. Mixer
zones have none (the DEM always uses their meshes). Format "dpht-walls-1" files (no primitives)
are read with none. Every zone with primitives lies on one surface, the primitives' surface.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.geometry.errors import GeometryError

FORMAT = "dpht-walls-3"
_READABLE = ("dpht-walls-1", "dpht-walls-2", FORMAT)
_ARRAYS = ("vertices", "centroid", "normal", "area", "zone")
PRIMITIVE_KINDS = ("cylinder", "annulus", "cone")
# A zone's mesh vertices must lie on its primitives to this fraction of the wall's size (gmsh puts
# them on the OpenCASCADE surface to round-off).
_ON_SURFACE_RTOL = 1e-9
# Relative agreement required between stored centroid/normal/area and the corners they derive from.
_CONSISTENCY_RTOL = 1e-9


def triangle_geometry(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid (M,3), unit normal (M,3) and area (M,) of triangles with corners ``vertices`` (M,3,3)."""
    a, b, c = vertices[:, 0], vertices[:, 1], vertices[:, 2]
    cross = np.cross(b - a, c - a)
    twice_area = np.linalg.norm(cross, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = cross / twice_area[:, None]
    return vertices.mean(axis=1), normal, 0.5 * twice_area


@dataclass(frozen=True)
class Primitive:
    """An exact wall surface: the surface of revolution about the tube axis (x = y = 0, along z)
    swept by the segment from (r0, z0) to (r1, z1) of the half-plane (r = distance from the axis, z):

    * ``cylinder``: r0 == r1, the cylinder r = r0 for z0 <= z <= z1 (LIGGGHTS ``zcylinder r0 0 0``);
    * ``annulus``: z0 == z1, the plane z = z0 for r0 <= r <= r1 (r0 = 0: a disc);
    * ``cone``: otherwise, a frustum (a radial mixer's funnel). Lengths in m.
    """

    zone: str
    kind: str
    segment: tuple[float, float, float, float]

    def __post_init__(self):
        r0, z0, r1, z1 = self.segment
        shape = "cylinder" if r0 == r1 else ("annulus" if z0 == z1 else "cone")
        if not all(np.isfinite(self.segment)) or min(r0, r1) < 0 or (r0 == r1 and z0 == z1):
            raise GeometryError(f"wall primitive of zone {self.zone!r}: bad segment {self.segment}")
        if self.kind != shape:
            raise GeometryError(f"wall primitive of zone {self.zone!r}: segment {self.segment} is a {shape}, not a {self.kind}")

    @classmethod
    def cylinder(cls, zone: str, radius: float, z0: float, z1: float) -> Primitive:
        return cls(zone, "cylinder", (float(radius), float(z0), float(radius), float(z1)))

    @classmethod
    def annulus(cls, zone: str, z: float, r_inner: float, r_outer: float) -> Primitive:
        return cls(zone, "annulus", (float(r_inner), float(z), float(r_outer), float(z)))

    def off_surface(self, points: np.ndarray, slack: float) -> np.ndarray:
        """Distance (m) of ``points`` (P, 3) from the cone, cylinder or plane this surface lies on,
        for the points within its extent (to ``slack`` m); NaN for the others. This is how far a
        mesh of it strays, not a distance to the surface (see dpht.thermal.primitives)."""
        r0, z0, r1, z1 = self.segment
        rho, z = np.hypot(points[:, 0], points[:, 1]), points[:, 2]
        length = np.hypot(r1 - r0, z1 - z0)
        along = ((rho - r0) * (r1 - r0) + (z - z0) * (z1 - z0)) / length
        across = np.abs((rho - r0) * (z1 - z0) - (z - z0) * (r1 - r0)) / length
        return np.where((along >= -slack) & (along <= length + slack), across, np.nan)


@dataclass(frozen=True)
class Walls:
    """Wall triangles with their zone; arrays as in the file format above."""

    vertices: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    zone: np.ndarray
    zone_names: tuple[str, ...]
    primitives: tuple[Primitive, ...] = ()
    surface: np.ndarray | None = None  # (M,) int32 index into surface_names; None: one surface per zone
    surface_names: tuple[str, ...] | None = None

    def __post_init__(self):
        if self.surface is None:  # one surface per zone, named after it
            object.__setattr__(self, "surface", np.asarray(self.zone, dtype=np.int32))
            object.__setattr__(self, "surface_names", tuple(self.zone_names))
        m = self.vertices.shape[0] if self.vertices.ndim == 3 else -1
        expected = {"vertices": (m, 3, 3), "centroid": (m, 3), "normal": (m, 3), "area": (m,), "zone": (m,), "surface": (m,)}
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise GeometryError(f"wall table: {name} has shape {getattr(self, name).shape}, expected {shape}")
        for kind in ("zone", "surface"):
            names, index = getattr(self, f"{kind}_names"), getattr(self, kind)
            if names is None or len(set(names)) != len(names) or not all(isinstance(z, str) for z in names):
                raise GeometryError(f"wall table: {kind}_names must be distinct strings, got {names!r}")
            if m and (index.min() < 0 or index.max() >= len(names)):
                raise GeometryError(f"wall table: {kind} indices outside 0..{len(names) - 1}")
        if not np.all(np.isfinite(self.vertices)):
            raise GeometryError("wall table: vertices contain non-finite values")
        centroid, normal, area = triangle_geometry(self.vertices)
        if np.any(area <= 0):
            raise GeometryError(f"wall table: {int(np.sum(area <= 0))} degenerate triangle(s) with zero area")
        scale = np.abs(self.vertices).max() if m else 1.0
        if not (
            np.allclose(self.centroid, centroid, rtol=0, atol=_CONSISTENCY_RTOL * scale)
            and np.allclose(self.normal, normal, rtol=0, atol=_CONSISTENCY_RTOL)
            and np.allclose(self.area, area, rtol=_CONSISTENCY_RTOL, atol=0)
        ):
            raise GeometryError("wall table: centroid, normal or area disagree with the vertices")
        self._check_primitives(scale)

    def _check_primitives(self, scale: float) -> None:
        """Every vertex of a zone that has primitives lies on one of them, and the zone on one surface."""
        for name in dict.fromkeys(p.zone for p in self.primitives):
            if name not in self.zone_names:
                raise GeometryError(f"wall table: a primitive names zone {name!r}, which has no triangles")
            surfaces = np.unique(self.surface[self.zone_mask(name)])
            if surfaces.size != 1:
                raise GeometryError(
                    f"wall table: zone {name!r} has primitives but spans the surfaces "
                    f"{[self.surface_names[s] for s in surfaces]}; a zone with primitives must lie on one surface"
                )
            corners = self.vertices[self.zone_mask(name)].reshape(-1, 3)
            tol = _ON_SURFACE_RTOL * scale
            off = np.fmin.reduce([p.off_surface(corners, tol) for p in self.primitives if p.zone == name])
            worst = np.nanmax(np.where(np.isnan(off), np.inf, off)) if off.size else 0.0
            if worst > tol:
                raise GeometryError(
                    f"wall table: zone {name!r} has mesh vertices {worst:.3g} m off its primitives (or outside them)"
                )

    @classmethod
    def from_vertices(cls, vertices: np.ndarray, zone: np.ndarray, zone_names, primitives=(), surface=None,
                      surface_names=None) -> Walls:  # fmt: skip
        """Build the table from triangle corners (M,3,3) and zone indices, deriving the rest;
        without ``surface`` (indices into ``surface_names``) each zone is its own surface."""
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        centroid, normal, area = triangle_geometry(vertices)
        surface = None if surface is None else np.asarray(surface, dtype=np.int32)
        return cls(vertices, centroid, normal, area, np.asarray(zone, dtype=np.int32), tuple(zone_names), tuple(primitives),
                   surface, None if surface_names is None else tuple(surface_names))  # fmt: skip

    def __len__(self) -> int:
        return self.area.size

    def zone_mask(self, name: str) -> np.ndarray:
        """Boolean mask (M,) of the triangles in zone ``name``."""
        if name not in self.zone_names:
            raise GeometryError(f"wall zone {name!r} does not exist; zones are {list(self.zone_names)}")
        return self.zone == self.zone_names.index(name)

    def primitive_surface(self, primitive: Primitive) -> int:
        """Index of the surface that ``primitive`` (one of :attr:`primitives`) is the exact form of."""
        return int(self.surface[self.zone_mask(primitive.zone)][0])


def save_walls(path: str | Path, walls: Walls, geometry_json: str, particle_diameter: float) -> None:
    """Write ``walls`` to ``path`` with the geometry config (JSON text) and particle diameter (m)."""
    with h5py.File(path, "w") as f:
        f.attrs.update(
            format=FORMAT,
            zone_names=list(walls.zone_names),
            surface_names=list(walls.surface_names),
            geometry=geometry_json,
            particle_diameter=float(particle_diameter),
        )
        for name in (*_ARRAYS, "surface"):
            f.create_dataset(name, data=getattr(walls, name))
        g = f.create_group("primitives")
        g.attrs["kinds"] = list(PRIMITIVE_KINDS)
        p = walls.primitives
        g.create_dataset("zone", data=np.array([walls.zone_names.index(q.zone) for q in p], dtype=np.int32))
        g.create_dataset("kind", data=np.array([PRIMITIVE_KINDS.index(q.kind) for q in p], dtype=np.int8))
        g.create_dataset("segment", data=np.array([q.segment for q in p], dtype=np.float64).reshape(-1, 4))


def load_walls(path: str | Path) -> Walls:
    """Read a wall table written by :func:`save_walls`; a malformed file raises GeometryError naming it."""
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise GeometryError(f"{path} does not exist (expected a wall table)") from None
    except OSError as error:
        raise GeometryError(f"{path} cannot be read as HDF5 ({error}); expected a wall table") from None
    with f:
        if f.attrs.get("format") not in _READABLE:
            raise GeometryError(f"{path}: not a wall table (attribute format not in {_READABLE})")
        missing = [name for name in _ARRAYS if name not in f]
        if missing or "zone_names" not in f.attrs:
            raise GeometryError(f"{path}: missing {missing or ['attribute zone_names']}")
        arrays = {name: f[name][...] for name in _ARRAYS}
        zone_names = tuple(str(z) for z in np.atleast_1d(f.attrs["zone_names"]).astype(str))
        surface, surface_names = None, None  # formats 1 and 2: one surface per zone
        if f.attrs["format"] == FORMAT:
            if "surface" not in f or "surface_names" not in f.attrs:
                raise GeometryError(f"{path}: missing /surface or attribute surface_names")
            surface = f["surface"][...]
            surface_names = tuple(str(z) for z in np.atleast_1d(f.attrs["surface_names"]).astype(str))
        stored = {name: f["primitives"][name][...] for name in ("zone", "kind", "segment")} if "primitives" in f else None
    try:
        primitives = () if stored is None else tuple(
            Primitive(zone_names[z], PRIMITIVE_KINDS[k], tuple(float(v) for v in seg))
            for z, k, seg in zip(stored["zone"], stored["kind"], stored["segment"])
        )  # fmt: skip
    except (IndexError, GeometryError) as error:
        raise GeometryError(f"{path}: bad /primitives: {error}") from None
    for name, values in (("zone", arrays["zone"]), ("surface", surface)):
        if values is not None and values.dtype.kind not in "iu":
            raise GeometryError(f"{path}: /{name} must hold integers, found {values.dtype}")
    try:
        return Walls(
            *(np.asarray(arrays[name], dtype=np.float64) for name in _ARRAYS[:4]),
            zone=arrays["zone"].astype(np.int32),
            zone_names=zone_names,
            primitives=primitives,
            surface=None if surface is None else surface.astype(np.int32),
            surface_names=surface_names,
        )
    except GeometryError as error:
        raise GeometryError(f"{path}: {error}") from None
