"""Mixers (DPHT paper, Section 6): closed forms for plate, funnel and small tubes; closed, outward
surfaces; passages that admit the particles; zone tagging; config errors naming the key."""

from __future__ import annotations

import copy
import itertools
import math

import meshio
import numpy as np
import pytest
import trimesh

from dpht.geometry.errors import GeometryConfigError, GeometryError
from dpht.verification.cases import geometry as reference
from dpht.verification.cases.geometry import D_PAPER, FUNNEL, PLATE, RADIAL, SCENE, TUBE
import dem_scene
from dpht.dem.decks import render_decks
from dpht.dem.liggghts import _stage_meshes
from dpht.dem.params import DemParams
from dpht.thermal import primitives
from dpht.thermal.wall_distance import build_index, nearest
from dpht.geometry.walls import Primitive, Walls, load_walls
from dpht.geometry import build, picture
from dpht.geometry.closed_surface import (
    is_closed_and_consistent,
    orient_outward,
    signed_volume,
    smallest_angle,
    triangle_quality,
)

R = reference.R
MIXER_ZONES = ("plate", "radial", "funnel")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    outdir = tmp_path_factory.mktemp("scene")
    summary = build(SCENE, D_PAPER, outdir)
    return outdir, summary, load_walls(outdir / "walls.h5")


def indexed(vertices):
    """Shared corner table and (M,3) indices; gmsh nodes are shared bit for bit."""
    corners, ids = np.unique(vertices.reshape(-1, 3), axis=0, return_inverse=True)
    return corners, ids.reshape(-1, 3)


# --- closed forms ---------------------------------------------------------------------------


def test_plate_chord_and_faces_match_the_segment(scene):
    _, _, walls = scene
    mask = walls.zone_mask("plate")
    t, f, phi = PLATE["thickness"], PLATE["opening"], math.radians(PLATE["orientation"])
    towards_opening = np.array([math.cos(phi), math.sin(phi), 0.0])
    chord_face = mask & (walls.normal @ towards_opening > 1 - 1e-12)
    # The chord face is a flat rectangle at distance c from the axis; the segment beyond it must hold
    # the fraction f of the cross-section: R^2 acos(c/R) - c sqrt(R^2 - c^2) = f pi R^2.
    c = walls.vertices[chord_face] @ towards_opening
    assert np.ptp(c) < 1e-15
    c = c.mean()
    assert R**2 * math.acos(c / R) - c * math.sqrt(R**2 - c**2) == pytest.approx(f * math.pi * R**2, rel=1e-9)
    assert walls.area[chord_face].sum() == pytest.approx(2.0 * math.sqrt(R**2 - c**2) * t, rel=1e-12)
    # Top and bottom faces: (1 - f) pi R^2 less what the arc's chords cut off, R^2 (p - sin p)/2 each.
    edge = reference.span(reference.max_edge(walls.vertices[mask]), R)
    for z, up in ((PLATE["height"], 1.0), (PLATE["height"] - t, -1.0)):
        face = mask & np.all(walls.vertices[:, :, 2] == z, axis=1)
        assert np.all(walls.normal[face, 2] == up)
        deficit = (1.0 - f) * math.pi * R**2 - walls.area[face].sum()
        assert 0.0 < deficit <= R**2 * (2.0 * math.pi) * edge**2 / 12.0


