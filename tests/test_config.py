"""Config validation messages and the stage keys that drive caching."""

import copy
from pathlib import Path

import pytest
import yaml

from dpht import config
from dpht.errors import ConfigError

DEFAULT = Path(__file__).resolve().parent.parent / "config" / "config.yaml"


@pytest.fixture(scope="module")
def base():
    return config.load(DEFAULT)


def raw():
    return yaml.safe_load(DEFAULT.read_text())


def test_default_config_is_valid_and_yaml12_numbers_are_numbers(base):
    assert base["particles"]["youngs_modulus_dem"] == 5.0e6  # written 5.0e6, a string for YAML 1.1
    assert base["geometry"]["mesh_size"] == 0.5
    assert list(base["variants"]) == ["base"]


def test_misspelt_key_is_named_with_a_suggestion():
    cfg = raw()
    cfg["particles"]["diamter"] = cfg["particles"].pop("diameter")
    with pytest.raises(ConfigError) as err:
        config.validate(cfg, "my.yaml")
    text = str(err.value)
    assert "my.yaml" in text
    assert "particles.diamter: unknown key (did you mean 'diameter'?)" in text
    assert "particles.diameter: missing (required)" in text


@pytest.mark.parametrize(
    "path, value, expected",
    [
        (("dem", "timestep"), -1e-5, "dem.timestep: -1e-05 is less than or equal to the minimum of 0"),
        (("thermal", "gas"), "argon", "thermal.gas"),
        (("thermal", "modes", "pfp"), "yes", "thermal.modes.pfp: 'yes' is not of type 'boolean'"),
        (("thermal", "walls", "heated_wall"), {"temp": 500}, "thermal.walls.heated_wall"),
        (("geometry", "tube", "heated"), [0.1], "geometry.tube.heated"),
        (("thermal", "solid_fraction"), {"bulk": 0.6}, "thermal.solid_fraction"),
        (("thermal", "solid_fraction"), 0.9, "thermal.solid_fraction"),
    ],
)
def test_bad_values_are_named(path, value, expected):
    cfg = raw()
    node = cfg
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(ConfigError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        config.validate(cfg)


def test_variant_overrides_merge_and_are_validated(base):
    cfg = raw()
    cfg["variants"] = {"base": {}, "hot": {"thermal": {"inlet_temperature": 500.0}}, "bad": {"dem": {"timestep": "fast"}}}
    with pytest.raises(ConfigError, match=r"(?s)variant .bad.*dem.timestep"):
        config.validate(cfg)
    del cfg["variants"]["bad"]
    full = config.validate(cfg)
    hot = config.variant(full, "hot")
    assert hot["thermal"]["inlet_temperature"] == 500.0
    assert hot["thermal"]["gas"] == base["thermal"]["gas"]
    with pytest.raises(ConfigError, match="unknown variant 'cold'"):
        config.variant(full, "cold")


def test_solid_fraction_per_region_reaches_only_its_modes(base):
    b = config.variant(base, "base")
    one = copy.deepcopy(b)
    one["thermal"]["solid_fraction"] = 0.58
    assert config.htc_spec(one, "pfp")["solid_fraction"] == config.htc_spec(one, "pfw")["solid_fraction"] == 0.58
    split = copy.deepcopy(b)
    split["thermal"]["solid_fraction"] = {"bulk": 0.61, "near_wall": 0.54}
    assert config.htc_spec(split, "pfp")["solid_fraction"] == 0.61
    assert config.htc_spec(split, "pfw")["solid_fraction"] == 0.54
    near = copy.deepcopy(split)
    near["thermal"]["solid_fraction"]["near_wall"] = 0.50
    assert config.htc_spec(near, "pfp") == config.htc_spec(split, "pfp")  # the PFP table is reused
    assert config.htc_spec(near, "pfw") != config.htc_spec(split, "pfw")


def test_thermal_changes_leave_geometry_and_dem_keys_alone(base):
    b = config.variant(base, "base")
    changed = copy.deepcopy(b)
    changed["particles"]["conductivity"] = 3.0
    changed["particles"]["specific_heat"] = 800.0
    changed["thermal"]["inlet_temperature"] = 400.0
    changed["wall"]["conductivity"] = 20.0
    changed["dem"]["ranks"] = 1
    for spec in (config.geometry_spec, config.dem_spec):
        assert config.digest(spec(changed)) == config.digest(spec(b))
    assert config.thermal_spec(changed) != config.thermal_spec(b)
    assert config.htc_spec(changed, "pfp") != config.htc_spec(b, "pfp")
    moved = copy.deepcopy(b)
    moved["dem"]["flow_time"] = 2.0
    assert config.digest(config.dem_spec(moved)) != config.digest(config.dem_spec(b))
    assert config.digest(config.geometry_spec(moved)) == config.digest(config.geometry_spec(b))


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        config.load(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("particles: [1, 2\n")
    with pytest.raises(ConfigError, match="bad.yaml: not valid YAML"):
        config.load(bad)
