"""Thermal-stage cases: relaxations with exact solutions, conservation, the maximum principle.

The relaxations compare with the explicit scheme's exact solution, which pins the conductance to
round-off (any error in G shows at once), and the first-order case compares with the exponential
solution of the ODE, which the scheme approaches as the step shrinks. The conductances are written
out from the paper's equations and the scene's spec, not taken from the thermal model.
"""

import math

import numpy as np

from dpht.closures import contact
from dpht.thermal import integrate
from dpht.thermal.neighbors import brute_force_pairs, build, pairs
from dpht.verification.scenes import RADIUS as R, advance, build_model, plane_walls, random_cluster, spec
from dpht.verification.harness import case

CONDUCTION = ["pp_contact", "pw_contact", "pfp", "pfw"]


def _capacity(s) -> float:
    """Heat capacity m c_p (J/K) of one particle of a scene with a constant specific heat."""
    p = s["particles"]
    return p["density"] * 4.0 / 3.0 * math.pi * R**3 * p["specific_heat"]


def two_spheres(distance: float, modes=("pp_contact",)):
    """Two equal spheres ``distance`` (m) apart: the scene, the thermal model, their positions and
    their contact conductance (:func:`two_sphere_conductance`)."""
    s = spec(list(modes))
    return s, build_model(s), np.array([[0.0, 0.0, 0.0], [distance, 0.0, 0.0]]), two_sphere_conductance(s, distance)


def two_sphere_conductance(s, distance: float) -> float:
    """Contact conductance G = 2 c_pp k_p sqrt(R^2 - d^2/4) (W/K, DPHT Eqs. 2-4) of two equal
    spheres of scene ``s`` (constant conductivity) ``distance`` (m) apart."""
    p = s["particles"]
    return 2.0 * contact.c_pp(p["youngs_modulus_dem"], p["youngs_modulus_real"]) * p["conductivity"] * math.sqrt(R**2 - distance**2 / 4)


def two_sphere_gap(gap: float, G: float, C: float, dt: float, steps: int, implicit: bool = False) -> float:
    """Temperature difference (K) of two equal spheres of heat capacity ``C`` (J/K) joined by a
    constant conductance ``G`` (W/K), ``gap`` K at the start, after ``steps`` steps of ``dt`` (s):
    the exact solution of the explicit scheme, which multiplies the gap by 1 - 2 G dt / C at every
    step, or with ``implicit`` of backward Euler, which divides it by 1 + 2 G dt / C."""
    if implicit:
        return gap / (1.0 + 2.0 * G * dt / C) ** steps
    return gap * (1.0 - 2.0 * G * dt / C) ** steps


def _gap(model, h) -> float:
    T = model.enthalpy.temperature(h)
    return float(T[1] - T[0])


@case("pp_contact_two_spheres", "two overlapping spheres: T gap after n steps = (1 - 2 G dt / m c_p)^n, G from Eqs. 2-4")
def pp_contact_two_spheres():
    s, model, positions, G = two_spheres(1.99 * R)
    C = _capacity(s)
    h = model.enthalpy.enthalpy(np.array([350.0, 450.0]))
    dt, steps = 0.005 * C / G, 400
    advance(model, positions, h, dt, steps)
    exact = two_sphere_gap(100.0, G, C, dt, steps)
    mean = float(model.enthalpy.temperature(h).mean())
    return max(abs(_gap(model, h) / exact - 1.0), abs(mean / 400.0 - 1.0)), 1e-10


@case("pp_contact_first_order", "two spheres: error against exp(-2 G t / m c_p) halves with the step (|ratio - 2|)",
      "ratio offset")
def pp_contact_first_order():
    s, model, positions, G = two_spheres(1.98 * R)
    C = _capacity(s)
    t_end = C / G
    errors = []
    for steps in (20, 40, 80):
        h = model.enthalpy.enthalpy(np.array([300.0, 500.0]))
        advance(model, positions, h, t_end / steps, steps)
        errors.append(abs(_gap(model, h) - 200.0 * math.exp(-2.0 * G * t_end / C)))
    return max(abs(errors[0] / errors[1] - 2.0), abs(errors[1] / errors[2] - 2.0)), 0.2


