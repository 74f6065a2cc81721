"""The registry of heat-transfer modes against everything that lists modes: the config schema and
default config, the kernels' records, the model's cutoffs, the output's wall columns."""

from pathlib import Path

import pytest
import yaml

from dpht import config
from dpht.errors import ConfigError
from dpht.closures import htc, rdf
from dpht.thermal import kernels, modes
from dpht.verification import scenes

ROOT = Path(__file__).resolve().parent.parent
R = scenes.RADIUS


def test_config_schema_switches_are_the_registry():
    thermal = config.schema()["properties"]["thermal"]["properties"]
    switches = thermal["modes"]
    assert switches["additionalProperties"] is False
    assert list(switches["properties"]) == list(modes.NAMES)
    switch = config.schema()["$defs"]["switch"]
    assert switch == {"enum": [True, False, "auto"], "default": "auto"}  # decided by thermal.effects
    for mode in modes.MODES:
        assert switches["properties"][mode.name] == {"$ref": "#/$defs/switch"}, mode.name
        if mode.cutoff_key is not None:  # the key giving the cutoff exists, in radii
            assert "radii" in thermal[mode.cutoff_key]["description"], mode.cutoff_key


def test_default_config_lists_every_mode():
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    assert list(cfg["thermal"]["modes"]) == list(modes.NAMES)
    # A switch left out is auto, as in the default config; only a true one is on before the effects are decided.
    filled = config.load(ROOT / "config" / "config.yaml")
    assert filled["thermal"]["modes"] == dict.fromkeys(modes.NAMES, "auto") == cfg["thermal"]["modes"]
    assert modes.enabled(filled["thermal"]["modes"]) == frozenset()
    assert modes.enabled({"pfp": True, "pfw": "auto", "pp_contact": False}) == {"pfp"}


def test_registry_entries_are_consistent():
    assert len(set(modes.NAMES)) == len(modes.MODES) and len(set(modes.LABELS.values())) == len(modes.MODES)
    assert set(modes.PP_MODES) | set(modes.PW_MODES) == set(modes.NAMES)
    assert kernels.PairTables._fields == modes.PP_MODES and kernels.WallTables._fields == modes.PW_MODES
    for mode in modes.MODES:
        if mode.table is not None:
            kind, part = mode.table
            assert part in (htc.KINDS if kind == "htc" else rdf.RDFTables.__dataclass_fields__), mode.name
            assert modes.reader(kind, part) is mode
    assert modes.needing("rdf") == config.RADIATION_MODES == ("pp_radiation", "pw_radiation")
    assert [modes.wall_column(m) for m in modes.PW_MODES] == list(range(len(modes.PW_MODES)))


@pytest.mark.parametrize(
    "enabled, pair, wall",
    [
        (["pp_contact"], 2.0, 0.0),
        (["pw_contact"], 0.0, 1.0),
        (["pp_contact", "pfp"], 3.0, 0.0),
        (["pw_contact", "pfw"], 0.0, 1.5),
        (["pp_contact", "pw_radiation"], 2.0, 7.0),
        (list(modes.NAMES), 7.0, 7.0),
    ],
)
def test_model_cutoffs_follow_each_modes_rule(enabled, pair, wall):
    """Contact: touching (2 R centre-centre, R centre-wall); the others: their thermal.* key in radii
    (scenes.BASE_SPEC: pfp 3, pfw 1.5, radiation 7)."""
    model = scenes.build_model(scenes.spec(enabled), scenes.plane_walls(), scenes.synthetic_rdf())
    assert model.pair_cutoff == pair * R and model.wall_cutoff == wall * R
    assert bool(model.surfaces) == (wall > 0)
    assert model.n_elements == len(scenes.plane_walls().area)


def test_a_table_needed_but_missing_is_refused():
    with pytest.raises(ConfigError, match="thermal.rdf_table: needed for \\['pp_radiation'\\]"):
        scenes.build_model(scenes.spec(["pp_radiation"]))
