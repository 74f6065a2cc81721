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
