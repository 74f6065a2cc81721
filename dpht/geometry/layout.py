"""The geometry a config describes, without gmsh: its checked parts, its wall zones, and sample points
on every zone's surfaces.

The workflow checks a config before its first job runs (``dpht.preflight``): boundary conditions
need the zone names, and wall-temperature expressions must be valid on the walls, long before gmsh
has meshed them. :func:`layout` runs every config check of the geometry stage (tube, mixers,
passages, clearances) and names the zones the stage will write; :func:`sample_walls` puts points on
the zones' surfaces analytically (the tube's cylinder segments and orifice annulus exactly, each
mixer through its ``surface_points``) as a wall table of tiny triangles, so that the thermal stage's
own functions can evaluate the boundary conditions on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dpht.geometry import checks
from dpht.geometry.build import _checked_config
from dpht.geometry.mixers import Mixer, mixers_from_config
from dpht.geometry.tube import ADIABATIC, HEATED, ORIFICE, Tube
from dpht.geometry.walls import Walls

# Sample points per cylinder segment (azimuths x heights) and on the orifice annulus (azimuths x radii),
# from a thousandth of the span inside each end (where the elements next to a cut have their centroids).
AZIMUTHS, HEIGHTS, RADII = 24, 16, 6
_SPAN = np.linspace(1e-3, 1.0 - 1e-3, HEIGHTS)
_TINY = 1e-9  # m, edge of the sample triangles: their centroids are the sample points


@dataclass(frozen=True)
class Layout:
    """The checked parts of a ``geometry`` config and the wall zones the geometry stage will write."""

    config: dict  # the geometry mapping with defaults filled in
    tube: Tube
    mixers: list[Mixer]
    zone_names: tuple[str, ...]  # in the order of the stage's wall table


def layout(geometry_cfg: dict, particle_diameter: float) -> Layout:
    """Check ``geometry_cfg`` as the geometry stage does (GeometryConfigError names the key) and
    return its parts; no gmsh."""
    checks.positive(particle_diameter, "particle_diameter (particles.diameter)")
    cfg = _checked_config(geometry_cfg)
    tube = Tube.from_config(cfg["tube"], particle_diameter, cfg["min_passage"], cfg["mesh_size"] * particle_diameter)
    mixers = mixers_from_config(cfg.get("mixers"), tube, particle_diameter, cfg["min_passage"])
    zones = [zone for zone in (HEATED, ADIABATIC) if any(z == zone for z, _ in _segments(tube))]
    zones += [ORIFICE, *(mixer.zone for mixer in mixers)]
    return Layout(cfg, tube, mixers, tuple(dict.fromkeys(zones)))


def _segments(tube: Tube) -> list[tuple[str, tuple[float, float]]]:
    """(zone, (z_bottom, z_top)) of every cylinder segment between the tube's cuts."""
    cuts = tube.cuts()
    return [(tube.segment_zone(a, b), (a, b)) for a, b in zip(cuts[:-1], cuts[1:])]


def zone_points(parts: Layout) -> dict[str, np.ndarray]:
    """Points (P, 3) m on the surfaces of every zone: the cylinder segments and the orifice annulus
    exactly, from end to end, the mixers as their ``surface_points`` give them."""
    R = parts.tube.radius
    theta = 2 * np.pi * (np.arange(AZIMUTHS) + 0.5) / AZIMUTHS
    points: dict[str, list[np.ndarray]] = {zone: [] for zone in parts.zone_names}
    for zone, (a, b) in _segments(parts.tube):
        z = a + (b - a) * _SPAN
        t, zz = np.meshgrid(theta, z)
        points[zone].append(np.column_stack([R * np.cos(t).ravel(), R * np.sin(t).ravel(), zz.ravel()]))
    r_hole = parts.tube.orifice_radius
    r = r_hole + (R - r_hole) * _SPAN[:: (HEIGHTS - 1) // (RADII - 1)]
    t, rr = np.meshgrid(theta, r)
    points[ORIFICE].append(np.column_stack([(rr * np.cos(t)).ravel(), (rr * np.sin(t)).ravel(),
                                            np.full(rr.size, parts.tube.orifice_height)]))  # fmt: skip
    for mixer in parts.mixers:
        points[mixer.zone].append(np.asarray(mixer.surface_points(), dtype=float).reshape(-1, 3))
    return {zone: np.concatenate(found) for zone, found in points.items()}


def sample_walls(parts: Layout) -> Walls:
    """A wall table of tiny triangles centred on the :func:`zone_points` of every zone."""
    found = zone_points(parts)
    centres = np.concatenate(list(found.values()))
    zone = np.repeat(np.arange(len(found), dtype=np.int32), [len(p) for p in found.values()])
    corners = _TINY * (np.eye(3) - 1.0 / 3.0)  # three corners whose mean is the origin
    return Walls.from_vertices(centres[:, None, :] + corners[None], zone, tuple(found))
