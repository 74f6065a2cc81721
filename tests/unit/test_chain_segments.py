"""The segments of a chain (dpht.chain.segments) from a scene's `chain` section and geometry, and
the section's errors, named with file, line and key before any job."""

import copy
import re
from pathlib import Path

import pytest
import yaml

from dpht import config
from dpht.chain.segments import RESOLVED, SLICE, Chain
from dpht.errors import ConfigError
from dpht.plan import from_workflow

ROOT = Path(__file__).resolve().parents[2]
MIXERS = ROOT / "config" / "mixers.yaml"
D = 371.2e-6  # m, the mixer scene's particles
DEFAULT = ROOT / "config" / "config.yaml"


def scene(variant="radial", **chain):
    """The mixer scene's variant with a chain section (schema defaults filled)."""
    cfg = config.load(MIXERS)
    cfg["chain"] = chain
    return config.variant(config.validate(cfg), variant)


def in_diameters(chain):
    return [(s.kind, round(s.bottom / D, 6), round(s.top / D, 6)) for s in chain.segments]


def assert_continuous(chain):
    """Flow order, no gap, no overlap, from the inlet to the orifice plate."""
    segments = chain.segments
    assert segments[0].top == chain.inlet and segments[-1].bottom == chain.outlet
    assert all(a.bottom == b.top for a, b in zip(segments, segments[1:]))
    assert all(s.length > 0 for s in segments)


def test_one_mixer_is_resolved_with_its_margins_between_slices():
    c = scene(inlet_height=31 * D, margin_above=2.0, margin_below=4.0, field={"rings": 12})  # the heated top
    chain = Chain.of(c)
    assert_continuous(chain)
    mixer_bottom, mixer_top = 7.70982e-3 - 6.07 * D, 7.70982e-3  # the radial mixer: 6.07 d tall, top at its height
    kinds = [s.kind for s in chain.segments]
    assert kinds == [SLICE, RESOLVED, SLICE]
    resolved = chain.segments[1]
    assert resolved.top == pytest.approx(mixer_top + 2 * D) and resolved.bottom == pytest.approx(mixer_bottom - 4 * D, abs=0.05 * D)
    assert [i.index for i in resolved.inserts] == [0]
    assert chain.field.rings == 12 and chain.field.sectors == 1 and chain.slice_length == 16 * D


def test_the_base_tube_is_one_slice_and_the_outlet_may_be_resolved():
    chain = Chain.of(scene("base"))
    # orifice plate at 2 d, inlet the tube's top, cut where the heated range (2-31 d) begins
    assert in_diameters(chain) == [(SLICE, 31.0, 38.0), (SLICE, 2.0, 31.0)]
    chain = Chain.of(scene("base", outlet_margin=4.0))
    assert in_diameters(chain) == [(SLICE, 31.0, 38.0), (SLICE, 6.0, 31.0), (RESOLVED, 2.0, 6.0)]
    assert chain.segments[2].outlet and not chain.segments[2].inserts
    chain = Chain.of(scene("base", cuts=[20 * D, 10 * D]))
    assert in_diameters(chain) == [(SLICE, 31.0, 38.0), (SLICE, 20.0, 31.0), (SLICE, 10.0, 20.0), (SLICE, 2.0, 10.0)]


def series(heights):
    """The radial variant with radial mixers at ``heights`` (m)."""
    c = scene()
    radial = c["geometry"]["mixers"][0]
    c["geometry"]["tube"]["length"] = 0.18
    c["geometry"]["tube"]["heated"] = [c["geometry"]["tube"]["heated"][0], 0.145]
    c["geometry"]["mixers"] = [{**radial, "height": h} for h in heights]
    return c


def test_identical_mixers_in_series_share_one_resolved_shape():
    c = series([0.14, 0.10, 0.06])
    chain = Chain.of(c)
    assert_continuous(chain)
    # the adiabatic entry above 0.145 m its own slice
    assert [s.kind for s in chain.segments] == [SLICE, SLICE, RESOLVED, SLICE, RESOLVED, SLICE, RESOLVED, SLICE]
    shapes = chain.shapes(c["geometry"])
    assert list(shapes.values()) == [[2, 4, 6]]  # three mixers, one DEM
    c["geometry"]["mixers"][1] = {"type": "flat_plate", "height": 0.10, "thickness": D, "opening": 0.3}
    assert sorted(map(len, Chain.of(c).shapes(c["geometry"]).values())) == [1, 2]


