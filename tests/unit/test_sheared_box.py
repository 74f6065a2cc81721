"""The sheared periodic box's parameters, deck and flow measurement (no LIGGGHTS: see
tests/stage/test_sheared_box_run.py for the run)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dpht.dem import dumps
from dpht.dem.sheared import ShearedBoxParams, flow_profile, render_deck
from dpht.errors import ConfigError
from sheared_scene import SPEC, spec_with


def test_shear_rate_is_the_peclet_numbers():
    """Paper Eq. 9: Pe = (d/2)^2 / (lambda / (rho c_p)) * rate; here 0.25 = 2.5e-7 / (2 / 1e6) * rate."""
    params = ShearedBoxParams.from_spec(SPEC)
    assert params.shear_rate == pytest.approx(2.0, rel=1e-12)
    doubled = ShearedBoxParams.from_spec(spec_with(particles={"conductivity": 4.0}))
    assert doubled.shear_rate == pytest.approx(4.0, rel=1e-12)
    edge = 15e-3
    assert params.edge == pytest.approx(edge, rel=1e-15)
    assert params.n_particles == round(0.45 * edge**3 / (math.pi / 6 * 1e-9))
    assert abs(params.solid_fraction - 0.45) < 0.5 * math.pi / 6 * 1e-9 / edge**3
    steps = params.steps()
    per_strain = 1.0 / (2.0 * 1e-5)
    assert steps["steady_end"] % 250 == 0 and steps["shear_end"] % 250 == 0
    assert steps["steady_end"] >= steps["rest_end"] + per_strain
    assert steps["shear_end"] - steps["steady_end"] == pytest.approx(3.0 * per_strain, abs=250)


def test_deck_packs_then_shears_the_triclinic_box():
    params = ShearedBoxParams.from_spec(SPEC)
    deck = render_deck(params)
    assert deck == render_deck(ShearedBoxParams.from_spec(SPEC))
    order = ["boundary p p p", "communicate single vel yes", "fix insert", "unfix insert", "unfix squeeze",
             "change_box all triclinic", "coefficientFriction peratomtypepair 2 0.5 0.5 0.5 0.5",
             "velocity all ramp vx -0.015 0.015 y 0.0 0.015 sum yes units box",
             "fix shear all deform 1 xy erate 2.0 remap v", "dump positions"]  # fmt: skip
    places = [deck.find(text) for text in order]
    assert -1 not in places and places == sorted(places), dict(zip(order, places))
    assert "coefficientFriction peratomtypepair 2 0.0 0.0 0.0 0.0" in deck[: places[2]]  # frictionless packing
    assert "thermo_style custom step atoms time c_iz_sum c_z_max f_ts_check[1] f_ts_check[2] xy" in deck
    assert "format float %.15g" in deck and "@{" not in deck


@pytest.mark.parametrize("section, key, value, message", [
    ("sheared_box", "size", 3, "at least 4"),
    ("sheared_box", "solid_fraction", 0.7, r"sheared_box.solid_fraction = 0.7"),
    ("sheared_box", "steady_strain", -1.0, "expected a value >= 0"),
    ("sheared_box", "peclet", 0.0, r"sheared_box.peclet = 0.0"),
    ("particles", "specific_heat", "-500.0 + 0.0 * T", "expected a positive number"),
    ("dem", "seed", 32452844, "prime"),
])  # fmt: skip
def test_bad_settings_are_named(section, key, value, message):
    with pytest.raises(ConfigError, match=message):
        ShearedBoxParams.from_spec(spec_with(**{section: {key: value}}))
    with pytest.raises(ConfigError, match="missing key 'sheared_box.size'"):
        ShearedBoxParams.from_spec({**SPEC, "sheared_box": {}})


def test_flow_profile_measures_a_known_shear_flow(tmp_path):
    """Particles streaming at rate * (Y - H/2) of their height Y in the unbounded sheared lattice,
    wandering across the y faces, written as a sheared box's frames (positions wrapped, flags and
    the tilt growing and flipping as LIGGGHTS keeps them): the measured rate, linearity and solid
    fraction are the flow's."""
    rng = np.random.default_rng(4)
    edge, radius, rate, dt, every = 0.006, 5e-4, 40.0, 1e-5, 500
    lo, hi = np.zeros(3), np.full(3, edge)
    n = 220
    unbounded = rng.random((n, 3)) * edge
    frames = []
    crossed = np.zeros(n, dtype=bool)
    for k in range(14):
        tilt = rate * edge * k * every * dt
        tilt -= edge * np.round(tilt / edge)
        image = np.floor((unbounded - lo) / edge).astype(np.int32)
        crossed |= image[:, 1] != 0
        pos = unbounded - image * edge
        pos[:, 0] -= image[:, 1] * tilt
        frames.append(dumps.DumpFrame(k * every, lo, hi, (True,) * 3, np.arange(1, n + 1), pos, image, tilt))
        step = rng.normal(0.0, 4e-4, (n, 3))  # wandering, across the y faces too
        step[:, 0] += rate * (unbounded[:, 1] - 0.5 * edge) * every * dt  # the stream at the interval's start
        unbounded = unbounded + step
    assert crossed.mean() > 0.2 and frames[-1].tilt < frames[-2].tilt  # y faces crossed, the box flipped
    for frame in frames:  # as the reader leaves them: in the orthogonal box
        dumps._wrap(frame.positions, frame.image, lo, hi, (True,) * 3, frame.tilt)
    dumps.write_positions(tmp_path / "p.h5", frames, radius=radius, density=2000.0, timestep=dt, dump_interval=every)
    with dumps.PositionsFile(tmp_path / "p.h5") as positions:
        profile = flow_profile(positions, 4)
    assert profile.shear_rate == pytest.approx(rate, rel=0.03)
    assert abs(profile.offset) < 0.03 * rate * edge and profile.linearity < 0.03 and profile.lost == 0
    solid = n * 4 / 3 * math.pi * radius**3 / edge**3
    assert np.mean(profile.solid_fraction) == pytest.approx(solid, rel=1e-12)  # every sphere counted once
    assert np.all(np.abs(profile.solid_fraction / solid - 1) < 0.2)
