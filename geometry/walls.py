"""Wall-element table: the triangles of every wall zone, written by the geometry stage and read by
the thermal stage (wall temperature boundary conditions, particle-wall heat transfer).

File format (HDF5)::

    /            attrs: format = "dpht-walls-1",
                        zone_names (list of str; index = value stored in /zone),
                        geometry (JSON of the geometry config used), particle_diameter (m)
    /vertices    (M, 3, 3) float64  triangle corners, m
    /centroid    (M, 3)    float64  mean of the corners, m
    /normal      (M, 3)    float64  unit normal, right-handed with the corner order
    /area        (M,)      float64  m^2, > 0
    /zone        (M,)      int32    index into zone_names

Normals point into the particle region (for the tube: towards the axis; for the orifice plate:
+z, towards the bed resting on it).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from geometry.errors import GeometryError

FORMAT = "dpht-walls-1"
_ARRAYS = ("vertices", "centroid", "normal", "area", "zone")
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
class Walls:
    """Wall triangles with their zone; arrays as in the file format above."""

    vertices: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    zone: np.ndarray
    zone_names: tuple[str, ...]

    def __post_init__(self):
        m = self.vertices.shape[0] if self.vertices.ndim == 3 else -1
        expected = {"vertices": (m, 3, 3), "centroid": (m, 3), "normal": (m, 3), "area": (m,), "zone": (m,)}
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise GeometryError(f"wall table: {name} has shape {getattr(self, name).shape}, expected {shape}")
        if len(set(self.zone_names)) != len(self.zone_names) or not all(isinstance(z, str) for z in self.zone_names):
            raise GeometryError(f"wall table: zone_names must be distinct strings, got {self.zone_names!r}")
        if m and (self.zone.min() < 0 or self.zone.max() >= len(self.zone_names)):
            raise GeometryError(f"wall table: zone indices outside 0..{len(self.zone_names) - 1}")
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

    @classmethod
    def from_vertices(cls, vertices: np.ndarray, zone: np.ndarray, zone_names) -> Walls:
        """Build the table from triangle corners (M,3,3) and zone indices, deriving the rest."""
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        centroid, normal, area = triangle_geometry(vertices)
        return cls(vertices, centroid, normal, area, np.asarray(zone, dtype=np.int32), tuple(zone_names))

    def __len__(self) -> int:
        return self.area.size

    def zone_mask(self, name: str) -> np.ndarray:
        """Boolean mask (M,) of the triangles in zone ``name``."""
        if name not in self.zone_names:
            raise GeometryError(f"wall zone {name!r} does not exist; zones are {list(self.zone_names)}")
        return self.zone == self.zone_names.index(name)


def save_walls(path: str | Path, walls: Walls, geometry_json: str, particle_diameter: float) -> None:
    """Write ``walls`` to ``path`` with the geometry config (JSON text) and particle diameter (m)."""
    with h5py.File(path, "w") as f:
        f.attrs.update(
            format=FORMAT,
            zone_names=list(walls.zone_names),
            geometry=geometry_json,
            particle_diameter=float(particle_diameter),
        )
        for name in _ARRAYS:
            f.create_dataset(name, data=getattr(walls, name))


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
        if f.attrs.get("format") != FORMAT:
            raise GeometryError(f"{path}: not a wall table (attribute format != {FORMAT!r})")
        missing = [name for name in _ARRAYS if name not in f]
        if missing or "zone_names" not in f.attrs:
            raise GeometryError(f"{path}: missing {missing or ['attribute zone_names']}")
        arrays = {name: f[name][...] for name in _ARRAYS}
        zone_names = tuple(str(z) for z in np.atleast_1d(f.attrs["zone_names"]).astype(str))
    if arrays["zone"].dtype.kind not in "iu":
        raise GeometryError(f"{path}: /zone must hold integers, found {arrays['zone'].dtype}")
    try:
        return Walls(
            *(np.asarray(arrays[name], dtype=np.float64) for name in _ARRAYS[:4]),
            zone=arrays["zone"].astype(np.int32),
            zone_names=zone_names,
        )
    except GeometryError as error:
        raise GeometryError(f"{path}: {error}") from None
