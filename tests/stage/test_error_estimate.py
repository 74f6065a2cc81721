"""The error estimate of every thermal run (issue 15): its pure parts against exact answers, and
the whole estimate against the exact error of a run whose converged answer is known."""

import json
import math

import numpy as np
import pytest
from test_thermal_stage import R, make_scene, run_stage

from dpht.closures import htc
from dpht.thermal import error_estimate


def test_richardson_recovers_the_error_of_a_first_order_sequence():
    exact, c = 2.0, 0.3
    fine, coarse = exact + c * 0.01, exact + c * 0.02
    assert error_estimate.richardson(coarse, fine) == pytest.approx(fine - exact)


def _bilinear_mean_error(values, d, t, f, samples=200_000, seed=0):
    """Exact mean signed relative error of bilinear interpolation of the table of ``f``, by sampling."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(d[0], d[-1], samples), rng.uniform(t[0], t[-1], samples)
    table = htc.HTCTable("pfp", d, t, values, radius=R, k_solid=1.0, solid_fraction=0.6)
    return float(np.mean(htc.interpolate(table, x, y) / f(x, y) - 1.0))


def test_tabulation_error_matches_the_exact_interpolation_error():
    d, t = np.linspace(1.0, 3.0, 21), np.linspace(300.0, 1300.0, 11)

    def f(x, y):  # convex in both, like an HTC in distance and radiation in temperature
        return 1.0 / x**2 * (1.0 + (y / 1000.0) ** 3)

    values = f(d[:, None], t[None, :])
    estimate = error_estimate.table_interpolation_error(values)
    exact = _bilinear_mean_error(values, d, t, f)
    assert estimate == pytest.approx(exact, rel=0.25), (estimate, exact)


def test_rdf_standard_error_of_independent_equal_entries():
    d = np.linspace(1.0, 7.0, 25)
    rel = error_estimate.rdf_relative_stderr(d, np.ones(25), np.full(25, 0.1), cutoff=7.0, shell=False)
    assert rel == pytest.approx(0.1 / math.sqrt(25))
    assert error_estimate.rdf_relative_stderr(d, np.ones(25), np.full(25, 0.1), cutoff=4.0, shell=False) > rel


@pytest.fixture(scope="module")
def fine_scene(tmp_path_factory):
    """The thermal stage's sinking bed dumped four times as often (frames 0.0025 s apart)."""
    return make_scene(tmp_path_factory.mktemp("estimate"), n_frames=81, dump_interval=250)


def test_estimate_is_within_a_factor_of_two_of_the_exact_error(fine_scene):
    runs = {stride: run_stage(fine_scene, f"stride{stride}", frame_stride=stride)[1] for stride in (1, 2, 4)}
    # The converged wall heat: Richardson extrapolation of the two finest runs (first order in the step).
    converged = 2 * runs[1]["wall_energy_J"] - runs[2]["wall_energy_J"]
    for stride in (2, 4):
        exact = runs[stride]["wall_energy_J"] / converged - 1.0
        estimate = runs[stride]["error_estimate"]
        assert 0.5 <= estimate["time_step"]["wall_heat"] / exact <= 2.0, (stride, estimate["time_step"], exact)
        # the whole estimate adds the tables' errors, which all these runs share
        assert estimate["wall_heat"]["relative"] >= abs(estimate["time_step"]["wall_heat"])
        json.dumps(estimate)  # goes into summary.json as it is
    parts = runs[4]["error_estimate"]["wall_heat"]["parts"]
    assert set(parts) == {"time_step", "pfw_table", "pfp_table_bound", "pw_rdf", "pp_rdf_bound"}


def test_pfw_tabulation_error_at_contact_exceeds_the_table_average():
    """Most particle-wall pairs sit near contact, where the PFW conductance has a kink: there the
    table's error is larger than its average over the table (why the stage takes the pairs met)."""
    lo, cutoff = htc.default_distance_range("pfw", R)[0], 1.5 * R
    table = htc.build_table("pfw", radius=R, k_solid=2.0, solid_fraction=0.54, distance_range=(lo, cutoff),
                            n_distance=25, temperature_range=(250.0, 1400.0), n_temperature=8)  # fmt: skip
    rng = np.random.default_rng(1)
    for met in (rng.uniform(lo, cutoff, 20000), np.clip(rng.normal(R, 0.02 * R, 20000), lo, cutoff)):
        T = np.full_like(met, 600.0)
        exact = htc.pfw(met, T, radius=R, k_solid=2.0, solid_fraction=0.54)
        error = error_estimate.tabulation_error(htc.interpolate(table, met, T), exact)
        assert error == pytest.approx(np.sum(htc.interpolate(table, met, T)) / np.sum(exact) - 1)
        if met.std() > 0.1 * R:
            uniform = abs(error)
        else:
            assert abs(error) > 3 * uniform, (error, uniform)
