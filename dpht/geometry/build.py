"""The geometry stage: config -> gmsh surface mesh -> wall zones (msh, STL per zone, walls.h5, summary).

Zones are gmsh physical groups; every triangle belongs to exactly one. Triangles are re-oriented so
that their normals face the particle region (see geometry.walls), whatever orientation the CAD
operations left them with: the tube's towards the axis, the orifice plate's upwards, and every
mixer's out of its solid.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpht.geometry.errors import GeometryConfigError, GeometryError, GmshError
from dpht.geometry.walls import Walls, save_walls

from dpht.geometry import checks
from dpht.geometry.closed_surface import orient_outward, signed_volume, smallest_angle, triangle_quality
from dpht.geometry.export import write_summary, write_zone_stls
from dpht.geometry.mixers import Mixer, mixers_from_config
from dpht.geometry.tube import ADIABATIC, HEATED, Tube, WallPatch

DEFAULTS = {"mesh_size": 0.5, "min_passage": 3.0}
MESH_SIZE_RANGE = (0.05, 2.0)  # element size in particle diameters
_GMSH_TRIANGLE = 2
# gmsh keeps one global model per process: builds from several threads must take turns.
_GMSH_LOCK = threading.Lock()


@dataclass
class _Solid:
    """One mixer in the gmsh model: its volumes, their boundary surfaces, and what was measured."""

    mixer: Mixer
    volumes: list[int]
    surfaces: list[list[int]]  # per volume
    triangles: int = 0
    mesh_volume: float = 0.0  # m^3, enclosed by the oriented triangles

    def cad_measures(self) -> tuple[float, float]:
        """Volume (m^3) and surface area (m^2) of the smooth CAD solid (OpenCASCADE)."""
        import gmsh

        volume = sum(gmsh.model.occ.getMass(3, v) for v in self.volumes)
        area = sum(gmsh.model.occ.getMass(2, s) for surfaces in self.surfaces for s in surfaces)
        return volume, area


def _checked_config(geometry_cfg: dict) -> dict:
    """The ``geometry`` mapping with defaults filled in; scalar options checked here, the parts in
    Tube and mixers_from_config. An empty ``mixers`` list is dropped, so that the summary and the
    wall table of a plain tube do not depend on whether the key is written."""
    if not isinstance(geometry_cfg, dict):
        raise GeometryConfigError(f"geometry must be a mapping, got {type(geometry_cfg).__name__}")
    unknown = sorted(set(geometry_cfg) - {"tube", "mixers", *DEFAULTS})
    if unknown:
        raise GeometryConfigError(f"geometry: unknown keys {unknown}; allowed: tube, mixers, {', '.join(DEFAULTS)}")
    if "tube" not in geometry_cfg:
        raise GeometryConfigError("geometry.tube is missing")
    cfg = {**DEFAULTS, **geometry_cfg}
    if "mixers" in cfg and cfg["mixers"] in (None, []):
        del cfg["mixers"]
    for key in DEFAULTS:
        checks.positive(cfg[key], f"geometry.{key}", "particle diameters")
    low, high = MESH_SIZE_RANGE
    if not low <= cfg["mesh_size"] <= high:
        raise GeometryConfigError(f"geometry.mesh_size must lie in [{low}, {high}] particle diameters, got {cfg['mesh_size']}")
    return cfg


def _surface_faces(surface: int, index: np.ndarray) -> np.ndarray:
    """Triangles (K,3) of one meshed gmsh surface as row indices into the node table."""
    import gmsh

    types, _, nodes = gmsh.model.mesh.getElements(2, surface)
    if list(types) != [_GMSH_TRIANGLE]:
        raise GmshError(f"gmsh gave element types {list(types)} on surface {surface}, not triangles")
    return index[nodes[0].astype(np.int64)].reshape(-1, 3)


def _solid_surfaces(volumes: list[int]) -> list[list[int]]:
    """Boundary surface tags of each volume."""
    import gmsh

    return [[abs(tag) for _, tag in gmsh.model.getBoundary([(3, v)], oriented=False)] for v in volumes]


def _solid_name(solid: _Solid, k: int) -> str:
    """Wall-surface name of volume ``k`` of a mixer: its config key, numbered if it has several solids."""
    return solid.mixer.key if len(solid.volumes) == 1 else f"{solid.mixer.key}.solid{k}"


def _triangles(patches: list[WallPatch], solids: list[_Solid]) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray, list[str]]:
    """Corners (M,3,3), zone indices, zone names, wall-surface indices and wall-surface names of the
    meshed walls: tube patches first, oriented by each patch's ``facing``, then each mixer's closed
    surface, oriented out of the solid (this also fills in the mixers' triangle counts and enclosed
    volumes). Each mixer volume is a wall surface of its own (geometry.walls)."""
    import gmsh

    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(node_tags.size)
    coords = coords.reshape(-1, 3)
    zone_names = list(dict.fromkeys([p.zone for p in patches] + [s.mixer.zone for s in solids]))
    surface_names = list(dict.fromkeys([p.wall_surface for p in patches]
                                       + [_solid_name(s, k) for s in solids for k in range(len(s.volumes))]))  # fmt: skip
    corners, zones, parts = [], [], []
    for patch in patches:
        for surface in patch.surfaces:
            tri = coords[_surface_faces(surface, index)]
            normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            flip = np.einsum("ij,ij->i", normal, patch.facing(tri.mean(axis=1))) < 0
            tri[flip] = tri[flip][:, [0, 2, 1]]
            corners.append(tri)
            zones.append(np.full(len(tri), zone_names.index(patch.zone), dtype=np.int32))
            parts.append(np.full(len(tri), surface_names.index(patch.wall_surface), dtype=np.int32))
    for solid in solids:
        for k, surfaces in enumerate(solid.surfaces):
            per_surface = [_surface_faces(s, index) for s in surfaces]
            patch_of_face = np.repeat(surfaces, [len(f) for f in per_surface])
            try:
                faces = orient_outward(coords, np.concatenate(per_surface), patch_of_face)
            except GeometryError as error:
                raise GmshError(f"{solid.mixer.key}: the meshed mixer surface is unusable: {error}") from None
            solid.triangles += len(faces)
            solid.mesh_volume += signed_volume(coords, faces)
            corners.append(coords[faces])
            zones.append(np.full(len(faces), zone_names.index(solid.mixer.zone), dtype=np.int32))
            parts.append(np.full(len(faces), surface_names.index(_solid_name(solid, k)), dtype=np.int32))
    return np.concatenate(corners), np.concatenate(zones), zone_names, np.concatenate(parts), surface_names


def _mesh(tube: Tube, mixers: list[Mixer], element_size: float, msh_path: Path) -> tuple[Walls, list[_Solid], list]:
    """Build, tag and mesh tube and mixers in a private gmsh session; write the .msh.

    Returns the wall table, the meshed mixers and their CAD (volume, area) pairs.
    """
    import gmsh

    with _GMSH_LOCK:
        if gmsh.isInitialized():
            raise GeometryError("gmsh is already initialised in this process; geometry.build needs its own session")
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
            # The tube first: its entities, hence its mesh, come out the same with or without mixers.
            patches = tube.add_to_model()
            volumes = [mixer.add_to_model() for mixer in mixers]
            gmsh.model.occ.synchronize()
            solids = []
            for mixer, tags in zip(mixers, volumes):
                if not tags:
                    raise GmshError(f"{mixer.key}: the CAD operations left no solid")
                solids.append(_Solid(mixer, tags, _solid_surfaces(tags)))
            zones: dict[str, list[int]] = {}
            for patch in patches:
                zones.setdefault(patch.zone, []).extend(patch.surfaces)
            for solid in solids:
                zones.setdefault(solid.mixer.zone, []).extend(s for surfaces in solid.surfaces for s in surfaces)
            for name, surfaces in zones.items():
                gmsh.model.addPhysicalGroup(2, surfaces, name=name)
            gmsh.model.mesh.generate(2)
            gmsh.write(str(msh_path))
            vertices, zone, zone_names, surface, surface_names = _triangles(patches, solids)
            cad = [solid.cad_measures() for solid in solids]
        except GeometryError:
            raise
        except Exception as error:  # gmsh reports every failure as a bare Exception
            raise GmshError(f"gmsh failed while building the geometry: {error}") from error
        finally:
            gmsh.finalize()
    return Walls.from_vertices(vertices, zone, zone_names, tube.primitives(), surface, surface_names), solids, cad


def _cylinder(walls: Walls) -> np.ndarray:
    """Mask of the tube's cylinder triangles (heated and adiabatic zones)."""
    return np.isin(walls.zone, [walls.zone_names.index(z) for z in (HEATED, ADIABATIC) if z in walls.zone_names])


