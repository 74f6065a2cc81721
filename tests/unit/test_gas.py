"""Gas conductivity tables (dpht.closures.gas): nodes, interpolation shape, range checks, user tables."""

import numpy as np
import pytest

from dpht.closures import gas
from dpht.errors import DPHTError

# Independent source: CRC Handbook of Chemistry and Physics, "Thermal conductivity of gases",
# in 1e-3 W/(m K). The module's tables come from Incropera Table A.4 and NIST SRD 134.
CRC = {
    "air": {300: 26.2, 400: 33.3, 500: 39.7, 600: 45.7},
    "nitrogen": {100: 9.8, 200: 18.7, 300: 26.0, 400: 32.3, 500: 38.3, 600: 44.0},
    "co2": {300: 16.8, 400: 25.1, 500: 33.5, 600: 41.6},
    "helium": {100: 75.5, 200: 119.3, 300: 156.7, 400: 190.6, 500: 222.3, 600: 252.4},
}


@pytest.mark.parametrize("name", gas.GASES)
def test_interpolation_reproduces_table_nodes(name):
    temperature, k = gas.table(name)
    assert np.allclose(gas.conductivity(name, temperature), k, rtol=1e-14, atol=0)
    assert gas.valid_range(name) == (temperature[0], temperature[-1])


@pytest.mark.parametrize("name", gas.GASES)
def test_interpolation_is_monotone_between_nodes(name):
    """All four tables increase with T; the interpolant must not overshoot between nodes."""
    temperature, k = gas.table(name)
    assert np.all(np.diff(k) > 0)
    fine = np.linspace(temperature[0], temperature[-1], 5000)
    assert np.all(np.diff(gas.conductivity(name, fine)) > 0)


@pytest.mark.parametrize("name", gas.GASES)
def test_tables_agree_with_crc_handbook(name):
    """Catches a mistyped entry: every table is within 3.5 % of an independent compilation."""
    points = {t: v for t, v in CRC[name].items() if gas.valid_range(name)[0] <= t <= gas.valid_range(name)[1]}
    assert len(points) >= 4
    temperature = np.array(list(points))
    reference = np.array(list(points.values())) * 1e-3
    assert np.max(np.abs(gas.conductivity(name, temperature) / reference - 1)) < 0.035


def test_vectorised_and_scalar():
    t = np.array([[300.0, 400.0], [500.0, 600.0]])
    k = gas.conductivity("air", t)
    assert k.shape == (2, 2)
    assert isinstance(gas.conductivity("air", 300.0), float)
    assert k[0, 0] == pytest.approx(0.0263)


def test_user_table_reproduces_linear_data():
    """Monotone cubic interpolation is exact for linear data."""
    table = {"temperature": [200.0, 450.0, 700.0, 1600.0], "conductivity": [0.01, 0.035, 0.06, 0.15]}
    t = np.linspace(200.0, 1600.0, 57)
    assert np.allclose(gas.conductivity(table, t), 1e-4 * t - 0.01, rtol=1e-12)
    assert gas.valid_range(table) == (200.0, 1600.0)


@pytest.mark.parametrize("name, temperature", [("air", 249.0), ("air", 1501.0), ("co2", 900.0), ("helium", 1100.0)])
def test_out_of_range_raises_with_gas_and_range(name, temperature):
    with pytest.raises(DPHTError) as err:
        gas.conductivity(name, [300.0, temperature])
    low, high = gas.valid_range(name)
    assert name in str(err.value) and f"{low:g}-{high:g} K" in str(err.value)


@pytest.mark.parametrize(
    "bad",
    [
        "argon",
        {"temperature": [300.0, 400.0]},
        {"temperature": [400.0, 300.0], "conductivity": [0.03, 0.02]},
        {"temperature": [300.0, 400.0], "conductivity": [0.03, -0.02]},
        {"temperature": [300.0], "conductivity": [0.03]},
        3.5,
    ],
)
def test_bad_gas_raises(bad):
    with pytest.raises(DPHTError, match="gas"):
        gas.conductivity(bad, 350.0)


# Incropera Table A.4 at 300 K: viscosity [1e-7 Pa s], c_p [kJ/(kg K)]; molar mass [g/mol]. The
# module derives its molecular constants from these (module docstring).
INCROPERA_300K = {"air": (184.6, 1.007, 28.97), "nitrogen": (178.2, 1.041, 28.01), "co2": (149.0, 0.851, 44.01),
                  "helium": (199.0, 5.193, 4.003)}
AVOGADRO = 6.02214076e23


