"""Monte Carlo ray tracing of radiation distribution factors (RDFs) in beds of spheres.

The RDF ``D_ij`` is the fraction of the rays emitted by particle ``i`` that are finally absorbed by
particle ``j`` (or by a wall), after any number of diffuse reflections (DPHT paper, Sections 3.6-3.7;
it enters Eqs. 25-26). Surfaces are gray and diffuse:

* emission is uniform over each sphere's surface with cosine-weighted (Lambertian) directions;
* a ray that hits a surface is absorbed with probability equal to its emissivity (Kirchhoff), and
  otherwise reflected diffusely (cosine-weighted about the surface normal);
* rays are followed until absorbed or until they leave the domain through an open boundary. A ray
  may come back to its emitter after reflections: that is self-absorption ``D_ii``.

Walls are infinite planes (:class:`PlaneWall`) or triangle meshes (:class:`MeshWall`), each with its
own emissivity (0 = perfectly reflecting). Axes marked periodic wrap around ``box``; the other axes
are open. Each ray finds its first intersection by walking a uniform grid (3D-DDA, Amanatides & Woo
1987), so it tests O(1) spheres whatever the bed size.

Randomness is counter-based: every random number is Philox4x32-10 (Salmon et al. 2011, SC'11)
applied to the counter ``(event, ray, particle, 0)`` under the key ``seed``, so a ray's path depends
only on ``(seed, particle, ray)`` and results are bit-identical for any thread count.

Python API::

    result = trace(positions, radius, emissivity, rays_per_particle,
                   walls=(PlaneWall(point, normal, emissivity), ...), box=None,
                   periodic=(False, False, False), emitters=None, seed=0)
    result.matrix   # scipy.sparse CSR (N, N): D_ij, rows of non-emitters empty
    result.walls    # (N, n_walls): fraction absorbed by each wall
    result.lost     # (N,): fraction that left through open boundaries
    result.counts, result.wall_counts, result.lost_counts   # the integer ray counts

Lengths are in metres (any consistent unit works: the tracer is scale-free).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse
from numba import njit, prange

from dpht.errors import DPHTError

# Hit kinds returned by the first-hit search.
_NONE, _SPHERE, _PLANE, _TRIANGLE = 0, 1, 2, 3
# A ray that exceeds this many surface events, or walks more than this many times the grid's
# cells along x + y + z in one flight (about as many box lengths; possible only along open
# channels of a periodic bed, where images would let it fly for ever), is counted as lost.
MAX_EVENTS = 1_000_000
MAX_BOX_CROSSINGS = 64
# Grid cell edge in largest particle diameters (0.5 to 1.4 ran equally fast within the noise here).
CELL_SIZE = 1.0
# Elements of the per-chunk (emitter x ray) outcome buffer: bounds the tracer's working memory.
_CHUNK_ELEMENTS = 1 << 22

_MASK32 = np.uint64(0xFFFFFFFF)


# --------------------------------------------------------------------------------------------
# Counter-based random numbers


@njit(cache=True)
def philox4x32(c0, c1, c2, c3, k0, k1):
    """Philox4x32-10 block (Salmon et al. 2011): four 32-bit words from a counter and a key.

    Arguments and results are 32-bit values held in uint64.
    """
    for _ in range(10):
        p0 = np.uint64(0xD2511F53) * c0
        p1 = np.uint64(0xCD9E8D57) * c2
        c0, c1, c2, c3 = (p1 >> np.uint64(32)) ^ c1 ^ k0, p1 & _MASK32, (p0 >> np.uint64(32)) ^ c3 ^ k1, p0 & _MASK32
        k0 = (k0 + np.uint64(0x9E3779B9)) & _MASK32
        k1 = (k1 + np.uint64(0xBB67AE85)) & _MASK32
    return c0, c1, c2, c3


@njit(cache=True)
def _uniforms(seed, particle, ray, event):
    """Four uniform numbers in the open interval (0, 1) for one surface event of one ray."""
    w0, w1, w2, w3 = philox4x32(
        np.uint64(event) & _MASK32,
        np.uint64(ray) & _MASK32,
        np.uint64(particle) & _MASK32,
        np.uint64(0),
        np.uint64(seed) & _MASK32,
        (np.uint64(seed) >> np.uint64(32)) & _MASK32,
    )
    scale = 2.0**-32
    return (w0 + 0.5) * scale, (w1 + 0.5) * scale, (w2 + 0.5) * scale, (w3 + 0.5) * scale


# --------------------------------------------------------------------------------------------
# Sampling


@njit(cache=True)
def _cosine_direction(nx, ny, nz, u, v):
    """Lambertian (cosine-weighted) direction about the unit normal n.

    cos(theta) = sqrt(u) > 0 strictly, so the ray always leaves the surface. The tangent basis is
    the branch-free construction of Duff et al. (2017, JCGT 6(1)).
    """
    cos_t = np.sqrt(u)
    sin_t = np.sqrt(1.0 - u)
    phi = 2.0 * np.pi * v
    a1 = sin_t * np.cos(phi)
    a2 = sin_t * np.sin(phi)
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (
        a1 * (1.0 + sign * nx * nx * a) + a2 * b + cos_t * nx,
        a1 * sign * b + a2 * (sign + ny * ny * a) + cos_t * ny,
        -a1 * sign * nx - a2 * ny + cos_t * nz,
    )


@njit(cache=True)
def _sphere_normal(u, v):
    """Uniformly distributed unit vector (a uniform point on the unit sphere)."""
    z = 2.0 * u - 1.0
    s = np.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * v
    return s * np.cos(phi), s * np.sin(phi), z


# --------------------------------------------------------------------------------------------
# Intersections (ray o + t d, |d| = 1)


@njit(cache=True)
def _hit_sphere(ox, oy, oz, dx, dy, dz, cx, cy, cz, r):
    """Distance to where the ray enters the sphere, or inf.

    Only entries from outside count: a ray leaving a sphere's surface (the emitter, or a
    reflection point) moves away from its centre (b > 0) and can never hit it again, without any
    epsilon. The root is taken in the cancellation-free form c / (sqrt(b^2 - c) - b).
    """
    ex = ox - cx
    ey = oy - cy
    ez = oz - cz
    b = dx * ex + dy * ey + dz * ez
    if b >= 0.0:
        return np.inf
    c = ex * ex + ey * ey + ez * ez - r * r
    if c <= 0.0:
        return np.inf
    disc = b * b - c
    if disc <= 0.0:
        return np.inf
    return c / (np.sqrt(disc) - b)


@njit(cache=True)
def _hit_triangle(ox, oy, oz, dx, dy, dz, tri):
    """Moller-Trumbore (1997) ray-triangle distance, or inf; ``tri`` rows: v0, e1 = v1-v0, e2 = v2-v0."""
    e1x, e1y, e1z = tri[1, 0], tri[1, 1], tri[1, 2]
    e2x, e2y, e2z = tri[2, 0], tri[2, 1], tri[2, 2]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return np.inf
    inv = 1.0 / det
    sx = ox - tri[0, 0]
    sy = oy - tri[0, 1]
    sz = oz - tri[0, 2]
    u = (sx * px + sy * py + sz * pz) * inv
    if u < 0.0 or u > 1.0:
        return np.inf
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return np.inf
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    return t if t > 0.0 else np.inf


# --------------------------------------------------------------------------------------------
# Uniform grid


@njit(cache=True)
def _cell_range(lo_coord, hi_coord, origin, size, n, periodic):
    """Unwrapped cell indices [first, last] covering [lo_coord, hi_coord] along one axis."""
    first = int(np.floor((lo_coord - origin) / size))
    last = int(np.floor((hi_coord - origin) / size))
    if not periodic:
        first = min(max(first, 0), n - 1)
        last = min(max(last, 0), n - 1)
    return first, last


@njit(cache=True)
def _bin_boxes(box_lo, box_hi, lo, cell, dims, periodic):
    """Cell lists of axis-aligned boxes (the bounds of spheres or triangles).

    Returns ``start`` (n_cells + 1), ``ids`` (n_entries) and ``image`` (n_entries, 3): an item is
    listed in every cell its box overlaps; on periodic axes the cell index wraps, and ``image``
    counts the box lengths to subtract from the item's coordinates to place it next to that cell.
    """
    n_cells = dims[0] * dims[1] * dims[2]
    counts = np.zeros(n_cells, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            start = np.zeros(n_cells + 1, np.int64)
            for c in range(n_cells):
                start[c + 1] = start[c] + counts[c]
            fill = start[:-1].copy()
            ids = np.empty(start[n_cells], np.int32)
            image = np.empty((start[n_cells], 3), np.int64)
        for item in range(box_lo.shape[0]):
            f0, l0 = _cell_range(box_lo[item, 0], box_hi[item, 0], lo[0], cell[0], dims[0], periodic[0])
            f1, l1 = _cell_range(box_lo[item, 1], box_hi[item, 1], lo[1], cell[1], dims[1], periodic[1])
            f2, l2 = _cell_range(box_lo[item, 2], box_hi[item, 2], lo[2], cell[2], dims[2], periodic[2])
            for i in range(f0, l0 + 1):
                for j in range(f1, l1 + 1):
                    for k in range(f2, l2 + 1):
                        c = ((i % dims[0]) * dims[1] + j % dims[1]) * dims[2] + k % dims[2]
                        if pass_ == 0:
                            counts[c] += 1
                        else:
                            e = fill[c]
                            fill[c] += 1
                            ids[e] = item
                            image[e, 0] = i // dims[0]
                            image[e, 1] = j // dims[1]
                            image[e, 2] = k // dims[2]
    return start, ids, image


# --------------------------------------------------------------------------------------------
# First hit along a ray


@njit(cache=True)
def _axis_walk(x, d, lo, cell, n):
    """DDA set-up along one axis for a ray at coordinate ``x`` (at distance 0 along the ray):
    (cell index, step, distance to the next cell face, distance between faces)."""
    idx = min(max(int(np.floor((x - lo) / cell)), 0), n - 1)
    if d > 0.0:
        return idx, 1, (lo + (idx + 1) * cell - x) / d, cell / d
    if d < 0.0:
        return idx, -1, (lo + idx * cell - x) / d, -cell / d
    return idx, 0, np.inf, np.inf


@njit(cache=True)
def _first_hit(ox, oy, oz, dx, dy, dz, skip_plane, skip_triangle, scene):
    """First surface along the ray ``o + t d`` (|d| = 1).

    Returns ``(kind, index, t, ox, oy, oz, cx, cy, cz)``: ``kind`` is ``_NONE`` if the ray leaves
    the domain; ``o`` is the origin wrapped along periodic axes into the frame of the hit; for a
    sphere hit ``c`` is the centre of the image that was hit, in that frame.
    """
    (lo, cell, dims, periodic, length, sph_start, sph_data, sph_ids,
     tri_start, tri_ids, tri_geom, tri_normal, plane_point, plane_normal) = scene  # fmt: skip

    # Planes are infinite: test them all analytically. Their normals are perpendicular to the
    # periodic axes, so wrapping the origin does not change their distances.
    best_t = np.inf
    kind = _NONE
    index = -1
    for p in range(plane_point.shape[0]):
        denom = dx * plane_normal[p, 0] + dy * plane_normal[p, 1] + dz * plane_normal[p, 2]
        if p == skip_plane or denom == 0.0:
            continue
        t = (
            (plane_point[p, 0] - ox) * plane_normal[p, 0]
            + (plane_point[p, 1] - oy) * plane_normal[p, 1]
            + (plane_point[p, 2] - oz) * plane_normal[p, 2]
        ) / denom
        if 0.0 < t < best_t:
            best_t, kind, index = t, _PLANE, p

    # Wrap the origin into the box on periodic axes; clip the ray to the grid on open axes.
    if periodic[0]:
        ox -= np.floor((ox - lo[0]) / length[0]) * length[0]
    if periodic[1]:
        oy -= np.floor((oy - lo[1]) / length[1]) * length[1]
    if periodic[2]:
        oz -= np.floor((oz - lo[2]) / length[2]) * length[2]
    t_in = 0.0
    t_out = np.inf
    for a in range(3):
        if periodic[a]:
            continue
        x = ox if a == 0 else (oy if a == 1 else oz)
        da = dx if a == 0 else (dy if a == 1 else dz)
        hi = lo[a] + dims[a] * cell[a]
        if da != 0.0:
            t0 = (lo[a] - x) / da
            t1 = (hi - x) / da
            t_in = max(t_in, min(t0, t1))
            t_out = min(t_out, max(t0, t1))
        elif x < lo[a] or x > hi:
            t_out = -1.0
    cx = cy = cz = 0.0  # centre of the best sphere candidate, in the current frame
    if t_in > t_out or t_in >= best_t:
        return kind, index, best_t, ox, oy, oz, cx, cy, cz

    i0, s0, m0, e0 = _axis_walk(ox + t_in * dx, dx, lo[0], cell[0], dims[0])
    i1, s1, m1, e1 = _axis_walk(oy + t_in * dy, dy, lo[1], cell[1], dims[1])
    i2, s2, m2, e2 = _axis_walk(oz + t_in * dz, dz, lo[2], cell[2], dims[2])
    m0 += t_in
    m1 += t_in
    m2 += t_in
    for _ in range(MAX_BOX_CROSSINGS * (dims[0] + dims[1] + dims[2])):
        c = (i0 * dims[1] + i1) * dims[2] + i2
        for e in range(sph_start[c], sph_start[c + 1]):
            t = _hit_sphere(ox, oy, oz, dx, dy, dz, sph_data[e, 0], sph_data[e, 1], sph_data[e, 2], sph_data[e, 3])
            if t < best_t:
                best_t, kind, index = t, _SPHERE, sph_ids[e]
                cx, cy, cz = sph_data[e, 0], sph_data[e, 1], sph_data[e, 2]
        for e in range(tri_start[c], tri_start[c + 1]):
            tr = tri_ids[e]
            if tr != skip_triangle:
                t = _hit_triangle(ox, oy, oz, dx, dy, dz, tri_geom[tr])
                if t < best_t:
                    best_t, kind, index = t, _TRIANGLE, tr
        # A candidate inside the current cell cannot be beaten by anything further on.
        t_next = min(m0, m1, m2)
        if best_t <= t_next or t_next >= t_out:
            return kind, index, best_t, ox, oy, oz, cx, cy, cz
        # Step into the next cell; across a periodic face, shift the frame by one box length.
        if m0 == t_next:
            i0 += s0
            m0 += e0
            if i0 < 0 or i0 >= dims[0]:
                if not periodic[0]:
                    break
                i0 -= s0 * dims[0]
                ox -= s0 * length[0]
                cx -= s0 * length[0]
        elif m1 == t_next:
            i1 += s1
            m1 += e1
            if i1 < 0 or i1 >= dims[1]:
                if not periodic[1]:
                    break
                i1 -= s1 * dims[1]
                oy -= s1 * length[1]
                cy -= s1 * length[1]
        else:
            i2 += s2
            m2 += e2
            if i2 < 0 or i2 >= dims[2]:
                if not periodic[2]:
                    break
                i2 -= s2 * dims[2]
                oz -= s2 * length[2]
                cz -= s2 * length[2]
    else:
        return _NONE, -1, np.inf, ox, oy, oz, cx, cy, cz
    return kind, index, best_t, ox, oy, oz, cx, cy, cz


# --------------------------------------------------------------------------------------------
# Ray histories


@njit(cache=True)
def _trace_ray(i, ray, seed, centres, radii, particle_eps, wall_eps, plane_wall, tri_wall, scene):
    """Follow one ray emitted by particle ``i``; return the absorbing particle's index, or
    ``N + w`` for wall ``w``, or ``N + n_walls`` if the ray left the domain."""
    n = centres.shape[0]
    plane_normal = scene[13]
    tri_normal = scene[11]
    lost = n + wall_eps.shape[0]
    u0, u1, u2, u3 = _uniforms(seed, i, ray, 0)
    nx, ny, nz = _sphere_normal(u0, u1)
    r = radii[i]
    ox = centres[i, 0] + r * nx
    oy = centres[i, 1] + r * ny
    oz = centres[i, 2] + r * nz
    dx, dy, dz = _cosine_direction(nx, ny, nz, u2, u3)
    skip_plane = -1
    skip_triangle = -1
    for event in range(1, MAX_EVENTS + 1):
        kind, j, t, ox, oy, oz, cx, cy, cz = _first_hit(ox, oy, oz, dx, dy, dz, skip_plane, skip_triangle, scene)
        if kind == _NONE:
            return lost
        u0, u1, u2, u3 = _uniforms(seed, i, ray, event)
        ox += t * dx
        oy += t * dy
        oz += t * dz
        skip_plane = -1
        skip_triangle = -1
        if kind == _SPHERE:
            if u0 < particle_eps[j]:
                return j
            inv_r = 1.0 / radii[j]
            nx, ny, nz = (ox - cx) * inv_r, (oy - cy) * inv_r, (oz - cz) * inv_r
        else:
            if kind == _PLANE:
                w = plane_wall[j]
                nx, ny, nz = plane_normal[j, 0], plane_normal[j, 1], plane_normal[j, 2]
                skip_plane = j
            else:
                w = tri_wall[j]
                nx, ny, nz = tri_normal[j, 0], tri_normal[j, 1], tri_normal[j, 2]
                skip_triangle = j
            if u0 < wall_eps[w]:
                return n + w
            if nx * dx + ny * dy + nz * dz > 0.0:  # reflect to the side the ray came from
                nx, ny, nz = -nx, -ny, -nz
        dx, dy, dz = _cosine_direction(nx, ny, nz, u1, u2)
    return lost


@njit(cache=True, parallel=True)
def _trace_chunk(emitters, rays, seed, centres, radii, particle_eps, wall_eps, plane_wall, tri_wall, scene):
    """Outcome code of every ray of every emitter in ``emitters``: array (len(emitters), rays)."""
    out = np.empty((emitters.shape[0], rays), np.int32)
    for k in prange(emitters.shape[0]):
        for ray in range(rays):
            out[k, ray] = _trace_ray(
                emitters[k], ray, seed, centres, radii, particle_eps, wall_eps, plane_wall, tri_wall, scene
            )
    return out


def _tally(outcomes):
    """Run-length count each emitter's outcome codes: returns (row, code, count) arrays."""
    outcomes.sort(axis=1)
    flat = outcomes.ravel()
    change = np.ones(flat.size, bool)
    change[1:] = flat[1:] != flat[:-1]
    change[:: outcomes.shape[1]] = True  # a new emitter starts a new run
    start = np.flatnonzero(change)
    return start // outcomes.shape[1], flat[start], np.diff(np.append(start, flat.size))


