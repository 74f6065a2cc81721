"""The schema's defaults as code reads them (dpht.defaults): the values validation fills in."""

import pytest

from dpht import config, defaults
from dpht.defaults import default, setting
from test_config import DEFAULT


def _filled(raw: dict, full: dict, prefix=()):
    """Dotted keys and values of the settings validation added to ``raw`` (the config as written);
    of a mapping it added, each setting in it."""
    for key, value in full.items():
        if isinstance(value, dict) and key != "variants":
            if isinstance(raw.get(key, {}), dict):
                yield from _filled(raw.get(key, {}), value, (*prefix, key))
        elif key not in raw:
            yield ".".join((*prefix, key)), value


def test_every_default_validation_fills_is_the_one_code_reads():
    raw = config.read_yaml(DEFAULT)
    for section, keys in {"thermal": ("checkpoint_frames", "checkpoint_minutes", "modes", "integrator", "implicit"),
                          "dem": ("fill_solid_fraction", "tube_wall")}.items():  # fmt: skip
        for key in keys:
            raw[section].pop(key, None)
    raw.pop("figures", None)
    raw["thermal"]["frozen_bed"] = {"duration": 1.0, "step": 0.5}  # sections filled only where present
    raw["thermal"]["slice"] = {"inlet_height": 0.1, "distance": 0.1}
    filled = dict(_filled(raw, config.validate(raw)))
    assert {"thermal.checkpoint_frames", "thermal.modes.pfp", "thermal.implicit.scheme", "thermal.frozen_bed.frame",
            "thermal.slice.frames", "dem.fill_solid_fraction", "figures.steady_window"} <= filled.keys()  # fmt: skip
    for key, value in filled.items():
        assert default(key) == value, key


def test_a_default_beside_a_shared_definition_and_one_from_it():
    assert default("dem.drive.time_constant") == 0.005  # written next to its $ref to "positive"
    assert default("thermal.modes.pfp") == "auto"  # the "switch" definition's


def test_a_section_value_wins_and_unknown_keys_are_named():
    assert setting({"frames": "wrap"}, "thermal.slice.frames") == "wrap"
    assert setting({}, "thermal.slice.frames") == "mirror"
    with pytest.raises(KeyError, match="thermal.no_such_key: not a key"):
        default("thermal.no_such_key")
    with pytest.raises(KeyError, match="dem.timestep: the config schema gives no default"):
        default("dem.timestep")


def test_validation_and_the_defaults_read_one_schema():
    """The schema file is read once: validation fills in the very values :func:`default` reads."""
    assert config.schema() is defaults.schema()