def test_mixers_closer_than_their_margins_are_one_segment():
    c = series([0.10, 0.10 - 10 * D])  # 3.9 d between them: the upper one's wake reaches the lower one's top margin
    chain = Chain.of(c)
    assert [s.kind for s in chain.segments] == [SLICE, SLICE, RESOLVED, SLICE]
    assert [i.index for i in chain.segments[2].inserts] == [0, 1]
    assert len(chain.shapes(c["geometry"])) == 1


@pytest.mark.parametrize(("chain", "message"), [
    ({"inlet_height": 0.5}, r"chain.inlet_height: 0.5 m is not within the tube above its orifice plate"),
    ({"inlet_height": 6 * D}, r"geometry.mixers\[0\]: reaches z = .* above chain.inlet_height"),
    ({"cuts": [1.0 * D]}, r"chain.cuts\[0\]: .* is not between the orifice plate"),
])  # fmt: skip
def test_a_chain_that_does_not_fit_the_tube_is_refused(chain, message):
    with pytest.raises(ConfigError, match=message):
        Chain.of(scene(**chain))


def plan_with(tmp_path, overrides):
    override = tmp_path / "override.yaml"
    override.write_text(yaml.safe_dump(overrides))
    merged = config.merge(yaml.safe_load(DEFAULT.read_text()), copy.deepcopy(overrides))
    return from_workflow(merged, [DEFAULT, override]), override


def test_errors_name_file_line_and_key_before_any_job(tmp_path):
    with pytest.raises(ConfigError) as err:
        plan_with(tmp_path, {"chain": {"margin_below": 2.0, "inlet_height": 1.0}})
    assert re.search(rf"{re.escape(str(tmp_path / 'override.yaml'))}:2: chain.inlet_height: 1.0 m is not within", str(err.value))
    with pytest.raises(ConfigError) as err:
        plan_with(tmp_path, {"chain": {"field": {"ring": 4}}})
    assert "chain.field.ring: unknown key (did you mean 'rings'?)" in str(err.value)
    with pytest.raises(ConfigError) as err:
        plan_with(tmp_path, {"chain": {"field": {"sectors": 0}}})
    assert "chain.field.sectors" in str(err.value) and "override.yaml:3" in str(err.value)


DRIVEN = {"dem": {"drive": {"mass_flow": 4.5e-3, "orifice": True}}}  # a chain's flow


def test_a_chain_section_changes_no_stage_key_of_the_scene(tmp_path):
    """The section describes how a tube is cut, not what the scene's own stages compute; its
    segments' stage runs are the chain's (tests/workflow/test_chain.py)."""
    plan, _ = plan_with(tmp_path, {**DRIVEN, "chain": {"field": {"rings": 4}}})
    reference, _ = plan_with(tmp_path, DRIVEN)
    assert plan.keys == reference.keys and plan.chains and not reference.chains


def test_a_chain_needs_the_mass_flow_it_runs_at(tmp_path):
    with pytest.raises(ConfigError, match=r"dem.drive.mass_flow: a chain runs every segment at one mass flow"):
        plan_with(tmp_path, {"chain": {}})


def test_check_shows_the_chain_of_every_variant(tmp_path, capsys):
    """`dpht check` lists each variant's segments in flow order and the DEM runs their shapes need."""
    from dpht.__main__ import main

    override = tmp_path / "chain.yaml"
    override.write_text("chain: {outlet_margin: 4.0, field: {rings: 10}}\n")
    assert main(["check", str(MIXERS), str(override), "--no-jobs", "--directory", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert ("  chain: 5 segments from z = 38.0 d down to 2.0 d (hand-over field 10 rings x 1 sector(s); slices 16 d): "
            "slice 38.0-31.0 d, slice 31.0-23.8 d, resolved 23.8-9.7 d (mixers[0]), slice 9.7-6.0 d, resolved 6.0-2.0 d "
            "(the orifice plate)") in out
    # the plain tube: the adiabatic entry, the heated slice and the outlet
    assert "  chain: 3 segments from z = 38.0 d down to 2.0 d" in out
    assert out.count("2 resolved segment(s) of 2 shape(s): 3 DEM run(s) (one per resolved shape, one for every slice)") == 2
