"""A tube run as a chain of segments end to end (real Snakemake, gmsh, LIGGGHTS, thermal stage) on the
tiny chain of .test/config/chain.yaml: the jobs planned, energy across every hand-over, the chain's
total, and a plain tube cut into slices against the same tube as one slice carried the whole way."""

import json
import math
import subprocess

import h5py
import numpy as np
import pytest
import yaml

from dpht import config
from dpht.chain import outlet
from dpht.chain.segments import RESOLVED, SLICE
from dpht.plan import Plan
from test_workflow import SNAKEMAKE, TEST_CONFIG, end_to_end, job_counts, snakemake, tiny_config

CHAIN = TEST_CONFIG.parent / "chain.yaml"
PLATE = {"type": "flat_plate", "thickness": 1.0e-3, "opening": 0.6, "orientation": 0.0}
# Hand-over of a slice to a slice (test_a_plain_tube_cut_into_slices_is_the_tube_as_one_slice): the
# two chains share the DEM record and the wall along the path. A joint keeps each ring's mixing cup
# (the energy exactly) and loses the temperature spread within a ring; the wall heat is linear in the
# wall layer's temperature, so the loss is of second order. Beside it, each joint restarts the DEM
# record (another packing at the wall) and overlaps the stretch above by less than one thermal step
# of travel (0.2 mm of 48 here). 2% is the Watkins reduction's target for the slice itself.
SLICE_TO_SLICE = 0.02


def chain_config(variants: dict) -> dict:
    """The tiny scene with .test/config/chain.yaml merged over it and these ``variants`` only."""
    cfg = tiny_config(yaml.safe_load(CHAIN.read_text()))
    cfg["name"] = "chain"
    cfg["variants"] = variants
    return cfg


def variants_of_the_file() -> dict:
    return yaml.safe_load(CHAIN.read_text())["variants"]


@pytest.fixture(scope="module")
def chain_run(tmp_path_factory):
    """The chains of .test/config/chain.yaml, and the plain tube cut into slices with a one-ring field."""
    workdir = tmp_path_factory.mktemp("chain")
    variants = {**variants_of_the_file(), "plain_one_ring": {"chain": {"cuts": [0.035, 0.02], "field": {"rings": 1}}}}
    (workdir / "tiny.yaml").write_text(yaml.safe_dump(chain_config(variants)))
    dry = job_counts(snakemake(workdir, "-n"))
    result = subprocess.run([*SNAKEMAKE, "--directory", str(workdir), "--configfile", str(workdir / "tiny.yaml")],
                            capture_output=True, text=True, timeout=3600)  # fmt: skip
    assert result.returncode == 0, result.stderr[-4000:]
    plan = Plan(config.validate(chain_config(variants)))
    summaries = {v: json.loads((workdir / "results" / "chain" / v / "chain.json").read_text()) for v in variants}
    return workdir, plan, dry, summaries


@end_to_end
def test_one_dem_run_per_resolved_shape_and_one_for_every_slice(chain_run, tmp_path):
    _, plan, dry, summaries = chain_run
    # four chains: 3 + 3 + 1 + 3 segments, one DEM run of the plate and one of every slice
    assert dry["segment"] == 10 and dry["dem"] == 2 and dry["chain_summary"] == 4
    assert "thermal" not in dry and "figures" not in dry  # a chain variant runs as its segments, not as one tube
    assert [s["kind"] for s in summaries["plate"]["segments"]] == [SLICE, RESOLVED, SLICE]
    assert summaries["plate"]["dem_runs"] == 2 and summaries["plain"]["dem_runs"] == 1
    # two identical plates: still one DEM run of a plate (and the slices'), planned by Snakemake
    plates = {"plates": {"geometry": {"mixers": [{**PLATE, "height": 0.03}, {**PLATE, "height": 0.015}]}}}
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(chain_config(plates)))
    counts = job_counts(snakemake(tmp_path, "-n"))
    assert counts["dem"] == 2 and counts["segment"] == 5