@case("pw_contact_sphere_plane", "sphere on a Dirichlet plane: excess = (1 - G dt / m c_p)^n, G from Eqs. 5-7; wall heat = m c_p dT")
def pw_contact_sphere_plane():
    s = spec(["pw_contact"], walls={"hot": {"temperature": 600.0}})
    p, w = s["particles"], s["wall"]
    model = build_model(s, plane_walls())
    d = 0.99 * R
    softening = contact.c_pw(p["poisson_ratio"], p["youngs_modulus_real"], p["youngs_modulus_dem"],
                             w["poisson_ratio"], w["youngs_modulus_real"], w["youngs_modulus_dem"])  # fmt: skip
    G = contact.pw_conductivity(p["conductivity"], w["conductivity"]) * softening * math.sqrt(R**2 - d**2)
    C = _capacity(s)
    h = model.enthalpy.enthalpy(np.array([300.0]))
    dt, steps = 0.1 * C / G, 25
    _, _, reports = advance(model, np.array([[0.001, 0.0013, d]]), h, dt, steps)
    T = float(model.enthalpy.temperature(h)[0])
    heat = math.fsum(r.element_heat.sum() for r in reports) * dt
    exact = 300.0 * (1.0 - G * dt / C) ** steps
    return max(abs((600.0 - T) / exact - 1.0), abs(heat / (C * (T - 300.0)) - 1.0)), 1e-10


@case("energy_balance", "every frame, particle energy change = wall heat (all conduction modes, T-dependent c_p)")
def energy_balance():
    s = spec(CONDUCTION, walls={"hot": {"temperature": 900.0}})
    s["particles"]["specific_heat"] = "271.5 * T_C**0.1719"
    model = build_model(s, plane_walls())
    h = model.enthalpy.enthalpy(np.random.default_rng(1).uniform(300, 700, 400))
    frame, rates, _ = advance(model, random_cluster(), h, 0.0, 1)
    error = 0.0
    for _ in range(5):
        before = math.fsum(h)
        report = integrate.advance(model, frame, h, 0.05, rates)
        gained = model.mass * (math.fsum(h) - before)
        wall = 0.05 * math.fsum(report.element_heat.ravel())
        error = max(error, abs(gained - wall) / abs(wall))
    return error, 1e-12


@case("maximum_principle", "no particle leaves [min, max] of initial and wall temperatures with a step needing sub-steps",
      "K")
def maximum_principle():
    model = build_model(spec(CONDUCTION, walls={"hot": {"temperature": 600.0}}), plane_walls())
    h = model.enthalpy.enthalpy(np.random.default_rng(5).uniform(300, 400, 400))
    _, _, reports = advance(model, random_cluster(seed=4), h, 5.0, 6)  # far beyond the explicit limit
    T = model.enthalpy.temperature(h)
    if not all(r.substeps > 1 for r in reports) or not T.mean() > 300.0:
        return math.inf, 1e-9  # the case did not test what it claims: no sub-steps, or no heating
    return max(300.0 - T.min(), T.max() - 600.0, 0.0), 1e-9


@case("cell_list_brute_force", "pairs from the periodic cell list equal an all-pairs search (count of differences)",
      "pairs")
def cell_list_brute_force():
    box = np.array([0.02, 0.015, 0.03])
    pos = np.random.default_rng(0).random((3000, 3)) * box
    cut = 0.0021
    found = set(zip(*pairs(build(pos, cut, box_lo=np.zeros(3), box_hi=box, periodic=(True, False, True)), cut)))
    found = {(min(a, b), max(a, b)) for a, b in found}
    reference = set(zip(*brute_force_pairs(pos, cut, box_lo=np.zeros(3), box_hi=box, periodic=(True, False, True))))
    return len(found ^ reference), 0


@case("sheared_cell_list_brute_force", "pairs from the cell list of a sheared periodic box (tilt 0.37 of its x length) "
      "equal an all-pairs nearest-image search (count of differences)", "pairs")
def sheared_cell_list_brute_force():
    box = np.array([0.02, 0.015, 0.012])
    pos = np.random.default_rng(1).random((3000, 3)) * box
    cut, tilt, periodic = 0.0021, 0.37 * box[0], (True, True, True)
    found = set(zip(*pairs(build(pos, cut, box_lo=np.zeros(3), box_hi=box, periodic=periodic, tilt=tilt), cut)))
    found = {(min(a, b), max(a, b)) for a, b in found}
    reference = set(zip(*brute_force_pairs(pos, cut, box_lo=np.zeros(3), box_hi=box, periodic=periodic, tilt=tilt)))
    return len(found ^ reference), 0