# --------------------------------------------------------------------------------------------
# Python API


@dataclass(frozen=True)
class PlaneWall:
    """An infinite plane through ``point`` with normal ``normal`` (either side may face the bed)."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    emissivity: float


@dataclass(frozen=True)
class MeshWall:
    """A triangle mesh: ``vertices`` (V, 3) in m and ``faces`` (F, 3) vertex indices; both sides
    of every triangle are surfaces with the same emissivity."""

    vertices: np.ndarray
    faces: np.ndarray
    emissivity: float

    @classmethod
    def from_file(cls, path: str | Path, emissivity: float, scale: float = 1.0) -> "MeshWall":
        """Read any mesh format trimesh reads (STL, OBJ, PLY...); ``scale`` converts to metres."""
        import trimesh

        path = Path(path)
        if not path.is_file():
            raise DPHTError(f"wall mesh file {path} does not exist")
        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception as err:  # trimesh raises many types for unreadable files
            raise DPHTError(f"wall mesh file {path} could not be read: {err}") from None
        if len(mesh.faces) == 0:
            raise DPHTError(f"wall mesh file {path} has no triangles")
        return cls(np.asarray(mesh.vertices, float) * scale, np.asarray(mesh.faces, np.int64), emissivity)


@dataclass(frozen=True)
class RDFResult:
    """Ray counts from :func:`trace`. Fractions are counts / ``rays``; for every emitter
    ``counts`` row sum + ``wall_counts`` row sum + ``lost_counts`` = ``rays`` exactly."""

    counts: scipy.sparse.csr_matrix  # (N, N) int64: rays of emitter i absorbed by particle j
    wall_counts: np.ndarray  # (N, n_walls) int64
    lost_counts: np.ndarray  # (N,) int64: see ``lost``
    rays: int  # rays emitted per emitter
    emitters: np.ndarray = field(repr=False)  # indices of the particles that emitted

    @property
    def matrix(self) -> scipy.sparse.csr_matrix:
        """RDF D_ij (DPHT paper, Eq. 25), diagonal = self-absorption; rows of non-emitters are 0."""
        return (self.counts / self.rays).tocsr()

    @property
    def walls(self) -> np.ndarray:
        """RDF particle -> wall D_iw (DPHT paper, Eq. 26), one column per wall."""
        return self.wall_counts / self.rays

    @property
    def lost(self) -> np.ndarray:
        """Fraction of the emitted rays that left through an open boundary (or, in a periodic
        bed, flew more than ``MAX_BOX_CROSSINGS`` box lengths along an open channel)."""
        return self.lost_counts / self.rays


def _per_particle(value, n, name, high):
    """A number or N numbers in (0, high], as an (N,) array."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise DPHTError(f"{name}: expected a number or {n} values, got shape {arr.shape}")
    bad = ~(np.isfinite(arr) & (arr > 0.0) & (arr <= high))
    if np.any(bad):
        raise DPHTError(f"{name} must lie in (0, {high:g}]; got {arr[bad][0]!r}")
    return arr