@pytest.mark.parametrize("name", gas.GASES)
def test_molecular_data_follow_from_their_sources(name):
    """Catches a mistyped constant: each is recomputed from the data and relations the docstring cites."""
    mu, c_p, molar_mass = INCROPERA_300K[name]
    m = gas.molecular(name)
    mass = molar_mass * 1e-3 / AVOGADRO
    # Hard-sphere viscosity (Chapman-Enskog, first approximation) at 300 K gives the diameter.
    sigma = np.sqrt(5 / 16 * np.sqrt(np.pi * mass * gas.BOLTZMANN * 300.0) / (np.pi * mu * 1e-7))
    assert m.collision_diameter == pytest.approx(sigma, rel=0.003)
    gamma = c_p / (c_p - 8.314462618 / molar_mass)
    assert m.heat_capacity_ratio == pytest.approx(gamma, rel=0.005)
    # Eucken's relation Pr = 4 gamma / (9 gamma - 5) holds for these gases within 5 %.
    assert m.prandtl == pytest.approx(4 * gamma / (9 * gamma - 5), rel=0.05)
    # Song & Yovanovich (1987) at a 300 K iron surface, T_0 = 273 K.
    star = molar_mass * (1.0 if name == "helium" else 1.4)
    ratio = molar_mass / 55.85
    e = np.exp(-0.57 * (300.0 - 273.0) / 273.0)
    assert m.accommodation == pytest.approx(e * star / (6.8 + star) + 2.4 * ratio / (1 + ratio) ** 2 * (1 - e), abs=0.005)


def test_mean_free_path_of_air_matches_published_value():
    """Jennings (1988, J. Aerosol Sci. 19:159): 66.5 nm in air at 23 C and 101.325 kPa."""
    assert gas.mean_free_path("air", 296.15, gas.ATMOSPHERE) == pytest.approx(66.5e-9, rel=0.03)


def test_jump_distance_scales_as_kinetic_theory_says():
    g = gas.jump_distance("nitrogen", 400.0, 2000.0, 0.5)
    assert gas.jump_distance("nitrogen", 800.0, 2000.0, 0.5) == pytest.approx(2 * g, rel=1e-14)  # Lambda ~ T
    assert gas.jump_distance("nitrogen", 400.0, 4000.0, 0.5) == pytest.approx(g / 2, rel=1e-14)  # Lambda ~ 1/p
    assert gas.jump_distance("nitrogen", 400.0, 2000.0, 1.0) == pytest.approx(g / 3, rel=1e-14)  # (2 - a)/a
    m = gas.MOLECULAR["nitrogen"]
    factor = 2 * m.heat_capacity_ratio / (m.heat_capacity_ratio + 1) / m.prandtl * 3  # a = 0.5
    assert g == pytest.approx(factor * gas.mean_free_path("nitrogen", 400.0, 2000.0), rel=1e-14)
    # Air at 1 atm: the jump distances are a fraction of a micrometre, 1000 Pa a hundred times more.
    assert 0.1e-6 < gas.jump_distance("air", 300.0, gas.ATMOSPHERE, 0.84) < 0.2e-6
    assert gas.mean_free_path("helium", 300.0, gas.ATMOSPHERE) > 2.5 * gas.mean_free_path("air", 300.0, gas.ATMOSPHERE)


def test_user_gas_table_gives_molecular_data_or_is_refused():
    table = {"temperature": [200.0, 1600.0], "conductivity": [0.01, 0.15]}
    with pytest.raises(DPHTError, match="has no 'collision_diameter', 'prandtl'"):
        gas.molecular(table | {"heat_capacity_ratio": 1.4})
    data = table | {"collision_diameter": 3.6e-10, "heat_capacity_ratio": 1.4, "prandtl": 0.7}
    assert gas.molecular(data) == gas.Molecular(3.6e-10, 1.4, 0.7, None)
    assert gas.molecular(data | {"accommodation": 0.8}).accommodation == 0.8
    # The same gamma as air's: the jump scales as 1/(sigma^2 Pr).
    assert gas.jump_distance(data, 300.0, 1e5, 0.84) == pytest.approx(
        gas.jump_distance("air", 300.0, 1e5, 0.84) * (3.67 / 3.6) ** 2 * 0.707 / 0.7, rel=1e-12)
    for key, value in (("collision_diameter", 0.0), ("heat_capacity_ratio", 1.0), ("heat_capacity_ratio", 1.8),
                       ("prandtl", "high"), ("accommodation", 1.2)):
        with pytest.raises(DPHTError, match=key):
            gas.molecular(data | {key: value})
