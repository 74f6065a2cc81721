"""One wall contact per wall surface, at the surface's nearest point, with the boundary condition
there (dpht.thermal.model): the edge and corner cases, on meshes and on exact primitives, against
the brute-force reference."""

from __future__ import annotations

import numpy as np
import pytest

from dpht.errors import DPHTError
from dpht.thermal import integrate, model as thermal_model
from dpht.thermal.modes import PW_MODES
from dpht.verification import reference, scenes
from dpht.geometry.walls import Primitive, Walls

R = scenes.RADIUS
R_TUBE, LENGTH, Z_CUT = 8 * R, 24 * R, 12 * R
CONDUCTION = ("pw_contact", "pfw")
ALL_PW = (*CONDUCTION, "pw_radiation")


def cylinder(z0, z1, n_theta=64, n_z=12):
    """Triangles of the cylinder r = R_TUBE between z0 and z1, corners on the cylinder."""
    return scenes.cylinder_triangles(R_TUBE, z0, z1, n_theta, n_z)


def annulus(z, r0, r1, n_theta=64, n_r=4):
    """Triangles of the plane z between radii r0 and r1."""
    theta = np.linspace(0, 2 * np.pi, n_theta + 1)
    radii = np.linspace(r0, r1, n_r + 1)
    tris = []
    for k in range(n_r):
        for m in range(n_theta):
            p = [(radii[i] * np.cos(theta[j]), radii[i] * np.sin(theta[j]), z) for i, j in
                 ((k, m), (k + 1, m), (k + 1, m + 1), (k, m + 1))]  # fmt: skip
            tris += [[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
    return np.array(tris, dtype=np.float64)


def box(lo, hi):
    """Triangles of the closed box [lo, hi]^3 (two per face)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([tri for f in faces for tri in ([c[f[0]], c[f[1]], c[f[2]]], [c[f[0]], c[f[2]], c[f[3]]])])


def tube(bottom="heated_wall", top="adiabatic_wall", plate=None):
    """A tube cut at Z_CUT into the zones ``bottom`` and ``top`` (one surface, "tube", with its exact
    cylinder pieces) and optionally an orifice plate at z = 0 (surface "orifice_plate", zone ``plate``)."""
    parts = [(cylinder(0.0, Z_CUT), bottom, "tube"), (cylinder(Z_CUT, LENGTH), top, "tube")]
    if plate:
        parts.append((annulus(0.0, 0.5 * R_TUBE, R_TUBE), plate, "orifice_plate"))
    pieces = [Primitive.cylinder(bottom, R_TUBE, 0.0, Z_CUT), Primitive.cylinder(top, R_TUBE, Z_CUT, LENGTH)]
    if plate:
        pieces.append(Primitive.annulus(plate, 0.0, 0.5 * R_TUBE, R_TUBE))
    return assemble(parts, pieces)


def assemble(parts, primitives=()):
    """A wall table from (triangles, zone, surface) parts."""
    zones = list(dict.fromkeys(z for _, z, _ in parts))
    surfaces = list(dict.fromkeys(s for _, _, s in parts))
    zone = np.concatenate([np.full(len(t), zones.index(z)) for t, z, _ in parts])
    surface = np.concatenate([np.full(len(t), surfaces.index(s)) for t, _, s in parts])
    return Walls.from_vertices(np.concatenate([t for t, _, _ in parts]), zone, zones, primitives, surface, surfaces)


def model_for(walls, conditions, modes=ALL_PW, kinds=None):
    s = scenes.spec(modes, walls=conditions, initial_temperature=300.0, inlet_temperature=300.0)
    return thermal_model.build(s, walls, scenes.htc_tables(s), scenes.synthetic_rdf(), kinds)


def kinds_of(walls, kind):
    return dict.fromkeys(walls.zone_names, kind)


def at(rho, z, phi=0.3):
    return np.array([[rho * np.cos(phi), rho * np.sin(phi), z]])


def contacts(model, points):
    """(element, distance) per surface and point, in the points' order."""
    frame = integrate.prepare_frame(model, np.asarray(points, float), None, None, (False, False, False))
    order = np.argsort(frame.particles)
    return frame.wall_element[:, order], frame.wall_distance[:, order]


def wall_heat(model, points, T=300.0):
    """Heat per PW mode (W) from the walls into particles at ``points`` at temperature T."""
    frame = integrate.prepare_frame(model, np.asarray(points, float), None, None, (False, False, False))
    h = np.full(len(points), model.enthalpy.enthalpy(T)[()])
    return integrate.advance(model, frame, h, 0.0, integrate.Rates.for_frame(model, frame)).element_heat.sum(axis=0)


HOT = {"temperature": 900.0}


@pytest.mark.parametrize("kind", ["mesh", "primitive"])
def test_a_particle_nearest_to_the_adiabatic_part_of_the_tube_gets_no_heat_from_its_heated_part(kind):
    """On the cylinder, heated below Z_CUT and adiabatic above: a particle touching the wall just
    above the seam is nearest to adiabatic wall, so it has no contact, although heated elements lie
    within every cutoff (a contact per zone gave it one at hypot(0.1 R, 0.3 R))."""
    walls = tube()
    model = model_for(walls, {"heated_wall": HOT, "adiabatic_wall": "adiabatic"}, kinds=kinds_of(walls, kind))
    above, below = at(R_TUBE - 0.9 * R, Z_CUT + 0.3 * R), at(R_TUBE - 0.9 * R, Z_CUT - 0.3 * R)
    assert np.all(wall_heat(model, above) == 0.0)
    element, distance = contacts(model, np.vstack([above, below]))
    assert element.shape[0] == 1  # one surface with a Dirichlet element: the tube
    assert element[0, 0] == -1 and walls.zone_names[walls.zone[element[0, 1]]] == "heated_wall"
    exact = R_TUBE - np.hypot(*below[0, :2])
    if kind == "primitive":  # the exact cylinder
        assert distance[0, 1] == pytest.approx(exact, rel=1e-12)
    else:  # the facet under the particle, inside the cylinder by at most its sagitta
        assert 0 <= exact - distance[0, 1] <= R_TUBE * (1 - np.cos(np.pi / 64))
    assert np.all(wall_heat(model, below) > 0)


@pytest.mark.parametrize("kind", ["mesh", "primitive"])
def test_two_dirichlet_zones_of_one_surface_count_a_particle_at_their_edge_once(kind):
    """Zones at 900 K and 700 K meeting at Z_CUT: a particle just above the edge exchanges heat with
    the 700 K element under it, once, exactly as with a wall made of that zone alone."""
    walls = tube(bottom="hot_zone", top="warm_zone")
    model = model_for(walls, {"hot_zone": HOT, "warm_zone": {"temperature": 700.0}}, kinds=kinds_of(walls, kind))
    point = at(R_TUBE - 0.95 * R, Z_CUT + 0.05 * R)
    element, _ = contacts(model, point)
    assert (element >= 0).sum() == 1 and walls.zone_names[walls.zone[element[element >= 0][0]]] == "warm_zone"
    alone = model_for(walls, {"hot_zone": {"temperature": 700.0}, "warm_zone": {"temperature": 700.0}}, kinds=kinds_of(walls, kind))
    np.testing.assert_allclose(wall_heat(model, point), wall_heat(alone, point), rtol=1e-12)
    assert wall_heat(model, point)[0] > 0  # touching: contact conduction


@pytest.mark.parametrize("plate", ["heated_plate", "adiabatic_plate"])
@pytest.mark.parametrize("kind", ["mesh", "primitive"])
def test_a_particle_in_the_corner_of_tube_and_plate_keeps_a_contact_with_each(kind, plate):
    """Tube and orifice plate are two surfaces: in their corner a particle touches both, and keeps
    its heated-tube contact even where the (adiabatic) plate is nearer."""
    walls = tube(bottom="heated_wall", top="heated_top", plate=plate)
    conditions = {"heated_wall": HOT, "heated_top": HOT, plate: HOT if plate == "heated_plate" else "adiabatic"}
    kinds = {**kinds_of(walls, kind), plate: "mesh"}  # the DEM's orifice is always its mesh
    model = model_for(walls, conditions, kinds=kinds)
    point = at(R_TUBE - 0.9 * R, 0.8 * R)
    element, distance = contacts(model, point)
    surfaces = [s.name for s in model.surfaces]
    assert surfaces == (["tube", "orifice_plate"] if plate == "heated_plate" else ["tube"])
    assert np.all(element[:, 0] >= 0)
    assert distance[surfaces.index("tube"), 0] <= 0.9 * R + 1e-15
    if plate == "heated_plate":
        assert distance[1, 0] == pytest.approx(0.8 * R, rel=1e-12)
    assert wall_heat(model, point)[0] > 0


def test_mixer_solids_are_surfaces_of_their_own_even_in_one_zone():
    """Two heated mixer boxes in one zone ("mixer") inside an adiabatic tube: a particle between
    them touches each, two contacts (a contact per zone gave it one); near a box's edge it has one
    contact, with the nearer face; near the adiabatic tube wall it takes nothing from the tube."""
    gap = 1.8 * R
    left, right = box([-3 * R - gap / 2, -R, 4 * R], [-gap / 2, R, 6 * R]), box([gap / 2, -R, 4 * R], [3 * R + gap / 2, R, 6 * R])
    walls = assemble([(cylinder(0.0, LENGTH), "tube_wall", "tube"), (left, "mixer", "mixer_a"), (right, "mixer", "mixer_b")])
    model = model_for(walls, {"tube_wall": "adiabatic", "mixer": HOT})
    assert [s.name for s in model.surfaces] == ["mixer_a", "mixer_b"]
    between = np.array([[0.0, 0.0, 5 * R]])
    element, distance = contacts(model, between)
    assert np.all(element[:, 0] >= 0) and np.allclose(distance[:, 0], gap / 2, rtol=1e-12)
    edge = np.array([[gap / 2 + 3.5 * R, 0.0, 6.5 * R]])  # beyond the outer top edge of the right box
    element, distance = contacts(model, edge)
    assert np.all(element[:, 0] >= 0)  # the left box still radiates to it
    np.testing.assert_allclose(distance[:, 0], [np.hypot(gap + 3.5 * R, 0.5 * R), np.sqrt(0.5) * R], rtol=1e-12)
    near_tube = at(R_TUBE - 0.5 * R, 20 * R)
    assert np.all(contacts(model, near_tube)[0] == -1)


@pytest.mark.parametrize("kind", ["mesh", "primitive"])
def test_contacts_and_heat_equal_the_brute_force_reference(kind):
    """Random particles in a tube with four zones on two surfaces: the contacts (element and
    distance per surface) and wall heat of the compiled path equal an all-elements search."""
    walls = tube(bottom="heated_wall", top="adiabatic_wall", plate="orifice")
    conditions = {"heated_wall": HOT, "adiabatic_wall": "adiabatic", "orifice": {"temperature": 600.0}}
    model = model_for(walls, conditions, kinds={**kinds_of(walls, kind), "orifice": "mesh"})
    rng = np.random.default_rng(4)
    n = 600
    rho = R_TUBE * np.sqrt(rng.uniform(0.3, 1.0, n)) - 0.95 * R * rng.uniform(0.0, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    points = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), rng.uniform(0.05 * R, LENGTH, n)])
    frame = integrate.prepare_frame(model, points, None, None, (False, False, False))
    found = {(int(frame.particles[i]), int(e), round(float(frame.wall_distance[s, i]), 15))
             for s, i in zip(*np.nonzero(frame.wall_element >= 0)) for e in [frame.wall_element[s, i]]}  # fmt: skip
    expected = {(int(i), int(e), round(float(d), 15)) for i, e, d in zip(*reference.wall_contacts(model, points, walls))}
    assert len(found) > 200 and found == expected
    T = np.random.default_rng(5).uniform(320.0, 800.0, n)
    h = model.enthalpy.enthalpy(T)
    report = integrate.advance(model, frame, h, 0.0, integrate.Rates.for_frame(model, frame))
    _, heat = reference.heat_rates(model, points, model.enthalpy.temperature(h), walls)
    np.testing.assert_allclose(report.element_heat.sum(axis=0), heat, rtol=1e-10)
    assert heat[PW_MODES.index("pw_contact")] > 0


