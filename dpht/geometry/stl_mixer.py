"""A mixer from the user's own CAD: a closed solid given as an STL file (``type: stl``).

The file is read and checked when the config is (before gmsh and LIGGGHTS run):

* it must hold triangles (an empty or unreadable file is named), none of zero area;
* its surface must be closed: every edge shared by exactly two triangles (corners are merged where
  their coordinates are equal, as CAD exporters write them);
* triangles wound inconsistently are re-wound, and a surface whose normals all point inwards is
  turned outwards (both noted in the stage log); a surface that cannot be oriented is refused;
* it must not cross itself, nor hold one closed shell inside another (two overlapping shells
  would be meshed into walls that overlap);
* ``scale`` converts the file's units to metres (default 1: the file is in metres). The scaled
  solid must lie inside the tube (radius and periodic height); one far larger than the tube is
  probably in other units, and the message names the largest common unit that puts it inside
  the tube (``scale: 0.001`` for millimetres).

The geometry stage then builds the solid in OpenCASCADE from its triangles (one planar face each)
and meshes it like the built-in mixers, so the same triangles reach LIGGGHTS (the zone's STL) and
the thermal stage (walls.h5). The solid's passages are not measured (``geometry.min_passage`` is
not checked for it): the DEM run report shows whether particles pass.
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dpht.geometry import checks
from dpht.geometry.closed_surface import _paired_edges, orient_outward, signed_volume
from dpht.geometry.errors import GeometryConfigError, GeometryError
from dpht.geometry.tube import Tube

TYPE = "stl"
REQUIRED = ("type", "file")
OPTIONAL = ("scale", "zone", "sha256")  # sha256: the file's digest, added by the workflow's plan
UNITS = {0.001: "millimetres", 0.01: "centimetres", 0.0254: "inches"}
MAX_SAMPLES = 2000  # surface points for the checks before gmsh (triangle centroids)
_LOG = logging.getLogger(__name__)


def file_digest(path: str | Path) -> str:
    """SHA-256 of the file's bytes: the geometry stage's cache key changes when the file does."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@dataclass(frozen=True)