def check_emissivity(name, value, allow_zero):
    """Raise DPHTError unless ``value`` lies in (0, 1], or in [0, 1] if ``allow_zero``."""
    if not (np.isfinite(value) and (value >= 0.0 if allow_zero else value > 0.0) and value <= 1.0):
        raise DPHTError(f"{name} must lie in {'[0' if allow_zero else '(0'}, 1]; got {value!r}")


def _grid(centres, radii, vertices, box, periodic):
    """Grid origin, cell sizes and dimensions: cells about one particle diameter wide."""
    target = CELL_SIZE * 2.0 * radii.max()
    lo = np.empty(3)
    extent = np.empty(3)
    for a in range(3):
        if periodic[a]:
            lo[a], extent[a] = box[0, a], box[1, a] - box[0, a]
        else:
            low = [np.min(centres[:, a] - radii)]
            high = [np.max(centres[:, a] + radii)]
            if vertices.size:
                low.append(vertices[:, a].min())
                high.append(vertices[:, a].max())
            pad = 1e-9 * (max(high) - min(low) + target)
            lo[a], extent[a] = min(low) - pad, max(high) - min(low) + 2 * pad
    # Keep the cell arrays to a few tens of MB, even for a small bed inside a large mesh.
    max_cells = 1 << 22
    target = max(target, (np.prod(extent) / max_cells) ** (1 / 3))
    dims = np.maximum(1, np.floor(extent / target)).astype(np.int64)
    for a in np.flatnonzero(periodic):
        if extent[a] < 3 * 2.0 * radii.max():
            raise DPHTError(
                f"box: periodic length along axis {'xyz'[a]} is {extent[a]:g}, less than 3 particle "
                f"diameters ({6 * radii.max():g})"
            )
        dims[a] = max(dims[a], 3)
    while np.prod(dims) > max_cells:
        dims = np.maximum(np.where(periodic, 3, 1), dims // 2)
    return lo, extent / dims, dims


def _scene(positions, radius, walls, box, periodic):
    """Validate the geometry and build the arrays the kernels use."""
    centres = np.array(positions, dtype=float, copy=True)
    if centres.ndim != 2 or centres.shape[1] != 3 or centres.shape[0] == 0:
        raise DPHTError(f"positions: expected an (N, 3) array with N >= 1, got shape {centres.shape}")
    if not np.all(np.isfinite(centres)):
        raise DPHTError("positions contain NaN or infinite values")
    n = centres.shape[0]
    radii = _per_particle(radius, n, "radius", np.inf)
    periodic = np.array(periodic, dtype=bool)
    if periodic.shape != (3,):
        raise DPHTError(f"periodic: expected three booleans (x, y, z), got {periodic.tolist()}")
    if box is None:
        if periodic.any():
            raise DPHTError("box is required when an axis is periodic")
        box = np.array([np.zeros(3), np.ones(3)])  # unused: no axis wraps
    box = np.asarray(box, dtype=float)
    if box.shape != (2, 3) or not np.all(np.isfinite(box)) or np.any(box[1] <= box[0]):
        raise DPHTError(f"box: expected [[xlo, ylo, zlo], [xhi, yhi, zhi]] with hi > lo, got {box.tolist()}")
    length = box[1] - box[0]
    for a in np.flatnonzero(periodic):  # wrap centres into the box
        centres[:, a] = box[0, a] + np.mod(centres[:, a] - box[0, a], length[a])

    wall_eps, plane_point, plane_normal, plane_wall = [], [], [], []
    tri_vertices, tri_wall = [], []
    for w, wall in enumerate(walls):
        check_emissivity(f"walls[{w}].emissivity", wall.emissivity, allow_zero=True)
        wall_eps.append(float(wall.emissivity))
        if isinstance(wall, PlaneWall):
            normal = np.asarray(wall.normal, dtype=float)
            point = np.asarray(wall.point, dtype=float)
            norm = np.linalg.norm(normal)
            if normal.shape != (3,) or point.shape != (3,) or not np.isfinite(norm) or norm == 0.0:
                raise DPHTError(f"walls[{w}]: a plane needs a 3-vector point and a non-zero 3-vector normal")
            normal = normal / norm
            if np.any(np.abs(normal[periodic]) > 1e-12):
                raise DPHTError(f"walls[{w}]: a plane normal must be perpendicular to the periodic axes")
            plane_point.append(point)
            plane_normal.append(normal)
            plane_wall.append(w)
        elif isinstance(wall, MeshWall):
            vertices = np.asarray(wall.vertices, dtype=float)
            faces = np.asarray(wall.faces)
            if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
                raise DPHTError(f"walls[{w}]: mesh vertices and faces must be (V, 3) and (F, 3) arrays")
            if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
                raise DPHTError(f"walls[{w}]: mesh face indices out of range")
            tri = vertices[faces]
            tol = 1e-9 * length[periodic]
            inside = (tri[..., periodic] >= box[0, periodic] - tol) & (tri[..., periodic] <= box[1, periodic] + tol)
            if not np.all(inside):
                raise DPHTError(f"walls[{w}]: mesh extends outside the box along a periodic axis")
            tri_vertices.append(tri)
            tri_wall.append(np.full(len(tri), w, np.int32))
        else:
            raise DPHTError(f"walls[{w}]: expected a PlaneWall or a MeshWall, got {type(wall).__name__}")

    tri = np.concatenate(tri_vertices) if tri_vertices else np.zeros((0, 3, 3))
    tri_wall = np.concatenate(tri_wall) if tri_wall else np.zeros(0, np.int32)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(normal, axis=1)
    keep = area2 > 0.0  # degenerate triangles cannot be hit
    tri, tri_wall, normal = tri[keep], tri_wall[keep], normal[keep] / area2[keep, None]
    tri_geom = np.ascontiguousarray(np.stack([tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=1))

    lo, cell, dims = _grid(centres, radii, tri.reshape(-1, 3), box, periodic)
    # Spheres are stored per cell with the coordinates of the image next to that cell.
    sph_start, sph_ids, image = _bin_boxes(centres - radii[:, None], centres + radii[:, None], lo, cell, dims, periodic)
    sph_data = np.column_stack([centres[sph_ids] - image * length, radii[sph_ids]])
    tri_start, tri_ids, _ = _bin_boxes(tri.min(axis=1), tri.max(axis=1), lo, cell, dims, np.zeros(3, bool))
    scene = (
        lo, cell, dims, periodic, length, sph_start, sph_data, sph_ids, tri_start, tri_ids, tri_geom,
        np.ascontiguousarray(normal),
        np.array(plane_point, dtype=float).reshape(-1, 3),
        np.array(plane_normal, dtype=float).reshape(-1, 3),
    )  # fmt: skip
    return centres, radii, np.array(wall_eps, dtype=float), np.array(plane_wall, np.int32), tri_wall, scene


def trace(
    positions,
    radius,
    emissivity,
    rays_per_particle: int,
    *,
    walls=(),
    box=None,
    periodic=(False, False, False),
    emitters=None,
    seed: int = 0,
    progress=None,
) -> RDFResult:
    """Trace ``rays_per_particle`` rays from each emitter and count where they are absorbed.

    positions: (N, 3) sphere centres, m. radius: sphere radius (m), a number or N values.
    emissivity: particle emissivity in (0, 1], a number or N values. walls: PlaneWall and MeshWall
    objects (one RDF column each). box: [[xlo, ylo, zlo], [xhi, yhi, zhi]], m, required if an axis
    is periodic; it matters only on periodic axes (centres are wrapped into it; mesh walls must lie
    inside it, plane normals must be perpendicular to those axes). emitters: indices of the
    particles that emit (default all). seed: 0 <= seed < 2**64. progress: called as
    ``progress(done, total)`` with emitter counts. Uses numba's current thread count; the result
    does not depend on it.
    """
    centres, radii, wall_eps, plane_wall, tri_wall, scene = _scene(positions, radius, walls, box, periodic)
    n = centres.shape[0]
    particle_eps = _per_particle(emissivity, n, "emissivity", 1.0)
    if int(rays_per_particle) != rays_per_particle or rays_per_particle < 1:
        raise DPHTError(f"rays_per_particle must be a positive integer; got {rays_per_particle!r}")
    rays = int(rays_per_particle)
    if int(seed) != seed or not 0 <= seed < 2**64:
        raise DPHTError(f"seed must be an integer in [0, 2**64); got {seed!r}")
    emitters = np.arange(n) if emitters is None else np.asarray(emitters)
    if emitters.ndim != 1 or emitters.dtype.kind not in "iu":
        raise DPHTError("emitters: expected a 1-D array of particle indices")
    if emitters.size and (emitters.min() < 0 or emitters.max() >= n):
        raise DPHTError(f"emitters: indices must lie in [0, {n})")
    if np.unique(emitters).size != emitters.size:
        raise DPHTError("emitters: indices must be distinct")
    emitters = emitters.astype(np.int64)

    n_walls = wall_eps.size
    rows, cols, vals = [], [], []
    wall_counts = np.zeros((n, n_walls), np.int64)
    lost_counts = np.zeros(n, np.int64)
    chunk = max(1, _CHUNK_ELEMENTS // rays)
    seed = np.uint64(seed)
    for first in range(0, emitters.size, chunk):
        block = emitters[first : first + chunk]
        outcomes = _trace_chunk(block, rays, seed, centres, radii, particle_eps, wall_eps, plane_wall, tri_wall, scene)
        local, codes, counts = _tally(outcomes)
        row = block[local]
        is_particle = codes < n
        rows.append(row[is_particle])
        cols.append(codes[is_particle])
        vals.append(counts[is_particle])
        is_wall = (codes >= n) & (codes < n + n_walls)
        wall_counts[row[is_wall], codes[is_wall] - n] = counts[is_wall]
        is_lost = codes == n + n_walls
        lost_counts[row[is_lost]] = counts[is_lost]
        if progress is not None:
            progress(min(first + chunk, emitters.size), emitters.size)
    def joined(parts):
        return np.concatenate(parts) if parts else np.zeros(0, np.int64)

    matrix = scipy.sparse.csr_matrix((joined(vals), (joined(rows), joined(cols))), shape=(n, n), dtype=np.int64)
    return RDFResult(matrix, wall_counts, lost_counts, rays, emitters)