def _volume_inside(walls: Walls, z_min: float) -> float:
    """Volume (m^3) enclosed by the faceted cylinder above the cut z = z_min.

    Divergence theorem with F = (x, y, 0)/2 (div F = 1): the flat caps z = const carry no flux, so
    V = -1/2 * sum_t A_t (c_x n_x + c_y n_y) over the cylinder triangles (normals point inwards, hence
    the sign); exact for flat triangles because F is linear.
    """
    cylinder = _cylinder(walls) & (walls.vertices[:, :, 2].min(axis=1) >= z_min)
    c, n = walls.centroid[cylinder], walls.normal[cylinder]
    return float(-0.5 * np.sum(walls.area[cylinder] * (c[:, 0] * n[:, 0] + c[:, 1] * n[:, 1])))


def _mixer_summaries(walls: Walls, n_tube: int, solids: list[_Solid], cad: list) -> list[dict]:
    """Per mixer: where it is, its passages, and its mesh against its CAD solid. The mixers'
    triangles follow the ``n_tube`` tube triangles in the wall table, in config order."""
    summaries, start = [], n_tube
    for solid, (volume_cad, area_cad) in zip(solids, cad):
        part = slice(start, start + solid.triangles)
        start = part.stop
        mixer = solid.mixer
        summaries.append({
            "key": mixer.key,
            "zone": mixer.zone,
            "z_range": list(mixer.z_range()),
            "passages": [{"key": key, "passage": what, "width": width} for key, what, width in mixer.passages()],
            "triangles": solid.triangles,
            "area": float(walls.area[part].sum()),
            "area_cad": area_cad,
            "volume": solid.mesh_volume,
            "volume_cad": volume_cad,
            "min_triangle_quality": float(triangle_quality(walls.vertices[part]).min()),
            "min_triangle_angle": float(smallest_angle(walls.vertices[part]).min()),
            "min_triangle_area": float(walls.area[part].min()),
        })
    return summaries


