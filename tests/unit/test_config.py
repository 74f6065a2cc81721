"""Config validation messages and the stage keys that drive caching."""

import copy
from pathlib import Path

import pytest
import yaml

from dpht import config
from dpht.closures import htc
from dpht.errors import ConfigError, DPHTError

DEFAULT = Path(__file__).resolve().parents[2] / "config" / "config.yaml"


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
        (("thermal", "modes", "pfp"), "yes", "thermal.modes.pfp: 'yes' is not allowed; expected one of true, false, \"auto\""),
        (("thermal", "walls", "heated_wall"), {"temp": 500}, "thermal.walls.heated_wall"),
        (("geometry", "tube", "heated"), [0.1], "geometry.tube.heated"),
        (("thermal", "solid_fraction"), {"bulk": 0.6}, "thermal.solid_fraction"),
        (("thermal", "solid_fraction"), 0.9, "thermal.solid_fraction"),
        (("thermal", "gas_pressure"), -1.0, "thermal.gas_pressure: -1.0 is less than the minimum of 0"),
        (("thermal", "gas_pressure"), "vacuum", "thermal.gas_pressure: 'vacuum' is not allowed; expected a number >= 0, or 'continuum'"),
        (("thermal", "accommodation"), {"particle": 0.0}, "thermal.accommodation.particle: 0.0 is less than or equal to the minimum of 0"),
        (("thermal", "accommodation"), {"wall": 1.2}, "thermal.accommodation.wall: 1.2 is greater than the maximum of 1"),
        (("thermal", "accommodation"), {"walls": 0.8}, "thermal.accommodation.walls: unknown key .did you mean 'wall'"),
        (("thermal", "gas"), {"temperature": [300.0, 900.0], "conductivity": [0.02, 0.05], "prandl": 0.7},
         "thermal.gas.prandl: unknown key .did you mean 'prandtl'"),
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


def test_gas_pressure_and_accommodation_reach_the_tables_that_use_them(base):
    b = config.variant(base, "base")
    assert b["thermal"]["gas_pressure"] == 101325.0 and "accommodation" not in b["thermal"]  # the defaults
    spec = {kind: config.htc_spec(b, kind) for kind in ("pfp", "pfw")}
    assert spec["pfp"]["gas_pressure"] == 101325.0 and "accommodation" not in spec["pfp"]
    assert spec["pfp"]["format"] == htc.FORMAT
    wall = copy.deepcopy(b)
    wall["thermal"]["accommodation"] = {"wall": 0.5}
    assert config.htc_spec(wall, "pfp") == spec["pfp"]  # the PFP table does not touch the wall
    assert config.htc_spec(wall, "pfw") == {**spec["pfw"], "accommodation": {"wall": 0.5}}
    low = copy.deepcopy(wall)
    low["thermal"]["gas_pressure"] = 1000  # an integer in YAML: the same key as 1000.0
    assert config.htc_spec(low, "pfw")["gas_pressure"] == 1000.0
    assert config.digest(config.htc_spec(low, "pfw")) == config.digest(
        config.htc_spec(config.merge(copy.deepcopy(wall), {"thermal": {"gas_pressure": 1000.0}}), "pfw"))
    # No jump, no coefficients: the continuum table is the same whatever they are.
    for pressure in ("continuum", 0.0):
        still = config.merge(copy.deepcopy(wall), {"thermal": {"gas_pressure": pressure}})
        assert "accommodation" not in config.htc_spec(still, "pfw")
    # The table a spec describes records them.
    table = htc.table_from_spec({**config.htc_spec(low, "pfw"), "distances": 16, "temperatures": 4, "solid_fraction": 0.6})
    assert (table.pressure, table.accommodation) == (1000.0, {"particle": 0.84, "wall": 0.5})


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
    with pytest.raises(ConfigError, match="bad.yaml, line 2, column 1: not valid YAML"):
        config.load(bad)


@pytest.mark.parametrize(
    "text, where",
    [  # the wording is libyaml's (PyYAML's pure-Python parser words some differently)
        ("a: 1\n  b: 2\n", r", line 2, column 4: not valid YAML: mapping values are not allowed"),
        ("a:\n  b: 1\n  b: 2\n", r", line 3, column 3: not valid YAML: key 'b' is given twice \(first on line 2\)"),
        ("a:\tb\n\tc: 1\n", r", line \d, column \d: not valid YAML: found .*tab"),
        ("- 1\n- 2\n", r": expected a mapping of sections at the top level, got list"),
    ],
)
def test_yaml_errors_name_file_and_line(tmp_path, text, where):
    path = tmp_path / "my.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=f"my.yaml{where}"):
        config.load(path)


def test_one_of_errors_say_what_is_allowed():
    """Issue 11, item 8: solid fraction 0.9 was refused without the allowed range."""
    cfg = raw()
    cfg["thermal"]["solid_fraction"] = 0.9
    with pytest.raises(ConfigError) as err:
        config.validate(cfg)
    assert ("thermal.solid_fraction: 0.9 is greater than or equal to the maximum of 0.75; expected a number > 0 and "
            "< 0.75, or 'measured', or a mapping with keys bulk, near_wall") in str(err.value)
    cfg["thermal"]["solid_fraction"] = {"bulk": 0.9, "near_wall": "measured"}
    with pytest.raises(ConfigError) as err:
        config.validate(cfg)
    assert str(err.value).endswith("thermal.solid_fraction.bulk: 0.9 is greater than or equal to the maximum of 0.75; "
                                   "expected a number > 0 and < 0.75, or 'measured'")
    cfg["thermal"]["solid_fraction"] = {"bulk": 0.6}
    with pytest.raises(ConfigError, match="thermal.solid_fraction.near_wall: missing"):
        config.validate(cfg)
    cfg["thermal"]["solid_fraction"] = 0.6
    cfg["thermal"]["walls"]["orifice"] = "adiabtic"
    with pytest.raises(ConfigError, match="thermal.walls.orifice: 'adiabtic' is not allowed; expected 'adiabatic', or a"):
        config.validate(cfg)


