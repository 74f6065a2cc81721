"""Verification of the geometry stage (geometry/): faceted tube and mixer meshes against closed forms.

The scene is the DPHT paper's Section 6 tube (9 mm, 0.3712 mm particles) with a flat plate, a
radial mixer and a plain funnel with an annular gap, meshed coarsely (element = 1 particle
diameter) so the errors are well above round-off. Faceting bounds used throughout: a triangle whose
corners lie on a cylinder or cone of radius r and whose edges are at most h long spans an azimuth
of at most theta = 2 asin(h / 2r); it then lies between radii r cos(theta/2) and r, and its area
falls short of the smooth surface's by O(theta^2) (theta^2/12 as in the tube's test).
"""

from __future__ import annotations

import functools
import math
import tempfile

import numpy as np

from dpht.verification.harness import case
from dpht.geometry.walls import Walls, load_walls

D_PAPER = 0.3712e-3  # m, Sauter mean diameter of the paper's particles (Section 6)
TUBE = {
    "inner_diameter": 9.0e-3,
    "length": 0.026,
    "orifice_height": 0.004,
    "orifice_diameter": 6.0e-3,
    "heated": [0.004, 0.026],
}
PLATE = {"type": "flat_plate", "height": 0.010, "thickness": 0.5e-3, "opening": 0.3, "orientation": 30.0,
         "zone": "plate"}
RADIAL = {"type": "radial", "height": 0.016, "outlet_diameter": 3.0e-3, "angle": 50.0, "wall_thickness": 0.25e-3,
          "n_tubes": 4, "tube_diameter": 1.2e-3, "inclination": 60.0, "tube_inlet_radius": 2.2e-3,
          "orientation": 10.0, "zone": "radial"}
FUNNEL = {"type": "radial", "height": 0.022, "inlet_diameter": 6.6e-3, "outlet_diameter": 3.0e-3, "angle": 50.0,
          "wall_thickness": 0.25e-3, "n_tubes": 0, "zone": "funnel"}
SCENE = {"tube": TUBE, "mixers": [PLATE, RADIAL, FUNNEL], "mesh_size": 1.0}
R = 0.5 * TUBE["inner_diameter"]


@functools.cache
def scene() -> tuple[dict, Walls]:
    """Summary and wall table of SCENE, built once per process in a temporary folder."""
    from dpht.geometry import build  #the geometry stage is a sibling package; import only when used

    with tempfile.TemporaryDirectory() as outdir:
        summary = build(SCENE, D_PAPER, outdir)
        return summary, load_walls(f"{outdir}/walls.h5")


def max_edge(vertices: np.ndarray) -> float:
    """Longest edge (m) of triangles (M,3,3)."""
    return float(np.linalg.norm(vertices - np.roll(vertices, 1, axis=1), axis=2).max())


def span(h: float, radius: float) -> float:
    """Largest azimuth (rad) a chord of length h can subtend on a circle of ``radius``."""
    return 2.0 * math.asin(min(1.0, h / (2.0 * radius)))


def clearance(walls: Walls, points: np.ndarray) -> np.ndarray:
    """Distance (m) from each point to the nearest wall triangle of any zone."""
    import trimesh

    corners, faces = np.unique(walls.vertices.reshape(-1, 3), axis=0, return_inverse=True)
    mesh = trimesh.Trimesh(corners, faces.reshape(-1, 3), process=False)
    return trimesh.proximity.closest_point(mesh, points)[1]


def funnel_surfaces(cfg: dict) -> dict[str, tuple[np.ndarray, float, float]]:
    """For each smooth surface of a plain funnel: (r, z) direction of its outward normal, exact area
    (m^2) and smallest radius (m). Profile: parallelogram with vertical sides dz = t / cos(angle)."""
    alpha = math.radians(cfg["angle"])
    r_in, r_out = 0.5 * cfg.get("inlet_diameter", TUBE["inner_diameter"]), 0.5 * cfg["outlet_diameter"]
    dz = cfg["wall_thickness"] / math.cos(alpha)
    cone = math.pi * (r_in + r_out) * (r_in - r_out) / math.cos(alpha)  # frustum: pi (r1 + r2) * slant
    return {
        "upper cone": (np.array([-math.sin(alpha), math.cos(alpha)]), cone, r_out),
        "lower cone": (np.array([math.sin(alpha), -math.cos(alpha)]), cone, r_out),
        "outlet band": (np.array([-1.0, 0.0]), 2.0 * math.pi * r_out * dz, r_out),
        "rim band": (np.array([1.0, 0.0]), 2.0 * math.pi * r_in * dz, r_in),
    }


def funnel_volume(cfg: dict) -> float:
    """Pappus: parallelogram area dz (r_in - r_out) times 2 pi times its centroid radius."""
    r_in, r_out = 0.5 * cfg.get("inlet_diameter", TUBE["inner_diameter"]), 0.5 * cfg["outlet_diameter"]
    return math.pi * cfg["wall_thickness"] / math.cos(math.radians(cfg["angle"])) * (r_in**2 - r_out**2)