@end_to_end
def test_energy_is_conserved_across_every_hand_over(chain_run):
    workdir, plan, _, summaries = chain_run
    for variant, summary in summaries.items():
        for joint in summary["joints"]:
            # the receiving particles' mass-weighted enthalpy is the field's mixing cup, to round-off
            assert abs(joint["relative_residual"]) <= 1e-12, (variant, joint)
        for k, (segment, key) in enumerate(zip(summary["segments"], plan.chains[variant].segments)):
            folder = workdir / "results" / "segment" / key
            record = outlet.read(folder / "thermal.h5")  # what left it, in float64
            assert record.temperature.dtype == np.float64
            if segment["kind"] == RESOLVED:  # its crossings, those of its steady window handed over
                assert record.kind == outlet.CROSSINGS and record.temperature.size > segment["samples"]
                continue
            assert record.kind == outlet.BED and record.temperature.size == segment["samples"]
            with h5py.File(folder / "thermal.h5") as f:  # its wall heat is its own books'
                wall, run = float(f["energy/wall"][-1]), json.loads(f.attrs["summary"])
            mass_flow, particle = summary["mass_flow_kg_s"], plan.runs[key].spec["handover"]["mass"]
            assert segment["wall_heat_W"] == pytest.approx(mass_flow * wall / (record.temperature.size * particle), rel=1e-12)
            if variant == "plate" and k == 2:
                # Below the plate the hand-over's shift (the field mass-weighted in the slice against
                # the plate segment's flux-weighted crossings) takes the slice's coldest particles
                # below its enthalpy table: their temperatures clamp at its edge, its outlet record
                # with them (docs/theory/chain.md, the tiny chain).
                with h5py.File(folder / "thermal.h5") as f:
                    coldest = float(np.nanmin(f["temperature"][0]))
                print(f"plate's last slice: shift {summary['joints'][1]['delta_K']:+.2f} K, coldest start {coldest:.2f} K, "
                      f"enthalpy rise {segment['enthalpy_rise_W']:.4g} W against its wall heat {segment['wall_heat_W']:.4g} W")
                continue
            # A slice carries every particle through its stretch: what it took from the wall per kg is
            # its mixing cup's rise from the field it was handed to the field it hands on.
            assert not any(run["clamped_lookups"].values()), (variant, k)
            assert segment["enthalpy_rise_W"] == pytest.approx(segment["wall_heat_W"], rel=1e-6), (variant, segment)


@end_to_end
def test_the_chain_total_is_the_sum_of_its_segments(chain_run):
    workdir, plan, _, summaries = chain_run
    for variant, summary in summaries.items():
        per_segment = [json.loads((workdir / "results" / "segment" / key / "summary.json").read_text())["outlet"]["wall_heat_W"]
                       for key in plan.chains[variant].segments]  # fmt: skip
        assert summary["wall_heat_W"] == pytest.approx(math.fsum(per_segment), rel=1e-14)
        assert summary["wall_heat_W"] > 0 and summary["outlet_cup_temperature_K"] > summary["inlet_temperature_K"]
        # the wall heat profile along the tube: contiguous bins from the inlet down, the same total
        # (a resolved segment's from its float32 heat per element)
        profile = summary["profile"]
        assert profile[0]["z_top_m"] == 0.05 and profile[-1]["z_bottom_m"] == pytest.approx(0.002, abs=1e-12)
        assert all(a["z_bottom_m"] == pytest.approx(b["z_top_m"], abs=1e-12) for a, b in zip(profile, profile[1:]))
        assert math.fsum(p["wall_heat_W"] for p in profile) == pytest.approx(summary["wall_heat_W"], rel=1e-5)
        cups = [j["cup_temperature_K"] for j in summary["joints"]] + [summary["outlet_cup_temperature_K"]]
        if variant != "plate":  # plain tubes heated all the way: every joint hotter than the one above
            assert cups == sorted(cups)
    plate = summaries["plate"]["segments"][1]
    assert plate["samples"] > 100 and plate["steady"] is not None
    # the resolved segment's books: its enthalpy rise against its wall heat over its window (at this
    # scale its joints are not in plug flow: docs/theory/chain.md, the tiny chain)
    print(f"plate segment: wall heat {plate['wall_heat_W']:.4g} W, enthalpy rise {plate['enthalpy_rise_W']:.4g} W, "
          f"halves {plate['wall_heat_halves_W']}, cups {plate['cup_halves_K']}, steady {plate['steady']}")


@end_to_end
def test_a_plain_tube_cut_into_slices_is_the_tube_as_one_slice(chain_run):
    """The hand-over of a slice to a slice is nearly lossless (SLICE_TO_SLICE); a one-ring field,
    which hands the wall layer the mean temperature of the section, is not."""
    _, _, _, summaries = chain_run
    one = summaries["plain_one"]
    rise = one["outlet_cup_temperature_K"] - one["inlet_temperature_K"]

    def misses(variant):
        s = summaries[variant]
        return (s["wall_heat_W"] / one["wall_heat_W"] - 1, (s["outlet_cup_temperature_K"] - one["outlet_cup_temperature_K"]) / rise)

    heat, outlet_rise = misses("plain")
    coarse_heat, _ = misses("plain_one_ring")
    print(f"three slices against one: wall heat {heat:+.3%}, outlet rise {outlet_rise:+.3%}; with a one-ring field "
          f"{coarse_heat:+.3%} (one slice: {one['wall_heat_W']:.4g} W, outlet {one['outlet_cup_temperature_K']:.2f} K)")
    assert abs(heat) <= SLICE_TO_SLICE and abs(outlet_rise) <= SLICE_TO_SLICE
    assert abs(coarse_heat) > abs(heat)
