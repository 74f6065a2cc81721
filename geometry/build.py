"""The geometry stage: config -> gmsh surface mesh -> wall zones (msh, STL per zone, walls.h5, summary).

Zones are gmsh physical groups; every triangle belongs to exactly one. Triangles are re-oriented so
that their normals face the particle region (see dpht.walls_io), whatever orientation the CAD
operations left them with.
"""

from __future__ import annotations

import json
import math
import numbers
import threading
from pathlib import Path

import gmsh
import numpy as np

from dpht.errors import ConfigError, DPHTError, ExternalToolError
from dpht.walls_io import Walls, save_walls

from .export import write_summary, write_zone_stls
from .tube import ORIFICE, Tube, WallPatch

DEFAULTS = {"mesh_size": 0.5, "min_passage": 3.0}
MESH_SIZE_RANGE = (0.05, 2.0)  # element size in particle diameters
_GMSH_TRIANGLE = 2
# gmsh keeps one global model per process: builds from several threads must take turns.
_GMSH_LOCK = threading.Lock()


def _is_positive(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, numbers.Real) and math.isfinite(value) and value > 0


def _checked_config(geometry_cfg: dict) -> dict:
    """The ``geometry`` mapping with defaults filled in; scalar options checked here, the tube in Tube."""
    if not isinstance(geometry_cfg, dict):
        raise ConfigError(f"geometry must be a mapping, got {type(geometry_cfg).__name__}")
    unknown = sorted(set(geometry_cfg) - {"tube", *DEFAULTS})
    if unknown:
        raise ConfigError(f"geometry: unknown keys {unknown}; allowed: tube, {', '.join(DEFAULTS)}")
    if "tube" not in geometry_cfg:
        raise ConfigError("geometry.tube is missing")
    cfg = {**DEFAULTS, **geometry_cfg}
    for key in DEFAULTS:
        if not _is_positive(cfg[key]):
            raise ConfigError(f"geometry.{key} must be a positive number (particle diameters), got {cfg[key]!r}")
    low, high = MESH_SIZE_RANGE
    if not low <= cfg["mesh_size"] <= high:
        raise ConfigError(f"geometry.mesh_size must lie in [{low}, {high}] particle diameters, got {cfg['mesh_size']}")
    return cfg