def radial_normals(walls: Walls, mask: np.ndarray) -> np.ndarray:
    """(r, z) components of the normals of the masked triangles."""
    c = walls.centroid[mask]
    radial = c[:, :2] / np.linalg.norm(c[:, :2], axis=1)[:, None]
    n = walls.normal[mask]
    return np.column_stack([np.einsum("ij,ij->i", n[:, :2], radial), n[:, 2]])


def small_tubes(cfg: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """Inlet and outlet centres of each small tube, from the layout's definition: the inlet at the
    top, tube_inlet_radius from the axis; the outlet where the bore touches the tube wall."""
    beta = math.radians(cfg["inclination"])
    r_bore = 0.5 * cfg["tube_diameter"]
    r_outlet = R - r_bore / math.sin(beta)
    z_outlet = cfg["height"] - (r_outlet - cfg["tube_inlet_radius"]) * math.tan(beta)
    ends = []
    for k in range(cfg["n_tubes"]):
        phi = math.radians(cfg.get("orientation", 0.0)) + 2.0 * math.pi * k / cfg["n_tubes"]
        e = np.array([math.cos(phi), math.sin(phi), 0.0])
        ends.append((cfg["tube_inlet_radius"] * e + [0, 0, cfg["height"]], r_outlet * e + [0, 0, z_outlet]))
    return ends


def bore_mask(walls: Walls, mask: np.ndarray, inlet: np.ndarray, outlet: np.ndarray, radius: float) -> np.ndarray:
    """Masked triangles lying on the bore cylinder (all corners at ``radius`` from its axis, normals
    across the axis and pointing at it)."""
    e = (outlet - inlet) / np.linalg.norm(outlet - inlet)
    rel = walls.vertices - inlet
    off_axis = np.linalg.norm(rel - np.einsum("ijk,k->ij", rel, e)[:, :, None] * e, axis=2)
    to_axis = inlet + np.outer((walls.centroid - inlet) @ e, e) - walls.centroid
    return (
        mask
        & np.all(np.abs(off_axis - radius) < 1e-9, axis=1)
        & (np.abs(walls.normal @ e) < 0.3)
        & (np.einsum("ij,ij->i", walls.normal, to_axis) > 0)
    )


def passage_paths(radial_cfg: dict, radial_bottom: float, plate_cfg: dict) -> list[tuple[str, np.ndarray, float]]:
    """(name, points (K,3), designed half-width in m) for every passage of the scene: down each small
    tube (vertically into the inlet, along the bore, vertically out), down the axis through the
    radial mixer's central opening and funnel outlet to its bottom ``radial_bottom`` (m), and down
    through the plate's opening."""
    s = np.linspace(0.0, 1.0, 120)[:, None]
    drop = np.array([0.0, 0.0, 2.0e-3])
    paths = []
    for k, (inlet, outlet) in enumerate(small_tubes(radial_cfg)):
        points = np.vstack([inlet + drop * (1 - s), inlet + (outlet - inlet) * s, outlet - drop * s])
        paths.append((f"small tube {k}", points, 0.5 * radial_cfg["tube_diameter"]))
    top = radial_cfg["height"]
    axis = np.column_stack([np.zeros(300), np.zeros(300), np.linspace(radial_bottom, top + 1e-3, 300)])
    beta = math.radians(radial_cfg["inclination"])
    a = (0.5 * radial_cfg["tube_diameter"] + radial_cfg["wall_thickness"]) / math.sin(beta)
    half = min(radial_cfg["tube_inlet_radius"] - a, 0.5 * radial_cfg["outlet_diameter"])
    paths.append(("radial mixer axis", axis, half))
    # The largest circle in the plate's opening touches chord and arc: diameter = segment height.
    theta = _segment_angle(plate_cfg["opening"])
    sagitta = R * (1.0 - math.cos(0.5 * theta))
    phi = math.radians(plate_cfg.get("orientation", 0.0))
    centre = (R - 0.5 * sagitta) * np.array([math.cos(phi), math.sin(phi), 0.0])
    z = np.linspace(plate_cfg["height"] - 2e-3, plate_cfg["height"] + 1e-3, 150)
    paths.append(("plate opening", centre + np.column_stack([0 * z, 0 * z, z]), 0.5 * sagitta))
    return paths


def _segment_angle(fraction: float) -> float:
    """Central angle of the segment with area fraction * pi R^2, by bisection on
    (theta - sin theta) / (2 pi) = fraction (independent of geometry.plate's root finder)."""
    low, high = 0.0, 2.0 * math.pi
    for _ in range(200):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if mid - math.sin(mid) < 2.0 * math.pi * fraction else (low, mid)
    return 0.5 * (low + high)


def _on_scene(name: str, description: str, unit: str):
    """Register ``check(summary, walls) -> (error, tolerance)`` as a case run on the SCENE build."""

    def register(check):
        case(name, description, unit)(lambda: check(*scene()))
        return check

    return register


@case("geometry_tube_volume", "faceted tube volume deficit above the orifice within the inscribed-polygon bound")
def tube_volume():
    # Horizontal sections of the faceted cylinder are polygons with corners between radius
    # R cos(theta/2) and R, so the deficit 1 - V/V_exact lies in [0, sin^2(theta/2)].
    from dpht.geometry import build

    with tempfile.TemporaryDirectory() as outdir:
        summary = build({"tube": TUBE, "mesh_size": 1.0}, 1.0e-3, outdir)
        walls = load_walls(f"{outdir}/walls.h5")
    cylinder = ~walls.zone_mask("orifice")
    theta = span(max_edge(walls.vertices[cylinder]), R)
    deficit = 1.0 - summary["volume_above_orifice"] / summary["volume_above_orifice_exact"]
    return (deficit if deficit > 0 else math.inf), math.sin(0.5 * theta) ** 2  # an excess is a bug


@_on_scene("geometry_plate_volume", "flat-plate mesh volume vs (1 - opening) pi R^2 thickness, over its faceting bound",
           "x faceting bound")
def plate_volume(summary: dict, walls: Walls):
    # Only the arc is faceted: each arc edge spanning phi cuts off R^2 (phi - sin phi)/2 <= R^2 phi^3/12
    # of the top and bottom faces, so the deficit is at most t R^2 (2 pi - theta) phi_max^2 / 12.
    mask = walls.zone_mask("plate")
    t, f = PLATE["thickness"], PLATE["opening"]
    exact = (1.0 - f) * math.pi * R**2 * t
    phi = span(max_edge(walls.vertices[mask]), R)
    bound = t * R**2 * (2.0 * math.pi - _segment_angle(f)) * phi**2 / 12.0
    volume = summary["mixers"][0]["volume"]
    return abs(volume - exact) / bound, 1.0


@_on_scene("geometry_funnel_cad", "funnel CAD volume and area (OpenCASCADE) vs Pappus and frustum formulas", "relative")
def funnel_cad(summary: dict, walls: Walls):
    funnel = summary["mixers"][2]
    area = sum(a for _, a, _ in funnel_surfaces(FUNNEL).values())
    return max(abs(funnel["volume_cad"] / funnel_volume(FUNNEL) - 1.0), abs(funnel["area_cad"] / area - 1.0)), 1e-9


@_on_scene("geometry_funnel_mesh_area", "funnel surfaces' mesh areas vs frustum and band areas, over theta^2/12",
           "x faceting bound")
def funnel_mesh_area(summary: dict, walls: Walls):
    mask = walls.zone_mask("funnel")
    normals = radial_normals(walls, mask)
    worst = 0.0
    for direction, exact, r_min in funnel_surfaces(FUNNEL).values():
        on = normals @ direction > 0.99
        theta = span(max_edge(walls.vertices[mask][on]), r_min)
        worst = max(worst, abs(walls.area[mask][on].sum() / exact - 1.0) / (theta**2 / 12.0))
    return worst, 1.0


@_on_scene("geometry_radial_bores", "small-tube bore mesh areas vs 2 pi r L, over theta^2/12", "x faceting bound")
def radial_bores(summary: dict, walls: Walls):
    mask = walls.zone_mask("radial")
    r_bore = 0.5 * RADIAL["tube_diameter"]
    worst = 0.0
    for inlet, outlet in small_tubes(RADIAL):
        # Both ends are cut by horizontal planes: the lateral area is the circumference times the
        # axial distance between the cut centres.
        bore = bore_mask(walls, mask, inlet, outlet, r_bore)
        exact = 2.0 * math.pi * r_bore * np.linalg.norm(outlet - inlet)
        theta = span(max_edge(walls.vertices[bore]), r_bore)
        worst = max(worst, abs(walls.area[bore].sum() / exact - 1.0) / (theta**2 / 12.0))
    return worst, 1.0


@_on_scene("geometry_mixer_passages", "clearance along every mixer passage vs its designed half-width, over its bound",
           "x faceting bound")
def mixer_passages(summary: dict, walls: Walls):
    # The mesh of a passage of half-width w lies no nearer than w cos(theta/2) to its axis; a
    # clearance above w is not an error here (facets of convex rims lie behind the smooth rim).
    mixers = ~np.isin(walls.zone_names, ["heated_wall", "adiabatic_wall", "orifice"])[walls.zone]
    h = max_edge(walls.vertices[mixers])
    worst = 0.0
    for _, points, half in passage_paths(RADIAL, summary["mixers"][1]["z_range"][0], PLATE):
        shortfall = 1.0 - clearance(walls, points).min() / half
        worst = max(worst, shortfall / (1.0 - math.cos(0.5 * span(h, half))))
    return worst, 1.0