def test_radial_layout_inlets_outlets_and_extent(scene):
    _, summary, walls = scene
    mask = walls.zone_mask("radial")
    beta = math.radians(RADIAL["inclination"])
    r_bore = 0.5 * RADIAL["tube_diameter"]
    r_wall = r_bore + RADIAL["wall_thickness"]
    ends = reference.small_tubes(RADIAL)
    for inlet, outlet in ends:
        bore = walls.vertices[reference.bore_mask(walls, mask, inlet, outlet, r_bore)]
        assert bore[:, :, 2].max() == pytest.approx(RADIAL["height"], abs=1e-12)  # cut at the inlet level
        assert bore[:, :, 2].min() == pytest.approx(outlet[2], abs=1e-12)  # and at the outlet level
        assert np.hypot(bore[:, :, 0], bore[:, :, 1]).max() == pytest.approx(R, rel=1e-9)  # touches the wall
    # The inlet rims are horizontal ellipse annuli (semi-axes r / sin(beta) and r) at the top.
    rims = mask & np.all(walls.vertices[:, :, 2] == RADIAL["height"], axis=1)
    assert np.all(walls.normal[rims, 2] == 1.0)
    exact = len(ends) * math.pi * (r_wall**2 - r_bore**2) / math.sin(beta)
    step = reference.span(reference.max_edge(walls.vertices[rims]), r_bore)  # parameter step of the polygons
    assert walls.area[rims].sum() == pytest.approx(exact, rel=step**2 / 6.0)
    # Vertical extent: down to the funnel's lowest point or the outlets, whichever is lower.
    alpha = math.radians(RADIAL["angle"])
    funnel_bottom = RADIAL["height"] - (R - 0.5 * RADIAL["outlet_diameter"]) * math.tan(alpha) - (
        RADIAL["wall_thickness"] / math.cos(alpha))
    bottom = min(funnel_bottom, ends[0][1][2])
    z = walls.vertices[mask][:, :, 2]
    assert z.min() == pytest.approx(bottom, abs=1e-12) and z.max() == pytest.approx(RADIAL["height"], abs=1e-12)
    assert summary["mixers"][1]["z_range"] == pytest.approx([bottom, RADIAL["height"]], abs=1e-15)


# --- passages ---------------------------------------------------------------------------------


def test_a_particle_passes_along_every_passage(scene):
    _, summary, walls = scene
    paths = reference.passage_paths(RADIAL, summary["mixers"][1]["z_range"][0], PLATE)
    assert len(paths) == RADIAL["n_tubes"] + 2
    for name, points, half in paths:
        gap = reference.clearance(walls, points).min()
        assert gap > 0.5 * D_PAPER, name  # a sphere of the particle diameter passes without touching
        if name != "radial mixer axis":  # inscribed facets: never wider than designed
            assert gap <= half * (1 + 1e-9), name


def test_the_sweep_detects_a_blocked_path(scene):
    # Control for the sweep: straight down next to the wall, the radial mixer's funnel is in the way.
    _, _, walls = scene
    z = np.linspace(RADIAL["height"] - 8e-3, RADIAL["height"] + 1e-3, 200)
    points = np.column_stack([np.full_like(z, -(R - 0.3e-3)), np.zeros_like(z), z])
    assert reference.clearance(walls, points).min() < 0.1 * D_PAPER  # samples inside the funnel wall


# --- surfaces and files -------------------------------------------------------------------------


def test_each_mixer_is_closed_outward_and_matches_its_cad_volume(scene):
    _, summary, walls = scene
    for index, zone in enumerate(MIXER_ZONES):
        mask = walls.zone_mask(zone)
        corners, faces = indexed(walls.vertices[mask])
        assert is_closed_and_consistent(faces), zone
        independent = trimesh.Trimesh(corners, faces, process=False)
        assert independent.is_watertight and independent.is_winding_consistent, zone
        assert independent.volume > 0, zone  # outward normals: into the particles
        report = summary["mixers"][index]
        assert report["zone"] == zone and report["triangles"] == mask.sum()
        assert report["volume"] == pytest.approx(independent.volume, rel=1e-12)
        assert report["volume"] == pytest.approx(report["volume_cad"], rel=2e-2)  # coarse facets
        assert report["min_triangle_area"] > 0 and report["min_triangle_quality"] > 0.1
        assert report["min_triangle_angle"] > 0.5  # LIGGGHTS warns below 0.5 degrees
    # Free volume: tube above the plate minus every mixer (all lie above it).
    mixers = sum(m["volume"] for m in summary["mixers"])
    assert summary["volume_above_orifice_free"] == pytest.approx(summary["volume_above_orifice"] - mixers, rel=1e-12)


