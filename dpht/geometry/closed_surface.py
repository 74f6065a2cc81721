"""Closed triangle surfaces (the boundaries of the mixer solids): outward orientation, enclosed
volume, triangle quality and smallest angle. Pure numpy; no gmsh.

gmsh winds the triangles of each CAD face consistently, but after OpenCASCADE booleans the faces of
one solid disagree with each other (and with the signs ``getBoundary(oriented=True)`` reports), so
the orientation is rebuilt from the mesh itself: two faces sharing an edge must traverse it in
opposite senses, and the enclosed volume must come out positive.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from dpht.geometry.errors import GeometryError


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per directed edge (3M): undirected key, whether it runs low -> high node, and its face."""
    start = faces.ravel()
    end = faces[:, [1, 2, 0]].ravel()
    low, high = np.minimum(start, end), np.maximum(start, end)
    key = low.astype(np.int64) * (int(faces.max()) + 1) + high
    return key, start < end, np.repeat(np.arange(len(faces)), 3)


def _paired_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The two uses of every edge, (E, 2) each: faces and directions; GeometryError if not closed."""
    key, forward, face = _edges(faces)
    order = np.argsort(key, kind="stable")
    key, forward, face = key[order], forward[order], face[order]
    _, counts = np.unique(key, return_counts=True)
    if np.any(counts != 2):
        raise GeometryError(
            f"surface is not closed: {int(np.sum(counts == 1))} edges are used by one triangle and "
            f"{int(np.sum(counts > 2))} by more than two"
        )
    return key.reshape(-1, 2), face.reshape(-1, 2), forward.reshape(-1, 2)


def signed_volume(points: np.ndarray, faces: np.ndarray) -> float:
    """Volume (m^3) enclosed by a closed, consistently wound surface; > 0 when normals point out.

    Divergence theorem with F = x/3: V = sum over triangles of a . (b x c) / 6, exact for flat facets.
    """
    a, b, c = (points[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def orient_outward(points: np.ndarray, faces: np.ndarray, patch: np.ndarray) -> np.ndarray:
    """Re-wind ``faces`` (M,3 node indices into ``points``) so every closed body has outward normals.

    ``patch`` (M,) labels groups of faces already wound consistently among themselves (one label
    per CAD face); only whole patches are flipped. Raises GeometryError when the surface is not closed
    or cannot be oriented (an edge used twice in the same sense inside one patch, or a Moebius-like
    contradiction between patches).
    """
    faces = np.array(faces, dtype=np.int64)
    _, pair_face, pair_forward = _paired_edges(faces)
    patch = np.asarray(patch)
    labels, patch = np.unique(patch, return_inverse=True)
    p0, p1 = patch[pair_face[:, 0]], patch[pair_face[:, 1]]
    same_sense = pair_forward[:, 0] == pair_forward[:, 1]
    if np.any(same_sense & (p0 == p1)):
        raise GeometryError("surface cannot be oriented: a patch traverses one of its edges twice in the same sense")
    # Two patches meeting along an edge must be flipped differently exactly when they traverse it
    # in the same sense.
    links = np.unique(np.column_stack([p0, p1, same_sense])[p0 != p1], axis=0)
    neighbours: list[list[tuple[int, bool]]] = [[] for _ in labels]
    for a, b, differ in links.tolist():
        neighbours[a].append((b, bool(differ)))
        neighbours[b].append((a, bool(differ)))
    flip = np.full(len(labels), -1, dtype=np.int8)
    body = np.full(len(labels), -1, dtype=np.int64)
    for seed in range(len(labels)):
        if flip[seed] >= 0:
            continue
        flip[seed], body[seed] = 0, seed
        queue = deque([seed])
        while queue:
            a = queue.popleft()
            for b, differ in neighbours[a]:
                wanted = flip[a] ^ differ
                if flip[b] < 0:
                    flip[b], body[b] = wanted, seed
                    queue.append(b)
                elif flip[b] != wanted:
                    raise GeometryError("surface cannot be oriented consistently (non-orientable patch graph)")
    flipped = flip[patch].astype(bool)
    faces[flipped] = faces[flipped][:, ::-1]
    for seed in np.unique(body):
        members = body[patch] == seed
        if signed_volume(points, faces[members]) < 0:
            faces[members] = faces[members][:, ::-1]
    return faces


def is_closed_and_consistent(faces: np.ndarray) -> bool:
    """Every edge is shared by exactly two triangles that traverse it in opposite senses."""
    try:
        _, _, forward = _paired_edges(np.asarray(faces, dtype=np.int64))
    except GeometryError:
        return False
    return bool(np.all(forward[:, 0] != forward[:, 1]))


def triangle_quality(vertices: np.ndarray) -> np.ndarray:
    """Shape quality 4 sqrt(3) A / (a^2 + b^2 + c^2) of triangles (M,3,3): 1 equilateral, 0 degenerate."""
    edges = vertices[:, [1, 2, 0]] - vertices
    twice_area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    return 2.0 * np.sqrt(3.0) * twice_area / np.einsum("ijk,ijk->i", edges, edges)


def smallest_angle(vertices: np.ndarray) -> np.ndarray:
    """Smallest interior angle (degrees) of triangles (M,3,3); LIGGGHTS warns below 0.5 and stops
    below 0.018 degrees when it reads a mesh."""
    edges = vertices[:, [1, 2, 0]] - vertices  # edge i runs from corner i to corner i+1
    length = np.linalg.norm(edges, axis=2)
    # The angle at corner i lies between edge i and the reversed edge i-1.
    cosine = -np.einsum("ijk,ijk->ij", edges, np.roll(edges, 1, axis=1)) / (length * np.roll(length, 1, axis=1))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).min(axis=1)
