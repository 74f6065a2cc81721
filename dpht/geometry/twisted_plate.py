"""A twisted plate (a helical tape, the element of Kenics-type static mixers) as a closed triangle
surface, written as STL: the example insert ``geometry/twisted_plate.stl`` of the repository, which
``config/examples/twisted_plate.yaml`` places in the tube as a ``type: stl`` mixer.

Regenerate the example with ``python -m dpht.geometry.twisted_plate`` (it writes the same bytes).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from dpht.geometry.export import write_stl

# The example, in millimetres (the config reads it with scale: 0.001): a plate 7 mm wide and 0.6 mm
# thick, turned by half a turn from z = 10 mm to 22 mm, in a 9 mm tube (1 mm gap to the wall).
EXAMPLE = {"width": 7.0, "thickness": 0.6, "z0": 10.0, "z1": 22.0, "turns": 0.5}
EXAMPLE_FILE = Path("geometry") / "twisted_plate.stl"


def twisted_plate(width: float, thickness: float, z0: float, z1: float, turns: float,
                  across: int = 4, along: int = 20) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Vertices (V, 3) and outward-wound faces (F, 3) of a plate centred on the z axis, its width
    along x at z0, turned by ``turns`` revolutions about z up to z1 (lengths in any one unit).

    Each cross-section is the ``width`` x ``thickness`` rectangle rotated by 2 pi turns (z - z0) /
    (z1 - z0), its perimeter sampled at ``across`` segments per long side; ``along`` levels in z.
    The ends are closed by strips across the rectangle."""
    x = np.linspace(-0.5 * width, 0.5 * width, across + 1)
    half = 0.5 * thickness
    # The rectangle's perimeter, counter-clockwise seen from +z: bottom side left to right, top back.
    ring = np.concatenate([np.stack([x, np.full_like(x, -half)], 1), np.stack([x[::-1], np.full_like(x, half)], 1)])
    n = len(ring)
    levels = np.linspace(z0, z1, along + 1)
    angle = 2.0 * np.pi * turns * (levels - z0) / (z1 - z0)
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    vertices = np.stack([c * ring[:, 0] - s * ring[:, 1], s * ring[:, 0] + c * ring[:, 1],
                         np.repeat(levels[:, None], n, 1)], axis=2).reshape(-1, 3)  # fmt: skip
    k, j = np.meshgrid(np.arange(along), np.arange(n), indexing="ij")
    a, b = k * n + j, k * n + (j + 1) % n  # a quad between level k and k + 1 along the perimeter
    # Split the quads of both broad faces along the same diagonal in x: the facets then bulge the same
    # way on both sides of the twisted plate, and its thickness (and volume) keep their values.
    top = (j > across) & (j < n - 1)
    first = np.where(top[..., None], np.stack([a, b, a + n], -1), np.stack([a, b, b + n], -1))
    second = np.where(top[..., None], np.stack([b, b + n, a + n], -1), np.stack([a, b + n, a + n], -1))
    sides = np.concatenate([first.reshape(-1, 3), second.reshape(-1, 3)])
    lower, upper = np.arange(across), np.arange(2 * across + 1, across + 1, -1)  # bottom side i, top side across i
    cap = np.concatenate([np.stack([lower, upper, lower + 1], 1), np.stack([lower + 1, upper, upper - 1], 1)])
    faces = np.concatenate([sides, cap, cap[:, ::-1] + along * n])  # the end at z0 faces -z, at z1 faces +z
    return vertices, faces


def write(path: str | Path, vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    """Write the surface as ASCII STL (unit normals from the winding)."""
    triangles = vertices[faces]
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    write_stl(path, triangles, normal / np.linalg.norm(normal, axis=1, keepdims=True), name)


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else EXAMPLE_FILE
    write(target, *twisted_plate(**EXAMPLE), "twisted_plate")
    print(f"wrote {target}")
