"""The thermal kernels and integrator against closed forms, conservation laws and a brute-force reference."""

import math

import numpy as np
import pytest

from dpht.closures import htc
from dpht.thermal import integrate
from dpht.verification import reference
from dpht.verification.cases.thermal import two_sphere_gap
from dpht.errors import DPHTError
from dpht.thermal.modes import NAMES, needing
from dpht.thermal import model as thermal_model
from dpht.verification import scenes
from dpht.verification.scenes import (
    RADIUS,
    advance as run,
    build_model,
    htc_tables,
    plane_walls,
    random_cluster,
    spec,
)

R = RADIUS


def temperatures(model, h):
    return model.enthalpy.temperature(h)


def test_pfp_pair_matches_the_htc_integral():
    # Equal capacities keep the mean temperature fixed, so the PFP conductance is constant in time.
    s = spec(["pfp"])
    model = build_model(s)
    d = 2.3 * R
    pos = np.array([[0, 0, 0], [0, 0, d]], dtype=float)
    G = float(htc.pfp(d, 400.0, radius=R, k_solid=2.0, solid_fraction=0.6))
    C = model.mass * 1000.0
    h = model.enthalpy.enthalpy(np.array([380.0, 420.0]))
    dt, steps = 0.2 * C / G, 10
    run(model, pos, h, dt, steps)
    T = temperatures(model, h)
    # The kernel interpolates the HTC table bilinearly; its error bound at this resolution is 2e-3.
    assert T[1] - T[0] == pytest.approx(two_sphere_gap(40.0, G, C, dt, steps), rel=3e-3)


ALL_CONDUCTION = [m for m in NAMES if m not in needing("rdf")]


def test_particle_particle_terms_sum_to_zero():
    s = spec(["pp_contact", "pfp"])
    model = build_model(s)
    pos = random_cluster(seed=3)
    rng = np.random.default_rng(2)
    h = model.enthalpy.enthalpy(rng.uniform(300, 700, len(pos)))
    frame, rates, _ = run(model, pos, h, 0.0, 1)
    assert np.count_nonzero(rates.q) > 0.9 * len(pos)
    assert abs(math.fsum(rates.q)) <= 1e-12 * math.fsum(np.abs(rates.q))


def test_stability_limit_is_refused_with_a_message():
    s = spec(ALL_CONDUCTION, max_substeps=2)
    model = build_model(s, plane_walls())
    pos = random_cluster(seed=6)
    h = model.enthalpy.enthalpy(np.full(len(pos), 300.0))
    with pytest.raises(DPHTError, match="thermal.max_substeps"):
        run(model, pos, h, 50.0, 1)


def test_results_identical_for_one_and_two_threads():
    s = spec(ALL_CONDUCTION, walls={"hot": {"temperature": 600.0}})
    model = build_model(s, plane_walls())
    pos = random_cluster(n=1500, seed=7)
    rng = np.random.default_rng(8)
    h0 = model.enthalpy.enthalpy(rng.uniform(300, 500, len(pos)))

    def once():
        h = h0.copy()
        run(model, pos, h, 0.5, 3)
        return h

    results = scenes.on_threads(once)
    assert np.array_equal(results[0], results[1])


@pytest.mark.parametrize("conductivity", [2.0, {"temperature": [250.0, 600.0, 1400.0], "conductivity": [1.0, 2.0, 6.0]}])
def test_all_six_modes_match_a_brute_force_reference(conductivity):
    s = spec(NAMES, walls={"hot": {"temperature": 800.0}})
    s["particles"]["conductivity"] = conductivity
    walls = plane_walls(half=0.05)
    tables = htc_tables(s)
    model = thermal_model.build(s, walls, tables, scenes.synthetic_rdf())
    pos = random_cluster(n=300, seed=9)
    rng = np.random.default_rng(10)
    T = rng.uniform(400, 700, len(pos))
    h = model.enthalpy.enthalpy(T)
    T = model.enthalpy.temperature(h)
    frame, rates, reports = run(model, pos, h, 0.0, 1)
    q = np.zeros(len(pos))
    q[frame.particles] = rates.q
    q_ref, heat_ref = reference.heat_rates(model, pos, T, walls)
    assert np.max(np.abs(q - q_ref)) <= 1e-10 * np.max(np.abs(q_ref))
    np.testing.assert_allclose(reports[0].element_heat.sum(axis=0), heat_ref, rtol=1e-10)


def test_periodic_recycling_is_detected_from_image_flags_or_positions():
    lo, hi = np.zeros(3), np.array([1.0, 1.0, 0.05])
    before = np.array([[0, 0, 0.001], [0, 0, 0.030], [0, 0, 0.049], [0, 0, 0.020]])
    after = np.array([[0, 0, 0.049], [0, 0, 0.028], [0, 0, 0.001], [np.nan, np.nan, np.nan]])
    image_before = np.zeros((4, 3), dtype=int)
    image_after = image_before.copy()
    image_after[0, 2] = -1  # fell through z = 0 and re-entered at the top
    image_after[2, 2] = +1  # went up through the top: not a re-entry at the inlet
    expected = [True, False, False, False]
    assert integrate.wrapped(image_before, image_after, before, after, lo, hi, 2).tolist() == expected
    assert integrate.wrapped(None, None, before, after, lo, hi, 2).tolist() == expected


def test_per_region_solid_fraction_selects_the_rdf_of_each_region():
    """PP radiation looks the RDF up at the bulk solid fraction, PW radiation at the near-wall one."""
    modes = needing("rdf")
    walls = plane_walls()

    def tables(phi):
        s = spec(modes, walls={"hot": {"temperature": 800.0}}, solid_fraction=phi)
        return thermal_model.build(s, walls, {}, scenes.synthetic_rdf())

    split, bulk, near = tables({"bulk": 0.62, "near_wall": 0.48}), tables(0.62), tables(0.48)
    for a, b in ((split.tables["pp_radiation"], bulk.tables["pp_radiation"]),
                 (split.tables["pw_radiation"], near.tables["pw_radiation"])):  # fmt: skip
        assert a[:2] == b[:2] and np.array_equal(a.values, b.values)
    assert not np.allclose(bulk.tables["pp_radiation"].values, near.tables["pp_radiation"].values)  # the tables do depend on it
