"""Resolved intra-particle conduction (dpht.thermal.intraparticle): conservation, the lumped limit,
threads. The cooled-sphere case against the analytic series is a verification case
(dpht.verification.cases.intraparticle), run by tests/unit/test_verification.py."""

import math

import numpy as np
import pytest

from dpht.closures import heat_capacity
from dpht.thermal import intraparticle as ip
from dpht.util.interp import Table1D
from dpht.verification import scenes

RADIUS, DENSITY = 5e-4, 2500.0
MASS = DENSITY * 4.0 / 3.0 * math.pi * RADIUS**3


def _enthalpy(cp="271.5 * T_C**0.1719"):
    return heat_capacity.build(heat_capacity.specific_heat(cp), 290.0, 1300.0)


def _k_table(values=(1.0, 3.0)):
    return Table1D(250.0, 1050.0 / (len(values) - 1), np.asarray(values, dtype=float))


def _run(H, rows, q, dt, steps, shells, surface, enthalpy, k_table, iterations=1):
    convected = np.zeros(rows.size)
    ip.advance(H, rows, q, dt, steps, MASS, shells, surface, *enthalpy.arrays, k_table, iterations, convected)
    return convected


def test_the_capacities_hold_the_sphere_s_mass_and_the_outer_node_is_the_surface():
    for n in (2, 3, 5, 10, 33):
        g = ip.grid(RADIUS, n)
        assert math.isclose(g.weight.sum(), 1.0, rel_tol=1e-14) and np.all(g.weight > 0)
        assert np.allclose(g.capacity_matrix().sum(axis=0), g.weight, rtol=1e-14, atol=0)
        assert math.isclose(g.nodes[-1], RADIUS, rel_tol=1e-15) and math.isclose(g.nodes[0], RADIUS / n, rel_tol=1e-15)
    # as quadrature weights of the sphere they are fourth order: the mean of (r/a)^2 is 3/5
    error = [ip.grid(RADIUS, n).weight @ (ip.grid(RADIUS, n).nodes / RADIUS) ** 2 - 0.6 for n in (10, 20)]
    assert 15.0 < error[0] / error[1] < 17.0
    with pytest.raises(ValueError, match="at least 2 shells"):
        ip.grid(RADIUS, 1)


def test_one_step_is_backward_euler_of_the_capacity_and_conductance_matrices():
    """Constant properties: the kernel's step (elimination with the corner entry) is the dense
    solve of sum_j C_kj c_p (T'_j - T_j) = dt (conduction + Robin) at T'."""
    enthalpy, k = _enthalpy(900.0), 1.7
    for n in (2, 3, 4, 9):
        g = ip.grid(RADIUS, n)
        T = np.linspace(700.0, 400.0, n)
        H = enthalpy.enthalpy(T)[None, :].copy()
        A = np.zeros((n, n))
        for f in range(n - 1):
            A[np.ix_([f, f + 1], [f, f + 1])] += k * g.face[f] * np.array([[1.0, -1.0], [-1.0, 1.0]])
        hA = 300.0 * g.surface_area
        A[-1, -1] += hA
        b = np.zeros(n)
        b[-1] = hA * 350.0 + 0.02
        dt = 0.003
        C = MASS * 900.0 * g.capacity_matrix()
        expected = np.linalg.solve(C / dt + A, C @ T / dt + b)
        _run(H, np.arange(1), np.array([0.02]), dt, 1, g, ip.Surface(300.0, 350.0), enthalpy, _k_table((k, k)))
        assert np.allclose(enthalpy.temperature(H[0]), expected, rtol=1e-12, atol=0)


@pytest.mark.parametrize("iterations", [1, 3])
def test_energy_change_equals_surface_heat(iterations):
    """T-dependent c_p and k, random profiles, surface heat and convection: sum m_k dh_k = dt (q + Robin)."""
    enthalpy, shells = _enthalpy(), ip.grid(RADIUS, 10)
    rng = np.random.default_rng(3)
    H = enthalpy.enthalpy(rng.uniform(400.0, 1000.0, (50, 10)))
    rows = np.arange(0, 50, 2)
    q = rng.uniform(-0.05, 0.05, rows.size)
    before = H.copy()
    dt, steps = 0.01, 7
    convected = _run(H, rows, q, dt, steps, shells, ip.Surface(80.0, 500.0), enthalpy, _k_table(), iterations)
    gained = MASS * ((H - before) @ shells.weight)
    expected = dt * steps * q + convected
    assert np.all(np.abs(gained[rows] - expected) <= 1e-12 * np.abs(expected))
    assert np.array_equal(H[1::2], before[1::2])  # rows not listed are untouched
    assert np.all(np.abs(convected) > 0)