def build(geometry_cfg: dict, particle_diameter: float, outdir) -> dict:
    """Mesh the walls and write ``geometry.msh``, ``<zone>.stl``, ``walls.h5`` and ``geometry.json``.

    ``geometry_cfg`` is the ``geometry`` mapping of the config, ``particle_diameter`` in m. Returns
    the summary written to ``geometry.json``: element size (m), zone names, per zone the triangle
    count, faceted area and smooth-surface area (m^2), STL file name and exact surfaces (kind and
    segment r0, z0, r1, z1 in m, geometry.walls.Primitive), per wall surface (the tube, the orifice
    plate, each mixer solid) its triangle count and zones, and the volume (m^3) above
    the orifice plate inside the faceted tube (what the DEM particles see) and inside the smooth one.
    With mixers it also holds ``mixers`` (per mixer: key, zone, z range, passages, triangle count,
    mesh and CAD area and volume, smallest triangle quality, angle (degrees) and area) and
    ``volume_above_orifice_free``, the faceted tube volume above the plate minus the mixers there.
    Mixer zones' ``area_exact`` is the CAD area, including the faces welded to the tube wall.
    """
    import gmsh

    checks.positive(particle_diameter, "particle_diameter (particles.diameter)")
    cfg = _checked_config(geometry_cfg)
    element_size = cfg["mesh_size"] * particle_diameter
    tube = Tube.from_config(cfg["tube"], particle_diameter, cfg["min_passage"], element_size)
    mixers = mixers_from_config(cfg.get("mixers"), tube, particle_diameter, cfg["min_passage"])
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)

    walls, solids, cad = _mesh(tube, mixers, element_size, outdir / "geometry.msh")
    geometry_json = json.dumps(cfg, sort_keys=True)
    save_walls(outdir / "walls.h5", walls, geometry_json, particle_diameter)
    stls = write_zone_stls(outdir, walls)

    exact = tube.exact_areas()
    for solid, (_, area_cad) in zip(solids, cad):
        exact[solid.mixer.zone] = exact.get(solid.mixer.zone, 0.0) + area_cad
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
                "primitives": [{"kind": p.kind, "segment": list(p.segment)} for p in walls.primitives if p.zone == name],
            }
            for name in walls.zone_names
        },
        "surfaces": {
            name: {"triangles": int(np.sum(walls.surface == k)), "zones": sorted({walls.zone_names[z] for z in walls.zone[walls.surface == k]})}
            for k, name in enumerate(walls.surface_names)
        },
        "triangles": len(walls),
        "volume_above_orifice": _volume_inside(walls, tube.orifice_height),
        "volume_above_orifice_exact": tube.volume_above_orifice(),
        "gmsh_version": gmsh.__version__,
    }
    if mixers:
        n_tube = len(walls) - sum(solid.triangles for solid in solids)
        summary["mixers"] = _mixer_summaries(walls, n_tube, solids, cad)
        summary["volume_above_orifice_free"] = summary["volume_above_orifice"] - sum(
            solid.mesh_volume for solid in solids if solid.mixer.z_range()[0] > tube.orifice_height
        )
    write_summary(outdir / "geometry.json", summary)
    return summary