def test_every_triangle_tagged_once_and_stls_match(scene):
    outdir, summary, walls = scene
    assert summary["zone_names"] == ["heated_wall", "adiabatic_wall", "orifice", *MIXER_ZONES]
    msh = meshio.read(outdir / "geometry.msh")
    tag_of = {name: int(tag) for name, (tag, dim) in msh.field_data.items()}
    blocks = [i for i, cells in enumerate(msh.cells) if cells.type == "triangle"]
    physical = np.concatenate([msh.cell_data["gmsh:physical"][i] for i in blocks])
    assert physical.size == len(walls)
    for name in walls.zone_names:
        assert np.sum(physical == tag_of[name]) == walls.zone_mask(name).sum() == summary["zones"][name]["triangles"]
        stl = trimesh.load(outdir / f"{name}.stl", process=False)
        assert np.array_equal(stl.triangles, walls.vertices[walls.zone_mask(name)])
    assert len(np.unique(np.sort(indexed(walls.vertices)[1], axis=1), axis=0)) == len(walls)


def test_tube_meshes_are_the_same_with_and_without_mixers(scene, tmp_path):
    # Mixers leave the tube's triangles alone (gmsh moved a few orifice-plate nodes by ~1e-18 m, a
    # few ulps, when all three mixers were present); an empty mixers list leaves every output
    # byte-identical to a config without the key, so cached DEM runs of a plain tube stay valid.
    outdir, _, scene_walls = scene
    plain = {"tube": TUBE, "mesh_size": SCENE["mesh_size"]}
    build(plain, D_PAPER, tmp_path / "plain")
    build({**plain, "mixers": []}, D_PAPER, tmp_path / "empty")
    walls = load_walls(tmp_path / "plain" / "walls.h5")
    for name in walls.zone_names:
        assert np.allclose(walls.vertices[walls.zone_mask(name)], scene_walls.vertices[scene_walls.zone_mask(name)],
                           rtol=0, atol=1e-17), name
    for name in ("heated_wall.stl", "adiabatic_wall.stl", "orifice.stl", "walls.h5", "geometry.json", "geometry.msh"):
        assert (tmp_path / "plain" / name).read_bytes() == (tmp_path / "empty" / name).read_bytes(), name


def test_mixers_without_zone_share_the_mixer_zone(tmp_path):
    plate = {k: v for k, v in PLATE.items() if k != "zone"}
    funnel = {k: v for k, v in FUNNEL.items() if k != "zone"}
    summary = build({"tube": TUBE, "mixers": [plate, funnel], "mesh_size": 2.0}, D_PAPER, tmp_path)
    assert summary["zone_names"][3:] == ["mixer"]
    assert summary["zones"]["mixer"]["triangles"] == sum(m["triangles"] for m in summary["mixers"])
    assert summary["zones"]["mixer"]["area_exact"] == pytest.approx(sum(m["area_cad"] for m in summary["mixers"]))
    assert (tmp_path / "mixer.stl").is_file()
    # One zone, but each mixer solid is a wall surface of its own (one wall contact each).
    walls = load_walls(tmp_path / "walls.h5")
    assert walls.surface_names == ("tube", "orifice_plate", "geometry.mixers[0]", "geometry.mixers[1]")
    for k, mixer in enumerate(summary["mixers"]):
        assert summary["surfaces"][mixer["key"]] == {"triangles": mixer["triangles"], "zones": ["mixer"]}
        assert np.all(walls.zone[walls.surface == 2 + k] == walls.zone_names.index("mixer"))


