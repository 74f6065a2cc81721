"""The engineering figure's numbers on a synthetic flowing bed where they are known: a plug flow whose
speed grows towards the wall (so the mass-flux weighting matters), a prescribed temperature field,
a known wall heat flux and a wall temperature expression of z, c_p linear in T (so the enthalpy
mean is not the temperature mean), and energy bookkeeping with a known leak."""

import json

import h5py
import numpy as np
import pytest

from dpht.dem import dumps
from dpht.errors import DPHTError
from dpht.figures import scene as figures
from test_figures import (FLUX_A, FLUX_B, LENGTH, MODES, PARTICLE_RADIUS, TIME, TUBE_RADIUS, known_element_heat,
                          read_csv, tube_walls, write_thermal, write_walls)

T_IN = 303.15  # K
CP = (500.0, 0.8)  # c_p = a + b T, J/(kg K)
DENSITY = 3560.0  # kg/m^3
SPEED = 0.02  # m/s on the axis; 1.5 times that at r = R
DUMP_INTERVAL, TIMESTEP = 1000, 1e-4  # a frame every 0.1 s, the times of TIME
WALL = "900 + 4000 * z"  # K, z in m
GRADIENT, RADIAL = 8000.0, 150.0  # K/m down the tube, K from the axis to r = R
T_OUT = 650.0  # K, the leaving particles' temperature in the bookkeeping
MASS_FLOW_DEM = 1.3e-3  # kg/s, the DEM summary's
LEAK = 0.7  # W gained by the particles from no modelled source
MASS = DENSITY * 4.0 / 3.0 * np.pi * PARTICLE_RADIUS**3


def enthalpy(T):
    a, b = CP
    return a * T + 0.5 * b * T**2


def temperature_of(h):
    a, b = CP
    return (-a + np.sqrt(a * a + 2.0 * b * h)) / b


def lattice():
    spacing = 2.2 * PARTICLE_RADIUS
    grid = np.arange(-TUBE_RADIUS + 1.5 * PARTICLE_RADIUS, TUBE_RADIUS - 1.5 * PARTICLE_RADIUS, spacing)
    x, y, z = np.meshgrid(grid, grid, np.arange(0.5 * spacing, LENGTH, spacing), indexing="ij")
    inside = np.hypot(x, y) < TUBE_RADIUS - 1.5 * PARTICLE_RADIUS
    return np.column_stack([x[inside], y[inside], z[inside]])


@pytest.fixture(scope="module")
def bed(tmp_path_factory):
    root = tmp_path_factory.mktemp("engineering")
    start = lattice()
    n = len(start)
    r = np.hypot(start[:, 0], start[:, 1])
    speed = SPEED * (1.0 + 0.5 * r / TUBE_RADIUS)
    box_lo, box_hi = np.array([-TUBE_RADIUS, -TUBE_RADIUS, 0.0]), np.array([TUBE_RADIUS, TUBE_RADIUS, LENGTH])
    ids = np.arange(1, n + 1)
    frames, centres, images = [], [], []
    for k, t in enumerate(TIME):
        unwrapped = start - np.outer(speed * t, [0.0, 0.0, 1.0])
        image = np.zeros((n, 3), dtype=np.int32)
        image[:, 2] = np.floor(unwrapped[:, 2] / LENGTH).astype(np.int32)
        wrapped = unwrapped - image * [0.0, 0.0, LENGTH]
        centres.append(wrapped)
        images.append(image[:, 2])
        frames.append(dumps.DumpFrame(DUMP_INTERVAL * k, box_lo, box_hi, (False, False, True), ids, wrapped, image))
    positions = root / "positions.h5"
    dumps.write_positions(positions, frames, radius=PARTICLE_RADIUS, density=DENSITY, timestep=TIMESTEP,
                          dump_interval=DUMP_INTERVAL, summary={"mass_flow_second_half_kg_s": MASS_FLOW_DEM},
                          attrs={"recycled": [False, False, True]})
    centres = np.array(centres)
    temperature = T_IN + GRADIENT * (LENGTH - centres[..., 2]) + RADIAL * (r / TUBE_RADIUS)[None, :]

    table = tube_walls()
    heat, q = known_element_heat(table)
    # Bookkeeping: every particle crossing z = 0 in an interval leaves at T_OUT and is reset to T_IN.
    leaving = np.array([np.count_nonzero(b < a) for a, b in zip(images[:-1], images[1:])])
    recycled = np.concatenate([[0.0], np.cumsum(-MASS * leaving * (enthalpy(T_OUT) - enthalpy(T_IN)))])
    wall = np.concatenate([[0.0], np.cumsum(heat[:-1].sum(axis=(1, 2)) * np.diff(TIME))])
    thermal = write_thermal(root / "thermal.h5", ids=ids, temperature=temperature, element_heat=heat,
                            particles=5.0 + wall + recycled + LEAK * TIME, recycled=recycled)
    spec = {"particles": {"density": DENSITY, "diameter": 2 * PARTICLE_RADIUS, "specific_heat": f"{CP[0]} + {CP[1]} * T"},
            "thermal": {"walls": {"heated_wall": {"temperature": WALL}, "adiabatic_wall": "adiabatic",
                                  "orifice": "adiabatic"}}}
    with h5py.File(thermal, "a") as f:
        f.attrs["spec"] = json.dumps(spec)
        f["dem_frame"] = np.arange(len(TIME))
    return {"root": root, "positions": positions, "thermal": thermal, "walls": write_walls(root / "walls.h5", table),
            "centres": centres, "temperature": temperature, "speed": speed, "q": q, "leaving": leaving, "r": r}