class StlMixer:
    """A closed, outward-oriented triangle surface in m, from ``file`` times ``scale``."""

    key: str
    zone: str
    file: str
    scale: float
    vertices: np.ndarray = field(repr=False)  # (V, 3) m
    faces: np.ndarray = field(repr=False)  # (F, 3) indices, wound outwards
    notes: tuple[str, ...] = ()

    @classmethod
    def from_config(cls, cfg: dict, key: str, zone: str, tube: Tube) -> StlMixer:
        """Read and check one ``geometry.mixers`` item of type stl; GeometryConfigError names the key."""
        checks.keys(cfg, key, REQUIRED, OPTIONAL)
        if not isinstance(cfg["file"], str) or not cfg["file"]:
            raise GeometryConfigError(f"{key}.file must be the path of an STL file, got {cfg['file']!r}")
        path = Path(cfg["file"])
        scale = checks.positive(cfg.get("scale", 1.0), f"{key}.scale", "metres per unit of the file")
        if path.is_dir():
            raise GeometryConfigError(f"{key}.file: {path} is a folder; give the STL file in it")
        if not path.is_file():
            raise GeometryConfigError(f"{key}.file: {path} does not exist (paths are relative to the working folder)")
        if "sha256" in cfg and cfg["sha256"] != file_digest(path):
            raise GeometryConfigError(f"{key}.file: {path} changed after the workflow was planned; run it again")
        triangles = _read(path, key) * scale
        vertices, corners = np.unique(triangles.reshape(-1, 3), axis=0, return_inverse=True)
        faces = corners.reshape(-1, 3)
        faces, notes = _outward(vertices, faces, f"{key}.file {path}")
        _check_no_intersections(vertices, faces, f"{key}.file {path}")
        mixer = cls(key, zone, str(path), scale, vertices, faces, tuple(notes))
        mixer._check_inside(tube)
        for note in notes:
            _LOG.info("%s: %s", key, note)
        return mixer

    def _check_inside(self, tube: Tube) -> None:
        """The solid lies in the tube; far too large means other units (the message says which scale)."""
        if _inside(self.vertices, tube):
            return
        r = np.hypot(self.vertices[:, 0], self.vertices[:, 1])
        z = self.vertices[:, 2]
        extent = float(np.ptp(self.vertices, axis=0).max())
        ratio = extent / tube.inner_diameter
        where = (f"{self.key}.file {self.file}: the solid (scale {self.scale:g}) spans {extent:.4g} m and reaches "
                 f"r = {r.max():.4g} m, z = {z.min():.4g} to {z.max():.4g} m; the tube has radius {tube.radius:.4g} m "
                 f"and z from 0 to {tube.length:.4g} m")  # fmt: skip
        if ratio > 20:
            raw = self.vertices / self.scale  # in the file's units
            fitting = [s for s in sorted(UNITS, reverse=True) if _inside(raw * s, tube)]
            fit = fitting[0] if fitting else self.scale * 10.0 ** -round(math.log10(ratio))
            hint = f"in {UNITS[fit]}" if fitting else "in other units"
            raise GeometryConfigError(
                f"{where}: it is {ratio:.0f} times the tube's inner diameter, so the file is probably {hint}: "
                f"set {self.key}.scale: {fit:g}" + ("" if fitting else " or so (no common unit puts it inside the tube)")
            )
        raise GeometryConfigError(f"{where}: a mixer must lie inside the tube (move it in the CAD model)")

    def z_range(self) -> tuple[float, float]:
        return float(self.vertices[:, 2].min()), float(self.vertices[:, 2].max())

    def passages(self) -> list[tuple[str, str, float]]:
        """Not measured for a user's solid (see the module docstring)."""
        return []

    @property
    def volume(self) -> float:
        """m^3 enclosed by the surface."""
        return signed_volume(self.vertices, self.faces)

    def surface_points(self) -> np.ndarray:
        """Centroids (P, 3) m of (at most MAX_SAMPLES of) its triangles."""
        faces = self.faces[:: max(1, len(self.faces) // MAX_SAMPLES)]
        return self.vertices[faces].mean(axis=1)

    def add_to_model(self) -> list[int]:
        """Add the solid to the gmsh OCC model (not synchronised), one planar face per triangle sewn
        into a closed shell; return its volume tags."""
        import gmsh

        occ = gmsh.model.occ
        points = [occ.addPoint(*v) for v in self.vertices.tolist()]
        lines = {}
        surfaces = []
        for face in self.faces.tolist():
            loop = []
            for a, b in ((face[0], face[1]), (face[1], face[2]), (face[2], face[0])):
                edge = (min(a, b), max(a, b))
                if edge not in lines:
                    lines[edge] = occ.addLine(points[edge[0]], points[edge[1]])
                loop.append(lines[edge])
            surfaces.append(occ.addPlaneSurface([occ.addCurveLoop(loop)]))
        return [occ.addVolume([occ.addSurfaceLoop(surfaces)])]


def _inside(vertices: np.ndarray, tube: Tube) -> bool:
    """Whether points (m) lie in the tube (radius, periodic height), to float32 precision (STL)."""
    r, z = np.hypot(vertices[:, 0], vertices[:, 1]), vertices[:, 2]
    return bool(np.all(r <= tube.radius * (1 + 1e-6)) and z.min() > 0.0 and z.max() < tube.length)


def _crossings(starts: np.ndarray, ends: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Whether each segment ``starts[k]``-``ends[k]`` crosses triangle ``triangles[k]`` (M, 3, 3)
    inside it, its ends excluded (Moeller and Trumbore 1997, on segments)."""
    direction = ends - starts
    e1, e2 = triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(direction, axis=1)
    ok = np.abs(det) > 1e-12 * scale  # not parallel to the triangle's plane
    det = np.where(ok, det, 1.0)
    t0 = starts - triangles[:, 0]
    u = np.einsum("ij,ij->i", t0, p) / det
    q = np.cross(t0, e1)
    v = np.einsum("ij,ij->i", direction, q) / det
    t = np.einsum("ij,ij->i", e2, q) / det
    eps = 1e-9
    return ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)


def _check_no_intersections(vertices: np.ndarray, faces: np.ndarray, where: str) -> None:
    """A closed surface that crosses itself (two overlapping shells, a fold) or holds one shell inside
    another encloses no single solid: gmsh would mesh it silently into walls that overlap. Refused,
    naming a crossing. Edges against the triangles near them (their bounding spheres overlap) that
    share no corner with them; then one corner of each shell against the others (ray parity)."""
    from scipy.spatial import cKDTree

    triangles = vertices[faces]
    centres = triangles.mean(axis=1)
    size = np.linalg.norm(triangles - centres[:, None], axis=2).max(axis=1)
    pairs = cKDTree(centres).query_pairs(2.0 * size.max() * (1 + 1e-9), output_type="ndarray")
    pairs = pairs[np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1) <= size[pairs[:, 0]] + size[pairs[:, 1]]]
    shared = (faces[pairs[:, 0], :, None] == faces[pairs[:, 1], None, :]).any(axis=(1, 2))
    pairs = pairs[~shared]
    for a, b in (pairs.T, pairs[:, ::-1].T):
        for k in range(3):  # edge k of triangle a against triangle b
            hit = _crossings(triangles[a, k], triangles[a, (k + 1) % 3], triangles[b])
            if hit.any():
                first = int(np.argmax(hit))
                raise GeometryConfigError(
                    f"{where}: the surface crosses itself ({int(hit.sum())} or more crossings, e.g. triangles "
                    f"{int(a[first])} and {int(b[first])} near {np.round(centres[a[first]], 6).tolist()}): two shells "
                    "overlap, or the surface folds through itself. A mixer must be one closed solid, or solids apart "
                    "(unite them in the CAD tool)"
                )
    import trimesh

    shells = trimesh.graph.connected_components(trimesh.graph.face_adjacency(faces), nodes=np.arange(len(faces)))
    if len(shells) < 2:
        return
    far = vertices.max(axis=0) + np.ptp(vertices, axis=0) + 1.0
    for k, shell in enumerate(shells):
        point = vertices[faces[shell[0], 0]]
        others = np.setdiff1d(np.arange(len(faces)), shell)
        end = far + np.array([0.123, 0.456, 0.789]) * np.ptp(vertices)  # off any symmetry of the model
        crossings = _crossings(np.repeat(point[None], len(others), 0), np.repeat(end[None], len(others), 0), triangles[others])
        if crossings.sum() % 2:
            raise GeometryConfigError(
                f"{where}: one of its {len(shells)} closed shells (triangle {int(shell[0])} on) lies inside another: "
                "a mixer must be one closed solid, or solids apart (unite them in the CAD tool)"
            )


def _read(path: Path, key: str) -> np.ndarray:
    """Triangles (M, 3, 3) of an ASCII or binary STL file, in its units."""
    import trimesh

    try:
        mesh = trimesh.load(path, file_type="stl", force="mesh", process=False)
        triangles = np.asarray(mesh.triangles, dtype=np.float64).reshape(-1, 3, 3)
    except Exception as err:  # trimesh raises many types for unreadable files
        raise GeometryConfigError(f"{key}.file: {path} cannot be read as STL: {err}") from None
    if len(triangles) == 0:
        raise GeometryConfigError(f"{key}.file: {path} holds no triangles (empty, or not an STL file)")
    if not np.all(np.isfinite(triangles)):
        raise GeometryConfigError(f"{key}.file: {path} has non-finite coordinates")
    return triangles


def _outward(vertices: np.ndarray, faces: np.ndarray, where: str) -> tuple[np.ndarray, list[str]]:
    """``faces`` closed and wound outwards, and what had to be fixed; GeometryConfigError otherwise."""
    area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)  # fmt: skip
    if np.any(area <= 0):
        raise GeometryConfigError(f"{where}: {int(np.sum(area <= 0))} of its {len(faces)} triangles have zero area")
    try:
        _, _, forward = _paired_edges(faces)
    except GeometryError as err:
        raise GeometryConfigError(f"{where}: a mixer must be a closed solid, but its {err} (corners are joined "
                                  "where their coordinates are equal: repair the mesh in the CAD tool)") from None  # fmt: skip
    notes = []
    if np.any(forward[:, 0] == forward[:, 1]):
        notes.append(f"{int(np.sum(forward[:, 0] == forward[:, 1]))} edges were traversed in the same sense by both "
                     "triangles: the triangles were re-wound consistently")  # fmt: skip
    inwards = signed_volume(vertices, faces) < 0
    try:
        faces = orient_outward(vertices, faces, np.arange(len(faces)))
    except GeometryError as err:
        raise GeometryConfigError(f"{where}: {err}") from None
    if inwards and not notes:
        notes.append("its normals pointed into the solid: they were turned outwards")
    if not signed_volume(vertices, faces) > 0:
        raise GeometryConfigError(f"{where}: the surface encloses no volume")
    return faces, notes
