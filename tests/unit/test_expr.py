"""Config expressions are parsed safely and evaluated on arrays."""

import numpy as np
import pytest

from dpht.errors import ConfigError
from dpht.thermal import model
from dpht.util.expr import parse
from dpht.verification import scenes


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


@pytest.mark.parametrize("text", ["1073.15 + 1/0", "9**9**9", "10**400", "1e400", "sqrt(-1) + 900", "log(0)"])
def test_constants_that_overflow_or_divide_by_zero_are_named_not_raised(text):
    """Issue 11, item 5: these gave bare ZeroDivisionError / OverflowError tracebacks."""
    expression = parse(text, ("x", "y", "z"), "thermal.walls.heated_wall.temperature")
    with pytest.raises(ConfigError) as err:
        expression.checked("a finite temperature > 0 K", minimum=0.0, x=np.zeros(4), y=np.zeros(4), z=np.zeros(4))
    message = str(err.value)
    assert message.startswith("thermal.walls.heated_wall.temperature: expression")
    assert "at 4 of 4 points" in message and "expected a finite temperature > 0 K" in message


def test_the_first_bad_element_is_named_with_its_value():
    """Division by zero at some elements: the message names where, not a valid value elsewhere."""
    z = np.linspace(0.0, 0.04, 41)
    expression = parse("1000 + 1/(z - 0.02) - 1/(z - 0.02)", ("x", "y", "z"), "thermal.walls.w.temperature")
    with pytest.raises(ConfigError, match=r"gives nan at 1 of 41 points, the first at x = 0, y = 0, z = 0.02;"):
        expression.checked("a finite temperature", x=0 * z, y=0 * z, z=z)
    fine = parse("1000 - 1e4 * z", ("x", "y", "z"), "k").checked("a temperature > 0", minimum=0.0, x=0, y=0, z=z)
    np.testing.assert_allclose(fine, 1000 - 1e4 * z)


def test_wall_temperatures_name_the_element():
    walls = scenes.plane_walls(zone="hot")
    message = r"thermal.walls.hot.temperature: .* gives inf at 64 of 128 points, the first at x = 0.0"
    with pytest.raises(ConfigError, match=message):
        model.wall_temperatures(walls, {"hot": {"temperature": "where(x > 0, 1/0, 600)"}})


@pytest.mark.parametrize(
    "text, message",
    [
        ("min(T)", r"min\(\) takes 2 arguments, got 1"),
        ("where(T > 1, 2)", r"where\(\) takes 3 arguments, got 2"),
        ("sqrt + T", "function 'sqrt' used without calling it"),
        ("sqrt(*T)", "Starred is not allowed"),
        ("1 +" * 100 + "1", "nested more than 60 levels"),
        ("T" * 3000, "3000 characters; at most 2000"),
        ("T\x00", "null bytes"),
        ("1 < T < 2", "single comparisons"),
        (1e400, "expected a finite number"),
        (10**400, "expected a finite number"),
    ],
    ids=lambda v: repr(v)[:20],
)
def test_malformed_expressions_are_refused_at_parse_time(text, message):
    with pytest.raises(ConfigError, match=message):
        parse(text, ("T",), "particles.specific_heat")


def test_comparisons_take_part_in_arithmetic():
    assert parse("-(T < 3) + 2 * (T >= 3)", ("T",), "k")(T=np.array([1.0, 5.0])).tolist() == [-1.0, 2.0]


def test_shifted_is_the_same_function_in_moved_coordinates():
    from dpht.util.expr import shifted

    text = "-995.70*z**3 + 381.44*z**2 - 657.96*z + 1057.8 + 0*x"
    moved = shifted(text, "z", -0.019, ("x", "y", "z"), "k")
    z = np.linspace(0.0, 0.05, 11)
    original, here = parse(text, ("x", "y", "z"), "k"), parse(moved, ("x", "y", "z"), "k")
    assert np.allclose(here(x=0.1, y=0.0, z=z), original(x=0.1, y=0.0, z=z - 0.019), rtol=1e-15)
    assert shifted(773.15, "z", 0.5, ("x", "y", "z"), "k") == 773.15 and shifted(text, "z", 0.0, ("x", "y", "z"), "k") == text
    with pytest.raises(ConfigError, match="k: cannot parse"):
        shifted("600 + ", "z", 0.5, ("x", "y", "z"), "k")