def _triangles(patches: list[WallPatch]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Corners (M,3,3) and zone indices of the meshed patches, oriented by each patch's ``facing``."""
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(node_tags.size)
    coords = coords.reshape(-1, 3)
    zone_names = list(dict.fromkeys(p.zone for p in patches))
    corners, zones = [], []
    for patch in patches:
        for surface in patch.surfaces:
            types, _, nodes = gmsh.model.mesh.getElements(2, surface)
            if list(types) != [_GMSH_TRIANGLE]:
                raise ExternalToolError(f"gmsh gave element types {list(types)} on surface {surface}, not triangles")
            tri = coords[index[nodes[0].astype(np.int64)]].reshape(-1, 3, 3)
            normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            flip = np.einsum("ij,ij->i", normal, patch.facing(tri.mean(axis=1))) < 0
            tri[flip] = tri[flip][:, [0, 2, 1]]
            corners.append(tri)
            zones.append(np.full(len(tri), zone_names.index(patch.zone), dtype=np.int32))
    return np.concatenate(corners), np.concatenate(zones), zone_names


def _mesh(tube: Tube, element_size: float, msh_path: Path) -> Walls:
    """Build, tag and mesh the tube in a private gmsh session; write the .msh; return the wall table."""
    with _GMSH_LOCK:
        if gmsh.isInitialized():
            raise DPHTError("gmsh is already initialised in this process; geometry.build needs its own session")
        gmsh.initialize(interruptible=False)  # no signal handler: works outside the main thread
        try:
            for option, value in {
                "General.Terminal": 0,
                "General.NumThreads": 1,  # single-threaded meshing is deterministic
                "Mesh.MeshSizeMin": element_size,
                "Mesh.MeshSizeMax": element_size,
                "Mesh.MeshSizeFromCurvature": 0,
                "Mesh.MeshSizeFromPoints": 0,
            }.items():
                gmsh.option.setNumber(option, value)
            gmsh.model.add("dpht_geometry")
            patches = tube.add_to_model()
            gmsh.model.occ.synchronize()
            zones: dict[str, list[int]] = {}
            for patch in patches:
                zones.setdefault(patch.zone, []).extend(patch.surfaces)
            for name, surfaces in zones.items():
                gmsh.model.addPhysicalGroup(2, surfaces, name=name)
            gmsh.model.mesh.generate(2)
            gmsh.write(str(msh_path))
            vertices, zone, zone_names = _triangles(patches)
        except DPHTError:
            raise
        except Exception as error:  # gmsh reports every failure as a bare Exception
            raise ExternalToolError(f"gmsh failed while building the geometry: {error}") from error
        finally:
            gmsh.finalize()
    return Walls.from_vertices(vertices, zone, zone_names)


def _volume_inside(walls: Walls, z_min: float) -> float:
    """Volume (m^3) enclosed by the faceted cylinder above the cut z = z_min.

    Divergence theorem with F = (x, y, 0)/2 (div F = 1): the flat caps z = const carry no flux, so
    V = -1/2 * sum_t A_t (c_x n_x + c_y n_y) over the cylinder triangles (normals point inwards, hence
    the sign); exact for flat triangles because F is linear.
    """
    cylinder = ~walls.zone_mask(ORIFICE) & (walls.vertices[:, :, 2].min(axis=1) >= z_min)
    c, n = walls.centroid[cylinder], walls.normal[cylinder]
    return float(-0.5 * np.sum(walls.area[cylinder] * (c[:, 0] * n[:, 0] + c[:, 1] * n[:, 1])))


def build(geometry_cfg: dict, particle_diameter: float, outdir) -> dict:
    """Mesh the wall and write ``geometry.msh``, ``<zone>.stl``, ``walls.h5`` and ``geometry.json``.

    ``geometry_cfg`` is the ``geometry`` mapping of the config, ``particle_diameter`` in m. Returns
    the summary written to ``geometry.json``: element size (m), zone names, per zone the triangle
    count, faceted area and smooth-surface area (m^2) and STL file name, and the volume (m^3) above
    the orifice plate inside the faceted tube (what the DEM particles see) and inside the smooth one.
    """
    if not _is_positive(particle_diameter):
        raise ConfigError(f"particle_diameter (particles.diameter) must be positive (m), got {particle_diameter!r}")
    cfg = _checked_config(geometry_cfg)
    element_size = cfg["mesh_size"] * particle_diameter
    tube = Tube.from_config(cfg["tube"], particle_diameter, cfg["min_passage"], element_size)
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)

    walls = _mesh(tube, element_size, outdir / "geometry.msh")
    geometry_json = json.dumps(cfg, sort_keys=True)
    save_walls(outdir / "walls.h5", walls, geometry_json, particle_diameter)
    stls = write_zone_stls(outdir, walls)

    exact = tube.exact_areas()
    summary = {
        "geometry": json.loads(geometry_json),
        "particle_diameter": particle_diameter,
        "element_size": element_size,
        "zone_names": list(walls.zone_names),
        "zones": {
            name: {
                "triangles": int(walls.zone_mask(name).sum()),
                "area": float(walls.area[walls.zone_mask(name)].sum()),
                "area_exact": exact[name],
                "stl": stls[name].name,
            }
            for name in walls.zone_names
        },
        "triangles": len(walls),
        "volume_above_orifice": _volume_inside(walls, tube.orifice_height),
        "volume_above_orifice_exact": tube.volume_above_orifice(),
        "gmsh_version": gmsh.__version__,
    }
    write_summary(outdir / "geometry.json", summary)
    return summary