def test_picture_close_up_of_the_mixers(scene, tmp_path):
    import matplotlib.image

    outdir, _, _ = scene
    png = picture(outdir, tmp_path / "mixers.png", window_size=(500, 400), focus="radial")
    image = matplotlib.image.imread(png)[:, :, :3]
    green = np.all(np.abs(image - [0x66 / 255, 0xA1 / 255, 0x82 / 255]) < 0.2, axis=2)  # the radial zone's colour
    assert np.mean(np.any(image < 0.9, axis=2)) > 0.3 and green.mean() > 0.05
    with pytest.raises(GeometryError, match="stirrer"):
        picture(outdir, tmp_path / "x.png", focus="stirrer")


# --- closed_surface on a cube -------------------------------------------------------------------

CUBE_POINTS = np.array(list(itertools.product([0.0, 2.0], repeat=3)))
# Two triangles per face, each face wound outwards; patch = face index.
CUBE_FACES = np.array([
    [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
])
CUBE_PATCH = np.repeat(np.arange(6), 2)


def test_cube_faces_are_wound_outwards():
    assert signed_volume(CUBE_POINTS, CUBE_FACES) == pytest.approx(8.0)
    assert is_closed_and_consistent(CUBE_FACES)


@pytest.mark.parametrize("flipped", [[0], [1, 4], [0, 1, 2, 3, 4, 5]])
def test_orient_outward_repairs_flipped_patches(flipped):
    faces = CUBE_FACES.copy()
    flip = np.isin(CUBE_PATCH, flipped)
    faces[flip] = faces[flip][:, ::-1]
    assert not is_closed_and_consistent(faces) or len(flipped) == 6
    oriented = orient_outward(CUBE_POINTS, faces, CUBE_PATCH)
    assert np.array_equal(oriented, CUBE_FACES)  # whole patches flipped back, order kept
    assert signed_volume(CUBE_POINTS, oriented) == pytest.approx(8.0)


def test_orient_outward_rejects_open_or_inconsistent_surfaces():
    with pytest.raises(GeometryError, match="not closed"):
        orient_outward(CUBE_POINTS, CUBE_FACES[:-1], CUBE_PATCH[:-1])
    faces = CUBE_FACES.copy()
    faces[0] = faces[0][::-1]  # one triangle against its own patch
    with pytest.raises(GeometryError, match="cannot be oriented"):
        orient_outward(CUBE_POINTS, faces, CUBE_PATCH)


def test_triangle_quality_and_angle():
    equilateral = np.array([[[0, 0, 0], [1, 0, 0], [0.5, math.sqrt(3) / 2, 0]]])
    right = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=float)
    sliver = np.array([[[0, 0, 0], [1, 0, 0], [0.5, 1e-3, 0]]])
    assert triangle_quality(equilateral)[0] == pytest.approx(1.0)
    assert triangle_quality(right)[0] == pytest.approx(4 * math.sqrt(3) * 0.5 / 4)
    assert smallest_angle(np.vstack([equilateral, right]).astype(float)) == pytest.approx([60.0, 45.0])
    assert smallest_angle(sliver)[0] == pytest.approx(math.degrees(math.atan(2e-3)), rel=1e-6)


# --- config errors ------------------------------------------------------------------------------

_DELETE = object()


def with_mixer(index, **changes):
    """SCENE with mixer ``index`` changed (value _DELETE removes the key)."""
    cfg = copy.deepcopy(SCENE)
    for key, value in changes.items():
        if value is _DELETE:
            del cfg["mixers"][index][key]
        else:
            cfg["mixers"][index][key] = value
    return cfg