def test_a_dem_record_that_does_not_fit_the_wall_table_is_refused():
    walls = tube()
    conditions = {"heated_wall": HOT, "adiabatic_wall": "adiabatic"}
    with pytest.raises(DPHTError, match="different geometries"):
        model_for(walls, conditions, kinds={"heated_wall": "primitive"})
    no_primitives = Walls.from_vertices(walls.vertices, walls.zone, walls.zone_names, (), walls.surface, walls.surface_names)
    with pytest.raises(DPHTError, match="no primitives for them.*rebuild the geometry"):
        model_for(no_primitives, conditions, kinds=kinds_of(walls, "primitive"))


def test_the_built_tube_gives_no_heat_above_its_heated_range(tmp_path):
    """On the geometry stage's tube (heated 4-40 mm, adiabatic above): a particle touching the wall
    2 mm above the heated range, nearest to adiabatic wall, receives no heat from the heated
    elements 0.2 R below its nearest point; one just inside the range does."""
    from dpht.geometry import build
    from dpht.geometry.walls import load_walls

    d = 2 * R
    tube_cfg = {"inner_diameter": 9e-3, "length": 0.05, "orifice_height": 0.004, "orifice_diameter": 7e-3, "heated": [0.004, 0.040]}
    build({"tube": tube_cfg, "mesh_size": 1.0}, d, tmp_path)
    walls = load_walls(tmp_path / "walls.h5")
    s = scenes.spec(CONDUCTION, walls={"heated_wall": HOT, "adiabatic_wall": "adiabatic", "orifice": "adiabatic"},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    model = thermal_model.build(s, walls, scenes.htc_tables(s))  # the wall table's meshes
    r = 4.5e-3 - 0.95 * R
    above, inside = at(r, 0.040 + 0.2 * R), at(r, 0.040 - 0.2 * R)
    columns = [PW_MODES.index(m) for m in CONDUCTION]
    assert np.all(wall_heat(model, above) == 0.0)
    assert np.all(wall_heat(model, inside)[columns] > 0.0)
