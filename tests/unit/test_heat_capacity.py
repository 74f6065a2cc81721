"""Enthalpy tables: exact integrals, exact inverse, clear errors."""

import numpy as np
import pytest
from scipy.integrate import quad

from dpht.closures import heat_capacity
from dpht.errors import ConfigError


def test_enthalpy_of_the_paper_fit_against_quadrature():
    cp = heat_capacity.specific_heat("271.5 * T_C**0.1719")
    table = heat_capacity.build(cp, 303.15, 1073.15)
    for T in (310.0, 555.5, 1070.0):
        exact = quad(lambda t: 271.5 * (t - 273.15) ** 0.1719, table.T0, T, epsabs=0, epsrel=1e-13)[0]
        # Linear interpolation between nodes: error <= dT^2 max|cp'| / 8 (cp' is largest at the low end).
        bound = table.dT**2 / 8 * 271.5 * 0.1719 * (table.T0 - 273.15) ** (0.1719 - 1)
        assert abs(table.enthalpy(T) - exact) <= bound
    nodes = table.T0 + table.dT * np.arange(table.h.size)
    exact_nodes = np.array([quad(lambda t: 271.5 * (t - 273.15) ** 0.1719, table.T0, T, epsrel=1e-13)[0] for T in nodes[::400]])
    np.testing.assert_allclose(table.h[::400], exact_nodes, rtol=1e-11, atol=1e-9)


def test_inverse_round_trips_and_constant_cp_is_linear():
    table = heat_capacity.build(heat_capacity.specific_heat(1000.0), 300.0, 900.0)
    T = np.linspace(296, 904, 1001)
    np.testing.assert_allclose(table.temperature(table.enthalpy(T)), T, rtol=0, atol=1e-9)
    assert table.enthalpy(600.0) - table.enthalpy(400.0) == pytest.approx(1000.0 * 200.0, rel=1e-12)
    assert table.cp_min == pytest.approx(1000.0)


def test_non_positive_specific_heat_is_rejected_with_the_key():
    cp = heat_capacity.specific_heat("271.5 * T_C**0.1719")
    with pytest.raises(ConfigError, match=r"particles.specific_heat.*> 0"):
        heat_capacity.build(cp, 250.0, 400.0)  # T_C < 0: the fit is undefined there


def test_guided_inversion_equals_a_binary_search():
    """T(h) through the guide table is the exact inverse of the interpolant, as a search gives it,
    at, between and beyond the nodes."""
    table = heat_capacity.build(heat_capacity.specific_heat("271.5 * T_C**0.1719"), 300.0, 1200.0)
    rng = np.random.default_rng(5)
    h = np.concatenate([rng.uniform(-0.1, 1.1, 20000) * table.h[-1], table.h, np.nextafter(table.h, np.inf)])
    k = np.clip(np.searchsorted(table.h, h) - 1, 0, table.h.size - 2)
    f = np.clip((h - table.h[k]) / (table.h[k + 1] - table.h[k]), 0.0, 1.0)
    np.testing.assert_array_equal(table.temperature(h), table.T0 + (k + f) * table.dT)
    np.testing.assert_array_equal(table.temperature_rows(h, np.arange(h.size)[::-1]), table.temperature(h[::-1]))