def expected_bins(bed, edges):
    """Mixing-cup temperature and mass flow per bin, from the analytic enthalpy over the samples of
    the window's intervals 5..9 (each at its start, weighted by its downward displacement)."""
    weight, weighted_h = np.zeros(edges.size - 1), np.zeros(edges.size - 1)
    for k in range(5, 10):
        distance = LENGTH - bed["centres"][k][:, 2]
        index = np.digitize(distance, edges) - 1
        inside = (index >= 0) & (index < edges.size - 1)
        down = bed["speed"] * (TIME[k + 1] - TIME[k])
        weight += np.bincount(index[inside], MASS * down[inside], minlength=edges.size - 1)
        weighted_h += np.bincount(index[inside], MASS * down[inside] * enthalpy(bed["temperature"][k][inside]),
                                  minlength=edges.size - 1)
    return temperature_of(weighted_h / weight), weight / (0.5 * np.diff(edges))


def test_profiles_match_the_analytic_bed(bed, tmp_path):
    png = figures.engineering(bed["positions"], bed["thermal"], bed["walls"], tmp_path / "engineering.png")
    table = read_csv(png.with_suffix(".csv"))
    edges = np.append(table["distance_lo_m"], table["distance_hi_m"][-1])
    z_mean = LENGTH - table["distance_mean_m"]
    # Linear fields: an area-weighted bin mean is the field at the area-weighted mean height.
    wall = 900.0 + 4000.0 * z_mean
    flux = (FLUX_A + FLUX_B * z_mean[:, None]).sum(axis=1)
    np.testing.assert_allclose(table["wall_temperature_K"], wall, rtol=1e-12)
    np.testing.assert_allclose(table["flux_W_m2"], flux, rtol=1e-6)
    bulk, mass_flow = expected_bins(bed, edges)
    # The enthalpy table interpolates h linearly between nodes 0.25 K apart: |error| <= b dT^2 / 8 in h.
    np.testing.assert_allclose(table["bed_temperature_K"], bulk, rtol=0, atol=1e-4)
    np.testing.assert_allclose(table["mass_flow_kg_s"], mass_flow, rtol=1e-9)
    np.testing.assert_allclose(table["htc_W_m2K"], flux / (wall - bulk), rtol=1e-6)
    # The weighting matters here: the plain mean temperature of the bins differs by kelvins.
    plain = np.array([bed["temperature"][5:10][(np.digitize(LENGTH - bed["centres"][5:10, :, 2], edges) - 1) == i].mean()
                      for i in range(edges.size - 1)])
    assert np.min(np.abs(plain - bulk)) > 1.0


def test_energy_balance_terms(bed, tmp_path):
    figures.engineering(bed["positions"], bed["thermal"], bed["walls"], tmp_path / "engineering.png")
    balance = json.loads((tmp_path / "engineering.json").read_text())
    span = TIME[10] - TIME[5]
    duty = bed["q"].sum()
    leaving = bed["leaving"][5:10].sum()
    assert leaving > 50
    removed = MASS * leaving * (enthalpy(T_OUT) - enthalpy(T_IN)) / span  # W carried out by the flow
    assert balance["duty_W"] == pytest.approx(duty, rel=1e-6)
    assert balance["outlet_particles"] == leaving
    assert balance["outlet_temperature_K"] == pytest.approx(T_OUT, abs=1e-4)
    assert balance["mass_flow_window_kg_s"] == pytest.approx(MASS * leaving / span, rel=1e-12)
    assert balance["storage_W"] == pytest.approx(duty - removed + LEAK, rel=1e-9)
    assert balance["rise_window_W"] == pytest.approx(removed, rel=1e-6)
    assert balance["residual_window_W"] == pytest.approx(-LEAK, rel=1e-6)  # the leak, and nothing else
    rise = MASS_FLOW_DEM * (enthalpy(T_OUT) - enthalpy(T_IN))
    assert balance["rise_W"] == pytest.approx(rise, rel=1e-6)
    assert balance["residual_W"] == pytest.approx(removed - rise - LEAK, rel=1e-6)
    assert balance["residual_relative"] == pytest.approx(balance["residual_W"] / duty, rel=1e-12)


def test_small_differences_leave_the_htc_undefined(bed, tmp_path):
    wall_minus_bulk = figures.engineering_profile(bed["positions"], bed["thermal"], bed["walls"])
    difference = wall_minus_bulk["wall_temperature"] - wall_minus_bulk["bed_temperature"]
    threshold = np.median(np.abs(difference))
    profile = figures.engineering_profile(bed["positions"], bed["thermal"], bed["walls"], min_difference=threshold)
    assert np.array_equal(np.isnan(profile["htc"]), np.abs(difference) < threshold)
    with pytest.raises(DPHTError, match="min_difference"):
        figures.engineering_profile(bed["positions"], bed["thermal"], bed["walls"], min_difference=0.0)


def test_runs_without_the_needed_records_are_refused(bed, tmp_path):
    ids = np.arange(1, bed["centres"].shape[1] + 1)
    heat, _ = known_element_heat(tube_walls())
    bare = write_thermal(tmp_path / "bare.h5", ids=ids, temperature=bed["temperature"], element_heat=heat)
    with pytest.raises(DPHTError, match="bare.h5.*spec"):
        figures.engineering_profile(bed["positions"], bare, bed["walls"])
    with h5py.File(bed["thermal"]) as f, h5py.File(tmp_path / "slice.h5", "w") as g:
        for name in f:
            f.copy(name, g)
        g.attrs.update(f.attrs)
        spec = json.loads(f.attrs["spec"])
        g.attrs["spec"] = json.dumps({**spec, "thermal": {**spec["thermal"], "slice": {"inlet_height": 1.0}}})
    with pytest.raises(DPHTError, match="thermal.slice"):
        figures.engineering_profile(bed["positions"], tmp_path / "slice.h5", bed["walls"])
