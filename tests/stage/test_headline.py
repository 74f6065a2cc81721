"""The headline of a design variant (dpht.headline): h_w recovers a wall-to-bed conductance put into
a synthetic bed, and from the figures of the engineering test's analytic bed it gives that bed's
numbers."""

import csv
import io
import json
import math

import h5py
import numpy as np
import pytest

from dpht import headline
from dpht.closures import gas
from dpht.errors import DPHTError
from dpht.figures import scene as figures
from dpht.thermal.modes import NAMES, PW_MODES
from test_engineering import LENGTH, MASS_FLOW_DEM, T_OUT, bed, expected_bins  # noqa: F401 (bed: the fixture)
from test_figures import read_csv

BALANCE = {"window_s": 0.5, "inlet_temperature_K": 300.0, "outlet_temperature_K": 350.0, "mass_flow_kg_s": 0.01,
           "residual_W": 0.2, "residual_relative": 0.002, "residual_window_relative": 1e-15}  # fmt: skip
ALL_ON = {m: True for m in NAMES}
K_GAS = 0.05  # W/(m K), a constant gas


def uniform_case(h=180.0, wall=900.0, bed=(350.0, 400.0, 450.0, 500.0), area=(1e-4, 2e-4, 1.5e-4, 1e-4)):
    """Bins of heated wall at ``wall`` K over a bed at the local mixing-cup temperatures ``bed`` (K):
    each bin's heat is the conductance h A (T_w - T_b), split over the PW modes 1 : 2 : 1."""
    area, bed = np.array(area), np.array(bed)
    q = h * np.sum(area * (wall - bed))
    by_mode = dict(zip(PW_MODES, (0.25 * q, 0.5 * q, 0.25 * q)))
    return dict(area=area, wall_temperature=np.full(area.size, wall), bed_temperature=bed, wall_heat_by_mode=by_mode)


def make(case, **changes):
    arguments = dict(modes_on=ALL_ON, balance=BALANCE, particle_diameter=1e-3, gas_conductivity=lambda T: K_GAS,
                     error_estimate={"wall_heat": {"relative": 0.004}}, dem_seconds=60.0, thermal_seconds=5.0)  # fmt: skip
    return headline.headline("base", **{**case, **arguments, **changes})


def test_h_w_recovers_the_conductance_put_in():
    h = make(uniform_case(h=180.0))
    assert h.htc_W_m2K == pytest.approx(180.0, rel=1e-12)
    assert h.heated_area_m2 == pytest.approx(5.5e-4)
    assert h.wall_heat_W == pytest.approx(sum(uniform_case()["wall_heat_by_mode"].values()), rel=1e-15)
    assert h.nusselt == pytest.approx(180.0 * 1e-3 / K_GAS, rel=1e-12)
    assert h.wall_temperature_K == 900.0
    # Area-weighted: the bins of twice and 1.5 times the area pull the mean towards 400 and 450 K.
    assert h.bed_temperature_K == pytest.approx(np.average([350, 400, 450, 500], weights=[1, 2, 1.5, 1]), rel=1e-12)


def test_a_uniform_bed_and_wall():
    h = make(uniform_case(h=95.0, bed=(400.0,) * 4))
    assert h.difference_K == 500.0
    assert h.htc_W_m2K == pytest.approx(95.0, rel=1e-12)


def test_the_gas_conductivity_at_the_film_temperature():
    seen = []
    h = make(uniform_case(wall=1000.0, bed=(400.0,) * 4), gas_conductivity=lambda T: seen.append(T) or 0.04)
    assert seen == [700.0]
    assert h.gas_conductivity_W_mK == 0.04
    vacuum = make(uniform_case(), gas_conductivity=None)  # no gas: no Nusselt number of the gas
    assert math.isnan(vacuum.nusselt) and math.isnan(vacuum.gas_conductivity_W_mK)
    assert vacuum.htc_W_m2K == pytest.approx(180.0)


def test_bins_without_a_bed_temperature_are_left_out_of_the_mean():
    case = uniform_case(h=150.0, bed=(350.0, 400.0, 450.0, 500.0))
    case["bed_temperature"] = np.array([350.0, 400.0, 450.0, np.nan])  # no downward flow in the last bin
    # Q is of all bins and A_w all the heated area; the mean difference of the three with a T_b.
    q = sum(case["wall_heat_by_mode"].values())
    mean = np.average(900.0 - np.array([350.0, 400.0, 450.0]), weights=[1e-4, 2e-4, 1.5e-4])
    assert make(case).htc_W_m2K == pytest.approx(q / (5.5e-4 * mean), rel=1e-12)
    case["bed_temperature"][:] = np.nan
    assert math.isnan(make(case).htc_W_m2K)


