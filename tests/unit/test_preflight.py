"""The pre-flight check (dpht.preflight): what a config asks for is checked when the plan is built,
before gmsh or LIGGGHTS run, and every problem names the file, line, key and value."""

import re
from pathlib import Path

import pytest
import yaml

from dpht import config
from dpht.__main__ import main
from dpht.errors import ConfigError
from dpht.plan import Plan, from_workflow

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "config" / "config.yaml"
MIXER_SCENES = ["base", "flat_plate", "radial"]  # config/mixers.yaml, mixers_paper.yaml


def plan_with(tmp_path, overrides: dict, name="override.yaml"):
    """The workflow's plan of config/config.yaml with ``overrides`` written to a second file, as
    `snakemake --configfile override.yaml` would build it."""
    override = tmp_path / name
    override.write_text(yaml.safe_dump(overrides))
    merged = config.merge(yaml.safe_load(DEFAULT.read_text()), overrides)
    return from_workflow(merged, [DEFAULT, override]), override


def test_the_shipped_configs_pass(tmp_path):
    """The default config with its mixer study (config/mixers.yaml) and with the paper-scale one."""
    paper = tmp_path / "paper.yaml"
    paper.write_text("studies: [mixers]\nmixer_study: {scene: config/mixers_paper.yaml}\n")
    for files in ([DEFAULT], [DEFAULT, paper]):
        plan = from_workflow(config.Sources(files).merged(), files)
        assert plan.variants == ["base"] and list(plan.studies["mixers"].scenes) == MIXER_SCENES


WALL = "thermal.walls.heated_wall.temperature"


@pytest.mark.parametrize(
    "overrides, line, message",
    [
        # Issue 11, item 5: constants that fail, and a division by zero at some elements only.
        ({"thermal": {"walls": {"heated_wall": {"temperature": "1073.15 + 1/0"}}}}, 4,
         f"{WALL}: expression '1073.15 \\+ 1/0' gives inf at 384 of 384 points"),
        ({"thermal": {"walls": {"heated_wall": {"temperature": "9**9**9"}}}}, 4, f"{WALL}: expression '9\\*\\*9\\*\\*9'"),
        ({"thermal": {"walls": {"heated_wall": {"temperature": "where(z > 0.03, 1/(z - 0.035), 900)"}}}}, 4,
         f"{WALL}: .* gives -216.6\\d* at 48 of 384 points, the first at x = 0.0044615, y = 0.000587368, z = 0.0303832"),
        ({"thermal": {"walls": {"heatedwall": {"temperature": "900"}}}}, 2,
         r"thermal.walls: zones \['heatedwall'\] are not in the geometry \(zones: \['heated_wall', 'adiabatic_wall'"),
        ({"thermal": {"htc_table": {"temperature_range": [400.0, 1000.0]}}}, 3,
         r"thermal.htc_table.temperature_range: the scene reaches 303.1-1073.2 K .* cover \[400.0, 1000.0\] K"),
        ({"particles": {"specific_heat": "1000 - T"}}, 2,
         "particles.specific_heat: specific heat must be finite and > 0 .* but is -0.1499.* at T = 1000.15 K"),
        ({"particles": {"conductivity": {"temperature": [300.0, 1073.15], "conductivity": [2.0, 2.5]}}}, 2,
         r"particles.conductivity: temperature 298.15 K is outside the particle conductivity table"),
        ({"thermal": {"gas": {"temperature": [300.0, 1000.0], "conductivity": [0.02, 0.06]}}}, 2,
         "thermal.gas: temperature 250 K is outside the gas table"),
        ({"thermal": {"gas": {"temperature": [200.0, 1500.0], "conductivity": [0.02, 0.06], "prandtl": 0.7}}}, 2,
         "thermal.gas: the gas table has no 'collision_diameter', 'heat_capacity_ratio': the temperature jump at a "
         "finite gas pressure needs .*; give them, or set thermal.gas_pressure: continuum"),
        ({"thermal": {"gas": {"temperature": [200.0, 1500.0], "conductivity": [0.02, 0.06], "prandtl": 0.7,
                              "collision_diameter": 3.6e-10, "heat_capacity_ratio": 1.4},
                      "accommodation": {"particle": 0.9}}}, 2,
         "thermal.accommodation: accommodation of the wall surface: not given, and the gas table has no typical"),
        ({"thermal": {"solid_fraction": {"bulk": 0.7, "near_wall": 0.54}}}, 3,
         r"thermal.solid_fraction.bulk = 0.7 is outside the solid fractions the RDF tables are built at .*0.25-0.64"),
        ({"thermal": {"rdf_table": "no/such/table.h5"}}, 2, "thermal.rdf_table: no/such/table.h5 does not exist"),
        ({"geometry": {"tube": {"heated": [0.004, 0.06]}}}, 3, r"geometry.tube.heated must satisfy 0 <= z0 < z1 <= "),
        ({"geometry": {"tube": {"orifice_diameter": 0.01}}}, 3, "geometry.tube.orifice_diameter .* must be smaller"),
        ({"geometry": {"mixers": [{"type": "flat_plate", "height": 0.02, "thickness": 5e-4, "opening": 0.05}]},
          "thermal": {"walls": {"mixer": "adiabatic"}}}, 4, r"geometry.mixers\[0\].opening: the opening .* is"),
        ({"dem": {"timestep": 1.0e-4}}, 2, "dem.timestep = 0.0001 s is 1.37 of the Rayleigh time"),
        ({"dem": {"restart_interval": 1500}}, 2, "dem.restart_interval = 1500 must be a multiple of dem.dump_interval"),
        ({"thermal": {"frame_stride": 200}}, 2, "thermal.frame_stride = 200: the DEM run writes 151 frames"),
        # (a study's section is checked when the run asks for the study)
        ({"radiation_study": {"solid_fraction": 0.2}, "studies": ["radiation"]}, 2, "radiation_study.solid_fraction = 0.2 is outside"),
        ({"radiation_study": {"hot_x": -0.01}, "studies": ["radiation"]}, 1, r"radiation_study: cold_x \(-0.004\) must be below hot_x"),
        ({"thermal": {"intraparticle": True, "integrator": "multirate"}}, 2,
         r"thermal.integrator: 'multirate' cannot advance resolved particles .*\(thermal.intraparticle: True\)"),
        ({"thermal": {"intraparticle": "auto", "implicit": {"scheme": "tr_bdf2"}}}, 3,
         r"thermal.implicit.scheme: 'tr_bdf2' cannot advance resolved particles \(thermal.intraparticle: auto"),
        ({"thermal": {"convection": {"coefficient": 10.0, "gas_temperature": 300.0}, "integrator": "multirate"}}, 5,
         r"thermal.integrator: 'multirate' cannot advance .*\(thermal.convection\)"),
    ],
    ids=lambda value: None if isinstance(value, dict) else str(value)[:30],
)
def test_problems_are_found_before_any_job(tmp_path, overrides, line, message):
    with pytest.raises(ConfigError) as err:
        plan_with(tmp_path, overrides)
    text = str(err.value)
    assert "the config cannot run (checked before any job started)" in text
    assert re.search(f"{re.escape(str(tmp_path / 'override.yaml'))}:{line}: {message}", text), text


