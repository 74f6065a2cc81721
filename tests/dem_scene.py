"""The tiny DEM scene the DEM tests share: a small periodic tube (8 mm, 20 mm long, 6 mm orifice,
~420 particles of 1 mm) with wall STLs made here, so the tests do not depend on the geometry stage."""

from __future__ import annotations

import copy
import functools
import json
import math
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from dpht.dem.liggghts import run_dem

needs_liggghts = pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed")

D, R_TUBE, LENGTH, Z_PLATE, R_HOLE = 1.0e-3, 4.0e-3, 0.02, 0.002, 3.0e-3
SPEC = {
    "particles": {"diameter": D, "density": 3560.0, "youngs_modulus_dem": 5.0e6, "poisson_ratio": 0.3},
    "wall": {"youngs_modulus_dem": 5.0e6, "poisson_ratio": 0.3},
    "contact": {
        "restitution": {"pp": 0.82, "pw": 0.44},
        "friction": {"pp": 0.72, "pw": 0.30},
        "rolling_friction": {"pp": 0.13, "pw": 0.50},
    },
    "geometry": {
        "tube": {
            "inner_diameter": 2 * R_TUBE,
            "length": LENGTH,
            "orifice_height": Z_PLATE,
            "orifice_diameter": 2 * R_HOLE,
            "heated": [Z_PLATE, 0.016],
        },
        "mesh_size": 1.0,
    },
    "dem": {
        "timestep": 1.0e-5,
        "fill_height": 0.008,
        "settle_time": 0.05,
        "flow_time": 0.1,
        "dump_interval": 500,
        "restart_interval": 4000,
        "seed": 32452843,
    },
}


def spec_with(**dem) -> dict:
    spec = copy.deepcopy(SPEC)
    spec["dem"].update(dem)
    return spec


def geometry_summary(spec: dict, mixers: list[dict] = ()) -> dict:
    """What the geometry stage's geometry.json says about a plain tube of ``spec`` (plus ``mixers``:
    entries as in its ``mixers`` list)."""
    summary = {
        "geometry": {"tube": spec["geometry"]["tube"], "mesh_size": spec["geometry"]["mesh_size"]},
        "zone_names": ["heated_wall", "adiabatic_wall", "orifice", *dict.fromkeys(m["zone"] for m in mixers)],
    }
    if mixers:
        summary["geometry"]["mixers"] = spec["geometry"]["mixers"]
        summary["mixers"] = list(mixers)
    return summary


GEOMETRY = geometry_summary(SPEC)


# --- wall STLs ------------------------------------------------------------------------------


def _write_stl(path: Path, triangles: np.ndarray) -> None:
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    record = np.zeros(len(triangles), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["n"], record["v"] = normal, triangles
    path.write_bytes(bytes(80) + np.uint32(len(triangles)).tobytes() + record.tobytes())


def _grid(u: np.ndarray, v: np.ndarray, point) -> np.ndarray:
    """Two triangles per cell of the (u, v) grid mapped to 3-D by ``point(u, v)``."""
    uu, vv = np.meshgrid(u, v, indexing="ij")
    p = point(uu, vv)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])


def tube_meshes(folder: Path, spec: dict = SPEC, size: float = 1.0e-3) -> Path:
    """heated/adiabatic cylinder pieces (radius R_TUBE, 0 <= z <= LENGTH), the orifice annulus (hole
    as in ``spec``) and the geometry summary, as the geometry stage writes them."""
    folder.mkdir(parents=True, exist_ok=True)
    theta = np.linspace(0.0, 2 * np.pi, math.ceil(2 * np.pi * R_TUBE / size) + 1)

    def cylinder(z0, z1):
        z = np.linspace(z0, z1, max(1, math.ceil((z1 - z0) / size)) + 1)
        return _grid(theta, z, lambda t, zz: np.stack([R_TUBE * np.cos(t), R_TUBE * np.sin(t), zz], -1))

    tube = spec["geometry"]["tube"]
    z_heat = tube["heated"]
    _write_stl(folder / "heated_wall.stl", cylinder(*z_heat))
    _write_stl(folder / "adiabatic_wall.stl", np.concatenate([cylinder(0.0, z_heat[0]), cylinder(z_heat[1], LENGTH)]))
    r = np.linspace(tube["orifice_diameter"] / 2, R_TUBE, 3)
    plate = _grid(theta, r, lambda t, rr: np.stack([rr * np.cos(t), rr * np.sin(t), np.full_like(t, Z_PLATE)], -1))
    _write_stl(folder / "orifice.stl", plate)
    (folder / "geometry.json").write_text(json.dumps(geometry_summary(spec)))
    return folder



def short_run(tmp_path_factory) -> tuple[Path, Path, dict, list[str], float]:
    """SPEC's DEM run: (root folder, meshes folder, summary, log lines, wall time s). Made once per
    test session (pytest's ``tmp_path_factory``) for the modules that read it."""
    return _short_run(tmp_path_factory.getbasetemp())


@functools.cache
def _short_run(basetemp: Path) -> tuple[Path, Path, dict, list[str], float]:
    root = basetemp / "dem_short_run"
    meshes = tube_meshes(root / "meshes")
    lines = []
    start = time.monotonic()
    summary = run_dem(SPEC, meshes, root / "work", root / "positions.h5", ranks=1, log=lines.append)
    return root, meshes, summary, lines, time.monotonic() - start
