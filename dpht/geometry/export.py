"""Files the geometry stage writes besides the mesh: one STL per wall zone, the JSON summary, and a
picture of the zones."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from dpht.geometry.walls import Walls, load_walls


def write_stl(path: str | Path, vertices: np.ndarray, normal: np.ndarray, name: str) -> None:
    """Write triangles (M,3,3) with unit normals (M,3) as ASCII STL.

    Coordinates are written as shortest round-trip decimals, so a corner at z = length is read back
    as exactly that double. Binary STL rounds to float32, which put the tube top 7e-10 m above the
    periodic boundary and made LIGGGHTS 3.8 warn that mesh nodes lie outside the box.
    """
    facet = "facet normal %r %r %r\n outer loop\n" + "  vertex %r %r %r\n" * 3 + " endloop\nendfacet\n"
    rows = np.hstack([normal, vertices.reshape(-1, 9)]).tolist()
    facets = [facet % tuple(row) for row in rows]
    Path(path).write_text(f"solid {name}\n" + "".join(facets) + f"endsolid {name}\n")


def write_zone_stls(outdir: Path, walls: Walls) -> dict[str, Path]:
    """One ``<zone>.stl`` per zone in ``outdir``; returns the paths by zone name."""
    paths = {}
    for name in walls.zone_names:
        mask = walls.zone_mask(name)
        paths[name] = outdir / f"{name}.stl"
        write_stl(paths[name], walls.vertices[mask], walls.normal[mask], name)
    return paths


def write_summary(path: str | Path, summary: dict) -> None:
    Path(path).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


# One colour per zone name, in the order zones appear; enough for the tube and later inserts.
_ZONE_COLOURS = ("#d1495b", "#8d99ae", "#edae49", "#00798c", "#66a182", "#30638e")


def picture(outdir: str | Path, png: str | Path, window_size=(700, 1100), focus: str | None = None) -> Path:
    """Render the wall zones in ``outdir/walls.h5`` to ``png``, off screen, coloured by zone.

    The half y > 0 of the tube is removed so the inside, the orifice plate and any mixers can be
    seen (like DPHT paper, Fig. 14). ``focus`` names a zone (e.g. ``"mixer"``) to frame: the close-up
    shows the tube between that zone's lowest and highest points.
    """
    # VTK picks its render window class when it is first imported; without EGL it segfaults here.
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    walls = load_walls(Path(outdir) / "walls.h5")
    if focus is not None:
        z = walls.vertices[walls.zone_mask(focus)][:, :, 2]  # GeometryError names a missing zone
        lo, hi = walls.vertices.reshape(-1, 3).min(axis=0), walls.vertices.reshape(-1, 3).max(axis=0)
        bounds = (lo[0], hi[0], lo[1], 0.0, z.min(), z.max())
    faces = np.hstack([np.full((len(walls), 1), 3), np.arange(3 * len(walls)).reshape(-1, 3)])
    mesh = pv.PolyData(walls.vertices.reshape(-1, 3), faces.ravel())
    mesh.cell_data["zone"] = walls.zone
    opened = mesh.clip(normal=(0.0, 1.0, 0.0), origin=(0.0, 0.0, 0.0))  # keeps y <= 0
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.set_background("white")
    for index, name in enumerate(walls.zone_names):
        cells = np.flatnonzero(opened.cell_data["zone"] == index)
        if cells.size:
            colour = _ZONE_COLOURS[index % len(_ZONE_COLOURS)]
            plotter.add_mesh(opened.extract_cells(cells), color=colour, label=name)
    plotter.add_legend(bcolor="white", size=(0.3, 0.1), loc="upper left", face="rectangle")
    # Look from the removed half (+y), slightly from above, onto the inner wall and the inserts.
    plotter.camera_position = [(0.0, 1.0, 0.5), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)]
    if focus is None:
        plotter.reset_camera()
        plotter.camera.zoom(1.3)
    else:
        plotter.enable_parallel_projection()  # no perspective taper at close range
        plotter.reset_camera(bounds=bounds)
    png = Path(png)
    plotter.screenshot(str(png))
    plotter.close()
    return png