def test_gas_data_are_needed_only_where_the_gas_conducts_with_a_jump(tmp_path):
    bare = {"temperature": [300.0, 1000.0], "conductivity": [0.02, 0.06]}  # nor does it cover the scene
    for pressure in ("continuum", 0.0):
        gas = bare if pressure == 0.0 else {**bare, "temperature": [200.0, 1500.0]}
        plan, _ = plan_with(tmp_path, {"thermal": {"gas": gas, "gas_pressure": pressure}})
        assert plan.configs["base"]["thermal"]["gas_pressure"] == pressure


def test_problems_of_several_variants_are_listed_together(tmp_path):
    bad = {"thermal": {"walls": {"heated_wall": {"temperature": "0"}}}}
    with pytest.raises(ConfigError) as err:
        plan_with(tmp_path, {"variants": {"base": {}, "cold": bad, "dense": {"thermal": {"solid_fraction": 0.7}}}})
    lines = str(err.value).splitlines()[1:]
    assert len(lines) == 2
    assert "gives 0.0" in lines[0] and lines[0].endswith("(variant cold)")
    assert "thermal.solid_fraction = 0.7 is outside" in lines[1] and lines[1].endswith("(variant dense)")


def test_a_base_variant_beside_a_mixer_shares_the_default_thermal_run(tmp_path):
    """Variants adding `mixer: adiabatic` for a flat_plate variant; the base variant has no such zone,
    so its thermal run is the default config's (issue 11: it ran again under a new key)."""
    plate = {"type": "flat_plate", "height": 0.020, "thickness": 0.5e-3, "opening": 0.65, "orientation": 0.0}
    mixers, _ = plan_with(tmp_path, {"thermal": {"walls": {"mixer": "adiabatic"}},
                                     "variants": {"base": {}, "flat_plate": {"geometry": {"mixers": [plate]}}}})  # fmt: skip
    default = Plan(config.load(DEFAULT))
    assert mixers.keys["base"] == default.keys["base"]
    assert "mixer" not in mixers.runs[mixers.keys["base"]["thermal"]].spec["thermal"]["walls"]
    assert mixers.runs[mixers.keys["flat_plate"]["thermal"]].spec["thermal"]["walls"]["mixer"] == "adiabatic"


def test_check_command(tmp_path, capsys):
    assert main(["check", str(DEFAULT), "--no-jobs"]) == 0  # the jobs: test_design.py
    assert "valid" in capsys.readouterr().out
    override = tmp_path / "bad.yaml"
    override.write_text("dem:\n  timestep: 1.0e-4\n")
    assert main(["check", str(DEFAULT), str(override)]) == 2
    assert f"{override}:2: dem.timestep = 0.0001 s" in capsys.readouterr().err