def test_particle_conductivity_table_is_not_called_a_gas_table():
    with pytest.raises(DPHTError, match="particles.conductivity: particle conductivity table: 'temperature' must"):
        htc.solid_conductivity({"temperature": [400.0, 300.0], "conductivity": [2.0, 2.1]}, 350.0)


@pytest.mark.parametrize("name, message", [
    ("..", "not allowed; a variant's results go to results/<run>/<name>/"), ("a b", "not allowed"),
    ("x/y", "not allowed"), (".hidden", "not allowed"), ("", "not allowed"), ("v" * 65, "not allowed"),
    ("studies", "taken by the folder results/<run>/studies/ beside the variants"),
    ("Comparison", "taken by the folder results/<run>/comparison/"),
])
def test_variant_names_are_safe_folder_names(name, message):
    """Issue 11, item 6: '..' planned results/../figures; a space ended in a MissingInputException."""
    cfg = raw()
    cfg["variants"] = {"base": {}, name: {}}
    with pytest.raises(ConfigError, match=message):
        config.validate(cfg, "my.yaml")
    cfg["variants"] = {"base": {}, "Base": {}}
    with pytest.raises(ConfigError, match="differ only in case"):
        config.validate(cfg)
    cfg["variants"] = {"base": {}, "flat-plate_2.5mm": {}, "dem": {}}  # results/<run>/dem/ is no stage's folder
    assert list(config.validate(cfg)["variants"]) == ["base", "flat-plate_2.5mm", "dem"]


def test_no_variant_or_run_is_named_like_a_folder_the_rules_write():
    """The reserved names come from the one table of paths (dpht.paths): a variant named like any
    folder beside the variants, a run like any stage cache folder, is refused with the folder named.
    (tests/workflow/test_workflow.py checks that table against the folders the rules write.)"""
    from dpht import paths, studies  # noqa: F401 (the studies register their keyed stages' folders)

    assert paths.reserved_variant_names() == {"comparison", "studies"}
    assert paths.reserved_run_names() >= {"geometry", "dem", "screening", "thermal", "radiation_study", "intraparticle_study"}
    for name in paths.reserved_variant_names():
        cfg = raw()
        cfg["variants"] = {"base": {}, name.upper(): {}}
        with pytest.raises(ConfigError, match=f"the name '{name.upper()}' is taken by the folder results/<run>/{name}/"):
            config.validate(cfg, "my.yaml")
    for name in paths.reserved_run_names():
        with pytest.raises(ConfigError, match=f"name: '{name}' is the stage folder results/{name}/ shared by every run"):
            config.validate({**raw(), "name": name}, "my.yaml")


def test_studies_and_name_are_the_last_files_own(tmp_path):
    """A design file merged over config/config.yaml inherits its base scene, not its studies or
    its name: its run makes no study and writes into results/<its file name>/."""
    design = tmp_path / "my_design.yaml"
    design.write_text("particles: {diameter: 6.0e-4}\n")
    default, merged = config.load(DEFAULT), config.load(DEFAULT, design)
    assert default["name"] == "default" and default["studies"] == ["watkins", "watkins_reduction", "mixers", "radiation",
                                                                     "intraparticle"]  # fmt: skip
    assert merged["name"] == "my_design" and merged["studies"] == [] and merged["particles"]["diameter"] == 6.0e-4
    assert merged["watkins"] == default["watkins"]  # the sections stay: a study asked for by name still runs
    design.write_text("name: mine\nstudies: [mixers]\nwatkins: null\n")
    merged = config.load(DEFAULT, design)
    assert merged["name"] == "mine" and merged["studies"] == ["mixers"] and merged["watkins"] is None


def test_errors_name_the_file_and_line_that_set_the_key(tmp_path):
    override = tmp_path / "override.yaml"
    override.write_text("thermal:\n  walls:\n    heated_wall: {temp: 900}\nvariants:\n  hot:\n    dem: {timestep: -1}\n")
    with pytest.raises(ConfigError) as err:
        config.load(DEFAULT, override)
    assert f"{override}:3: thermal.walls.heated_wall.temp: unknown key" in str(err.value)
    override.write_text("variants:\n  hot:\n    dem:\n      timestep: -1\n")
    with pytest.raises(ConfigError, match=f"variant 'hot'.*\\n  {override}:4: dem.timestep: -1"):
        config.load(DEFAULT, override)


def test_the_last_file_naming_variants_names_the_variants_that_run(tmp_path):
    """config/config.yaml's `variants: base` used to be merged into every override file's variants."""
    override = tmp_path / "override.yaml"
    override.write_text("variants:\n  hot: {thermal: {inlet_temperature: 500.0}}\n")
    assert list(config.load(DEFAULT, override)["variants"]) == ["hot"]
    override.write_text("thermal: {inlet_temperature: 400.0}\n")
    merged = config.load(DEFAULT, override)
    assert list(merged["variants"]) == ["base"] and merged["thermal"]["inlet_temperature"] == 400.0
