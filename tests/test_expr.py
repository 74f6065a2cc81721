"""Config expressions are parsed safely and evaluated on arrays."""

import numpy as np
import pytest

from dpht.errors import ConfigError
from dpht.util.expr import parse


def test_paper_profiles_evaluate():
    eq30 = parse("-995.70*z**3 + 381.44*z**2 - 657.96*z + 1057.8", ("x", "y", "z"), "thermal.walls.w.temperature")
    z = np.array([0.0, 0.3])
    assert eq30(x=0, y=0, z=z) == pytest.approx(-995.70 * z**3 + 381.44 * z**2 - 657.96 * z + 1057.8)
    cp = parse("271.5 * T_C**0.1719", ("T", "T_C"), "particles.specific_heat")
    assert cp(T=0, T_C=100.0) == pytest.approx(271.5 * 100**0.1719)
    assert parse(500, ("x",), "k")(x=np.zeros(3)).tolist() == [500.0] * 3
    assert parse("where(z > 0.1, 800, sqrt(250000))", ("z",), "k")(z=np.array([0.0, 0.2])).tolist() == [500.0, 800.0]


@pytest.mark.parametrize(
    "text, message",
    [
        ("__import__('os').system('true')", "not allowed"),
        ("open('x')", "function 'open' not allowed"),
        ("T.real", "Attribute is not allowed"),
        ("1 +", "cannot parse"),
        ("Tc * 2", "unknown name 'Tc'"),
        ("'abc'", "only numbers"),
        ("1 if T else 2", "IfExp is not allowed"),
        ("[T]", "List is not allowed"),
        ("T // 2", "FloorDiv not allowed"),
    ],
)
def test_rejected_with_the_key_named(text, message):
    with pytest.raises(ConfigError, match=message) as err:
        parse(text, ("T", "T_C"), "particles.specific_heat")
    assert "particles.specific_heat" in str(err.value)


def test_non_string_values_rejected():
    for value in (True, None, [1]):
        with pytest.raises(ConfigError, match="particles.specific_heat"):
            parse(value, ("T",), "particles.specific_heat")