def test_uniform_particle_without_heat_stays_uniform():
    enthalpy, shells = _enthalpy(), ip.grid(RADIUS, 8)
    H = np.full((3, 8), enthalpy.enthalpy(600.0)[()])
    before = H.copy()
    _run(H, np.arange(3), np.zeros(3), 0.1, 20, shells, ip.NO_CONVECTION, enthalpy, _k_table())
    assert np.allclose(H, before, rtol=1e-12, atol=0.0)  # round-off of the solve only


def test_maximum_principle_with_constant_properties():
    """Backward Euler on an M-matrix: no shell leaves [min initial, T_gas] when the particle is cooled."""
    enthalpy, shells = _enthalpy(1000.0), ip.grid(RADIUS, 12)
    rng = np.random.default_rng(5)
    H = enthalpy.enthalpy(rng.uniform(600.0, 900.0, (20, 12)))
    _run(H, np.arange(20), np.zeros(20), 0.5, 40, shells, ip.Surface(5000.0, 400.0), enthalpy, _k_table((2.0, 2.0)))
    T = enthalpy.temperature(H)
    assert T.min() >= 400.0 - 1e-9 and T.max() <= 900.0 + 1e-9


def test_lumped_limit_at_small_biot_number():
    """With Bi = h d / k -> 0 the resolved particle cools like a lumped one, the difference ~ Bi."""
    enthalpy, shells = _enthalpy(1000.0), ip.grid(RADIUS, 10)
    h_conv, T_gas, T_start = 200.0, 300.0, 800.0
    capacity = MASS * 1000.0
    dt, steps = 0.01, 300
    # Backward Euler on the lumped particle: (T' - T_gas) = (T - T_gas) / (1 + dt h A / m c)
    ratio = 1.0 / (1.0 + dt * h_conv * shells.surface_area / capacity)
    lumped = T_gas + (T_start - T_gas) * ratio**steps
    differences = []
    for k in (1.0, 10.0, 100.0):
        H = np.full((1, 10), enthalpy.enthalpy(T_start)[()])
        _run(H, np.arange(1), np.zeros(1), dt, steps, shells, ip.Surface(h_conv, T_gas), enthalpy, _k_table((k, k)))
        mean = float(enthalpy.temperature(H[0] @ shells.weight))
        differences.append(abs(mean - lumped) / (T_start - lumped))
    biot = [h_conv * 2 * RADIUS / k for k in (1.0, 10.0, 100.0)]
    assert differences[2] < 1e-4  # Bi = 2e-3
    for (d_hi, d_lo), (b_hi, b_lo) in zip(zip(differences, differences[1:]), zip(biot, biot[1:])):
        assert 0.5 < (d_hi / d_lo) / (b_hi / b_lo) < 1.5  # first order in Bi


def test_identical_for_one_and_two_threads():
    enthalpy, shells = _enthalpy(), ip.grid(RADIUS, 10)
    rng = np.random.default_rng(9)
    H0 = enthalpy.enthalpy(rng.uniform(400.0, 1000.0, (3000, 10)))
    q = rng.uniform(-0.05, 0.05, 3000)

    def once():
        H = H0.copy()
        conv = _run(H, np.arange(3000), q, 0.02, 5, shells, ip.Surface(50.0, 700.0), enthalpy, _k_table(), 2)
        return H, conv, ip.mean_enthalpy(H, shells.weight)

    results = scenes.on_threads(once)
    for a, b in zip(*results):
        assert np.array_equal(a, b)


def test_cooled_sphere_converges_at_fourth_order_in_space_and_first_in_time():
    from dpht.studies import cooled_sphere as case

    def in_space(n, dt=2e-4):  # backward Euler's first-order error cancelled between dt and dt / 2
        coarse, fine = case.simulate(n, dt), case.simulate(n, dt / 2)
        return case.errors(n, dt, [2.0 * b - a for a, b in zip(coarse, fine)]).mean()

    assert 3.6 < math.log2(in_space(4) / in_space(8)) < 4.4
    slow, fast = case.errors(9, 0.1).mean(), case.errors(9, 0.05).mean()
    assert 0.8 < math.log2(slow / fast) < 1.2


def test_verify_cooled_sphere_writes_the_profiles(tmp_path):
    import csv
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "dpht", "verify", "cooled-sphere", "--out", str(tmp_path)],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 0, done.stderr
    last = done.stdout.strip().splitlines()[-1]
    assert last.startswith("mean relative error: ") and float(last.split(": ")[1]) < 1e-5
    with open(tmp_path / "cooled_sphere.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["t", "r_over_a", "T"]
    assert {(float(r["t"]), float(r["r_over_a"])) for r in rows} == {
        (t, x) for t in (2.0, 5.0, 8.0, 10.0) for x in (0.0, 0.25, 0.5, 0.75, 1.0)
    }
    assert all(300.0 < float(r["T"]) < 800.0 for r in rows)
    for name in ("cooled_sphere_convergence.csv", "cooled_sphere.png", "cooled_sphere_convergence.png"):
        assert (tmp_path / name).stat().st_size > 0
