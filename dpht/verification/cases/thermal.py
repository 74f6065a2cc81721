"""Thermal-stage cases: relaxations with exact solutions, conservation, the maximum principle."""

import math

import numpy as np

from dpht.closures import contact
from dpht.thermal.neighbors import brute_force_pairs, build, pairs
from dpht.verification.scenes import RADIUS as R, advance, build_model, plane_walls, random_cluster, spec
from dpht.verification.harness import case

CONDUCTION = ["pp_contact", "pw_contact", "pfp", "pfw"]


def _relaxation_error(modes, positions, T0, walls, rate):
    """Max relative error of T(t) against exp(-rate t) over 2 time constants, 2000 steps."""
    model = build_model(spec(modes), walls)
    h = model.enthalpy.enthalpy(np.asarray(T0, dtype=float))
    steps, t_end = 2000, 2.0 / rate
    excess0 = _excess(model, h, walls)
    frame, rates, _ = advance(model, positions, h, t_end / steps, steps)
    return abs(_excess(model, h, walls) / excess0 - math.exp(-rate * t_end)) / math.exp(-rate * t_end)


def _excess(model, h, walls):
    T = model.enthalpy.temperature(h)
    return T[1] - T[0] if walls is None else 600.0 - T[0]


@case("pp_contact_two_spheres", "two overlapping spheres relax as exp(-2 G t / m c_p), G from Eqs. 2-4")
def pp_contact_two_spheres():
    d = 1.99 * R
    model = build_model(spec(["pp_contact"]))
    G = 2 * model.c_pp * 2.0 * math.sqrt(R**2 - d**2 / 4)
    error = _relaxation_error(["pp_contact"], np.array([[0, 0, 0], [d, 0, 0]]), [350.0, 450.0], None, 2 * G / (model.mass * 1000.0))
    return error, 2.5e-3  # first-order explicit scheme, 1000 steps per time constant


@case("pw_contact_sphere_plane", "a sphere on a Dirichlet plane relaxes as exp(-G t / m c_p), G from Eqs. 5-7")
def pw_contact_sphere_plane():
    d = 0.99 * R
    walls = plane_walls()
    model = build_model(spec(["pw_contact"]), walls)
    G = contact.pw_conductivity(2.0, 14.5) * model.c_pw * math.sqrt(R**2 - d**2)
    error = _relaxation_error(["pw_contact"], np.array([[1e-3, 1e-3, d]]), [300.0], walls, G / (model.mass * 1000.0))
    return error, 2.5e-3


@case("energy_balance", "sum of particle energy changes equals the wall heat (all conduction modes, T-dependent c_p)")
def energy_balance():
    s = spec(CONDUCTION, walls={"hot": {"temperature": 900.0}})
    s["particles"]["specific_heat"] = "271.5 * T_C**0.1719"
    model = build_model(s, plane_walls())
    h = model.enthalpy.enthalpy(np.random.default_rng(1).uniform(300, 700, 400))
    before = math.fsum(h)
    _, _, reports = advance(model, random_cluster(), h, 0.05, 5)
    gained = model.mass * (math.fsum(h) - before)
    wall = 0.05 * math.fsum(np.concatenate([r.element_heat.ravel() for r in reports]))
    return abs(gained - wall) / abs(wall), 1e-12


@case("maximum_principle", "no particle leaves [min, max] of initial and wall temperatures, even with sub-steps")
def maximum_principle():
    model = build_model(spec(CONDUCTION, walls={"hot": {"temperature": 600.0}}), plane_walls())
    h = model.enthalpy.enthalpy(np.random.default_rng(5).uniform(300, 400, 400))
    advance(model, random_cluster(seed=4), h, 5.0, 6)
    T = model.enthalpy.temperature(h)
    return max(300.0 - T.min(), T.max() - 600.0, 0.0), 1e-9


@case("cell_list_brute_force", "pairs from the periodic cell list equal an all-pairs search (count of differences)")
def cell_list_brute_force():
    box = np.array([0.02, 0.015, 0.03])
    pos = np.random.default_rng(0).random((3000, 3)) * box
    cut = 0.0021
    found = set(zip(*pairs(build(pos, cut, box_lo=np.zeros(3), box_hi=box, periodic=(True, False, True)), cut)))
    found = {(min(a, b), max(a, b)) for a, b in found}
    reference = set(zip(*brute_force_pairs(pos, cut, box_lo=np.zeros(3), box_hi=box, periodic=(True, False, True))))
    return len(found ^ reference), 0