@pytest.mark.parametrize(
    "cfg, key",
    [
        (with_mixer(0, type="propeller"), "geometry.mixers[0].type"),
        (with_mixer(0, opening=0.05), "geometry.mixers[0].opening"),  # segment height 0.78 mm < 3 d
        (with_mixer(0, opening=1.0), "geometry.mixers[0].opening"),
        (with_mixer(0, thickness=0.0), "geometry.mixers[0].thickness"),
        (with_mixer(0, height="high"), "geometry.mixers[0].height"),
        (with_mixer(0, holes=3), "geometry.mixers[0]"),
        (with_mixer(0, zone="heated_wall"), "geometry.mixers[0].zone"),
        (with_mixer(0, zone="Mixer 1"), "geometry.mixers[0].zone"),
        (with_mixer(0, height=0.0043), "geometry.mixers[0].height"),  # 0.3 mm above the orifice plate
        (with_mixer(0, height=0.0262), "geometry.mixers[0].height"),  # through the periodic boundary
        (with_mixer(0, height=0.0125), "geometry.mixers[1].height"),  # touches the radial mixer
        (with_mixer(1, outlet_diameter=1.0e-3), "geometry.mixers[1].outlet_diameter"),
        (with_mixer(1, outlet_diameter=9.0e-3), "geometry.mixers[1].outlet_diameter"),
        (with_mixer(1, inlet_diameter=9.5e-3), "geometry.mixers[1].inlet_diameter"),
        (with_mixer(1, inlet_diameter=8.5e-3), "geometry.mixers[1].inlet_diameter"),  # 0.25 mm annular gap
        (with_mixer(1, tube_diameter=0.8e-3), "geometry.mixers[1].tube_diameter"),
        (with_mixer(1, tube_inlet_radius=1.8e-3), "geometry.mixers[1].tube_inlet_radius"),  # inlets 0.7 mm apart
        (with_mixer(1, tube_inlet_radius=3.6e-3), "geometry.mixers[1].tube_inlet_radius"),  # beyond the rim
        (with_mixer(1, inclination=25.0), "geometry.mixers[1].inclination"),  # outlets inside the funnel
        (with_mixer(1, inclination=90.0), "geometry.mixers[1].inclination"),
        (with_mixer(1, angle=0.0), "geometry.mixers[1].angle"),
        (with_mixer(1, n_tubes=-1), "geometry.mixers[1].n_tubes"),
        (with_mixer(1, n_tubes=2.5), "geometry.mixers[1].n_tubes"),
        (with_mixer(1, tube_diameter=_DELETE), "geometry.mixers[1]"),
        (with_mixer(2, wall_thickness=-1e-4), "geometry.mixers[2].wall_thickness"),
        ({**SCENE, "mixers": {"type": "radial"}}, "geometry.mixers"),
        ({**SCENE, "mixers": ["radial"]}, r"geometry.mixers[0].type"),
    ],
)
def test_bad_mixer_config_raises_error_naming_the_key(tmp_path, cfg, key):
    with pytest.raises(GeometryConfigError, match=key.replace(".", r"\.").replace("[", r"\[").replace("]", r"\]")):
        build(cfg, D_PAPER, tmp_path)
    assert not (tmp_path / "walls.h5").exists()


# --- exact surfaces (geometry.walls.Primitive) and the STLs the DEM reads -----------------------

R_TUBE = 0.5 * TUBE["inner_diameter"]