def test_modes_off_and_particle_particle_modes_carry_no_wall_heat():
    case = uniform_case()
    off = make(case, modes_on={**ALL_ON, "pw_radiation": False})
    assert math.isnan(off.wall_heat_by_mode_W["pw_radiation"])
    assert off.wall_heat_W == pytest.approx(0.75 * make(case).wall_heat_W, rel=1e-12)
    with pytest.raises(DPHTError, match=r"wall heat of \['pfp'\]: only the particle-wall modes"):
        make({**case, "wall_heat_by_mode": {**case["wall_heat_by_mode"], "pfp": 1.0}})


def test_the_files():
    h = make(uniform_case())
    rows = list(csv.DictReader(io.StringIO(headline.csv_text(h))))
    assert len(rows) == 1 and rows[0]["variant"] == "base"
    assert float(rows[0]["htc_W_m2K"]) == h.htc_W_m2K  # round trip
    assert rows[0]["wall_heat_pp_contact_W"] == ""  # a particle-particle mode: no wall heat
    assert float(rows[0]["dem_seconds"]) == 60.0 and float(rows[0]["error_relative"]) == 0.004
    text = headline.markdown(h)
    assert "| wall-to-bed HTC h_w = Q / (A_w <T_w - T_b>) | 180 | W/(m2 K) |" in text
    assert "h_w = Q / (A_w <T_w - T_b>): A_w the heated (Dirichlet) wall area" in text
    assert "Sullivan" in text and "mixing-cup" in text
    record = headline.record(make(uniform_case(), gas_conductivity=None))
    assert record["nusselt"] is None and json.loads(json.dumps(record))["htc_W_m2K"] == pytest.approx(180.0)


def test_from_the_figures_of_an_analytic_bed(bed, tmp_path):  # noqa: F811 (the fixture)
    """The real figure functions on test_engineering's bed (wall 900 + 4000 z K, known flux, known
    mixing-cup temperatures and outlet); the headline read back from their files."""
    thermal = tmp_path / "thermal.h5"
    thermal.write_bytes(bed["thermal"].read_bytes())
    with h5py.File(thermal, "a") as f:  # the bed's run in air at 1 atm
        spec = json.loads(f.attrs["spec"])
        spec["thermal"]["gas"] = "air"
        f.attrs["spec"] = json.dumps(spec)
        enabled = set(json.loads(f.attrs["modes"]))
    engineering = figures.engineering(bed["positions"], thermal, bed["walls"], tmp_path / "engineering.png")
    flux = figures.wall_heat_flux(thermal, bed["walls"], tmp_path / "wall_heat_flux.png", zones=["heated_wall"])
    h = headline.from_outputs("base", engineering_png=engineering, wall_heat_flux_png=flux, thermal_h5=thermal,
                              dem_summary={"wall_time_s": {"settle": 1.5, "flow": 4.0}},
                              thermal_summary={"seconds": 2.5, "error_estimate": {"wall_heat": {"relative": 0.01}}})  # fmt: skip

    table = read_csv(engineering.with_suffix(".csv"))
    edges = np.append(table["distance_lo_m"], table["distance_hi_m"][-1])
    wall = 900.0 + 4000.0 * (LENGTH - table["distance_mean_m"])  # linear: the bin mean at the mean height
    bulk, _ = expected_bins(bed, edges)
    area = table["dirichlet_area_m2"]
    duty = bed["q"].sum()
    assert h.wall_heat_W == pytest.approx(duty, rel=1e-6)
    assert h.heated_area_m2 == pytest.approx(area.sum(), rel=1e-12)
    assert h.htc_W_m2K == pytest.approx(duty / (area.sum() * np.average(wall - bulk, weights=area)), rel=1e-6)
    film = 0.5 * (np.average(wall, weights=area) + np.average(bulk, weights=area))
    assert h.gas_conductivity_W_mK == pytest.approx(float(gas.conductivity("air", film)), rel=1e-6)
    assert h.outlet_temperature_K == pytest.approx(T_OUT, abs=1e-4)
    assert h.mass_flow_kg_s == MASS_FLOW_DEM
    assert h.modes_on == {m: m in enabled for m in NAMES}
    assert math.isnan(h.wall_heat_by_mode_W["pw_radiation"])  # off in this bed
    assert (h.dem_seconds, h.thermal_seconds, h.error_relative) == (5.5, 2.5, 0.01)
