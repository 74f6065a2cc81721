"""Exact distances from particle centres to the analytic wall surfaces the DEM collides them with.

With ``dem.tube_wall: primitive`` LIGGGHTS collides particles with an exact cylinder, not with the
gmsh triangles (whose facets sit up to 0.02 R inside it, three times the DEM's mean overlap); the
thermal stage must then measure distances to that cylinder. The surfaces are the geometry stage's
primitives (:class:`dpht.geometry.walls.Primitive`): surfaces of revolution about the tube axis
(x = y = 0, along z) swept by a segment from (r0, z0) to (r1, z1) in the half-plane (r, z) — a
cylinder piece (r0 == r1, LIGGGHTS ``zcylinder``), an annulus of the plane z = z0 (z0 == z1,
``zplane`` within r0..r1) or a cone frustum.

For a point p at distance rho from the axis, |p - q|^2 = rho^2 + r_q^2 - 2 rho r_q cos(dphi) + dz^2
is smallest at dphi = 0 for every point q of the sweep, so the closest point lies in p's own
half-plane and the distance is the 2-D distance from (rho, z) to the segment: exact, no faceting,
including beyond the ends (to the rim circle). The overlap with a particle of radius R is then
R - distance, as LIGGGHTS computes it for its primitives (tests/wall_contacts.py compares them on
a real LIGGGHTS frame).

Kernels are numba functions of plain arrays: a surface set is :class:`Surfaces` (segments and
their zone indices). Lengths in m.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from dpht.geometry.walls import Walls


class Surfaces(NamedTuple):
    """Exact wall surfaces: ``segment`` (K, 4) rows r0, z0, r1, z1 (m), ``zone`` (K,) zone index."""

    segment: np.ndarray
    zone: np.ndarray


def surfaces(walls: Walls, zones=None) -> Surfaces:
    """The primitives of ``walls`` (those of the zone names ``zones`` only, if given) as arrays."""
    chosen = [p for p in walls.primitives if zones is None or p.zone in zones]
    return Surfaces(
        np.array([p.segment for p in chosen], dtype=np.float64).reshape(-1, 4),
        np.array([walls.zone_names.index(p.zone) for p in chosen], dtype=np.int64),
    )


@njit(cache=True)
def segment_closest(rho, z, r0, z0, r1, z1):
    """Closest point (r, z) of the segment (r0, z0)-(r1, z1) to (rho, z): returns (r, z, distance)."""
    dr = r1 - r0
    dz = z1 - z0
    t = ((rho - r0) * dr + (z - z0) * dz) / (dr * dr + dz * dz)
    t = min(max(t, 0.0), 1.0)
    rq = r0 + t * dr  # exactly r0 along a cylinder (dr = 0), as LIGGGHTS' radius
    zq = z0 + t * dz
    return rq, zq, np.hypot(rho - rq, z - zq)


@njit(cache=True)
def distance(x, y, z, segment):
    """Distance (m) from the point (x, y, z) to the surface swept by ``segment`` (r0, z0, r1, z1)."""
    return segment_closest(np.hypot(x, y), z, segment[0], segment[1], segment[2], segment[3])[2]


@njit(cache=True)
def closest_point(x, y, z, segment):
    """Closest point (x, y, z) of the surface swept by ``segment`` to (x, y, z); on the axis the
    azimuth is taken as +x."""
    rho = np.hypot(x, y)
    rq, zq, _ = segment_closest(rho, z, segment[0], segment[1], segment[2], segment[3])
    if rho == 0.0:
        return rq, 0.0, zq
    return rq * x / rho, rq * y / rho, zq


def nearest(points, segment) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) from each of ``points`` (N, 3) to the nearest of the surfaces ``segment``
    (K, 4), and that surface's index; (inf, -1) without surfaces."""
    coords = np.ascontiguousarray(np.asarray(points, dtype=np.float64).T)
    best = np.empty(coords.shape[1])
    which = np.empty(coords.shape[1], dtype=np.int64)
    nearest_into(coords, np.arange(3), np.asarray(segment, dtype=np.float64).reshape(-1, 4), best, which)
    return best, which


@njit(cache=True, parallel=True)
def nearest_into(coords, where, segment, best, which):
    """Kernel of :func:`nearest` into ``best``/``which``: axis k of point i is ``coords[where[k], i]``
    (e.g. a cell list's sorted coordinates, read in order rather than gathered, as
    :func:`dpht.thermal.wall_distance.nearest_elements`). Ties go to the first segment."""
    for i in prange(coords.shape[1]):
        x, y, z = coords[where[0], i], coords[where[1], i], coords[where[2], i]
        rho = np.hypot(x, y)
        best[i] = np.inf
        which[i] = -1
        for k in range(segment.shape[0]):
            d = segment_closest(rho, z, segment[k, 0], segment[k, 1], segment[k, 2], segment[k, 3])[2]
            if d < best[i]:
                best[i] = d
                which[i] = k