def on_azimuth(rho, z, seed=0):
    """Points at distance ``rho`` from the axis and height ``z``, at random azimuths."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi, np.size(rho))
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z * np.ones(np.size(rho))])


def test_geometry_records_the_exact_surface_of_each_tube_zone(scene):
    outdir, summary, walls = scene
    tube = SCENE["tube"]
    by_zone = {z: [p for p in walls.primitives if p.zone == z] for z in walls.zone_names}
    assert all(p.kind == "cylinder" and p.segment[0] == 0.5 * tube["inner_diameter"] for p in by_zone["heated_wall"])
    pieces = sorted(p.segment[1::2] for z in ("heated_wall", "adiabatic_wall") for p in by_zone[z])
    assert pieces[0][0] == 0.0 and pieces[-1][1] == tube["length"]  # the whole periodic tube ...
    assert all(a[1] == b[0] for a, b in zip(pieces[:-1], pieces[1:]))  # ... without gaps
    (plate,) = by_zone["orifice"]
    assert plate.kind == "annulus" and plate.segment == (0.5 * tube["orifice_diameter"], tube["orifice_height"],
                                                         0.5 * tube["inner_diameter"], tube["orifice_height"])
    assert not any(by_zone[z] for z in ("plate", "radial", "funnel"))  # mixers: triangles only
    assert summary["zones"]["orifice"]["primitives"] == [{"kind": "annulus", "segment": list(plate.segment)}]
    # The triangles lie on their primitives (checked on load) but inside the smooth cylinder between
    # their corners: particle centres near the wall see the facets closer than the cylinder.
    cylinder = primitives.surfaces(walls, ("heated_wall",))
    mask = walls.zone_mask("heated_wall")
    index = build_index(walls.vertices[mask], 0.5e-3)
    rng = np.random.default_rng(1)
    points = on_azimuth(rng.uniform(R_TUBE - 0.4e-3, R_TUBE - 0.1e-3, 2000), rng.uniform(0.006, 0.024, 2000))
    exact, _ = primitives.nearest(points, cylinder.segment)
    _, faceted = nearest(index, points)
    tri = walls.vertices[mask]
    longest = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max()
    sagitta = R_TUBE * (1 - np.cos(np.arcsin(longest / (2 * R_TUBE))))  # of the longest chord
    assert summary["zones"]["heated_wall"]["primitives"][0]["kind"] == "cylinder"
    assert np.all(faceted <= exact + 1e-15) and (exact - faceted).max() <= sagitta * 1.01
    assert (exact - faceted).mean() > 0.2 * sagitta


def test_walls_refuse_primitives_their_triangles_are_not_on(scene):
    _, _, walls = scene
    moved = Primitive.cylinder("heated_wall", 1.001 * R_TUBE, 0.004, 0.026)
    with pytest.raises(GeometryError, match="heated_wall.*off its primitives"):
        Walls.from_vertices(walls.vertices, walls.zone, walls.zone_names, (moved,))
    with pytest.raises(GeometryError, match="is a cylinder, not a cone"):
        Primitive("x", "cone", (R_TUBE, 0.0, R_TUBE, 1.0))


def test_the_dem_reads_the_same_stls_and_cylinder_as_the_wall_table(scene, tmp_path):
    """Every zone LIGGGHTS reads as a mesh (the orifice and each mixer; the tube too with
    tube_wall: mesh) is staged into the one mesh file of the decks with the geometry stage's STL
    text, zone after zone, whose triangles are walls.h5's; the primitive tube is the recorded
    cylinder, to the last digit."""
    outdir, summary, walls = scene
    spec = copy.deepcopy(dem_scene.SPEC)
    spec["geometry"] = {"tube": SCENE["tube"], "mixers": SCENE["mixers"], "mesh_size": SCENE["mesh_size"]}
    spec["particles"]["diameter"] = D_PAPER
    for tube_wall in ("primitive", "mesh"):
        spec["dem"]["tube_wall"] = tube_wall
        params = DemParams.from_spec(spec, summary)
        zones = params.mesh_zones
        assert set(zones) >= {"orifice", "plate", "radial", "funnel"}
        work = tmp_path / tube_wall
        work.mkdir()
        _stage_meshes(zones, outdir, work)
        flow = render_decks(params)["flow.in"]
        assert "mesh/surface file meshes/walls.stl" in flow
        staged = (work / "meshes" / "walls.stl").read_text()
        assert staged == "solid walls\n" + "".join(
            (outdir / f"{zone}.stl").read_text().split("\n", 1)[1].rsplit("endsolid", 1)[0] for zone in zones
        ) + "endsolid walls\n"
        stl = trimesh.load(work / "meshes" / "walls.stl", process=False)
        assert np.array_equal(stl.triangles, np.concatenate([walls.vertices[walls.zone_mask(zone)] for zone in zones]))
        if tube_wall == "primitive":
            (radius,) = {p.segment[0] for p in walls.primitives if p.zone in ("heated_wall", "adiabatic_wall")}
            assert f"zcylinder {radius!r} 0.0 0.0" in flow
