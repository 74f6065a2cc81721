"""The hand-over field of a chain (dpht.chain.field): built from a segment's outlet particles,
sampled at the next segment's, with the mixing-cup enthalpy conserved across the hand-over."""

import math

import numpy as np
import pytest

from dpht.chain import field as hf
from dpht.chain.files import load_field, save_field
from dpht.closures import heat_capacity
from dpht.errors import DPHTError

R_TUBE = 4.5e-3  # m
D = 371.2e-6  # m
CP = "271.5 * T_C**0.1719"  # J/(kg K), the paper's Carbo HSP: c_p(T) mixes as energy, not temperature
TABLE = heat_capacity.build(heat_capacity.specific_heat(CP), 700.0, 1100.0)


def bed(n, seed, polydisperse=False):
    """``n`` particle centres uniform over the cross-section (m, within a radius of the wall), and radii."""
    rng = np.random.default_rng(seed)
    r = (R_TUBE - D / 2) * np.sqrt(rng.uniform(0, 1, n))
    theta = rng.uniform(0, 2 * np.pi, n)
    radius = rng.uniform(0.6, 1.4, n) * D / 2 if polydisperse else np.full(n, D / 2)
    return np.column_stack([r * np.cos(theta), r * np.sin(theta)]), radius


def profile(xy):
    """A wall boundary layer: 1073 K in the core, 800 K at the wall (K)."""
    rho = np.hypot(xy[:, 0], xy[:, 1]) / R_TUBE
    return 1073.15 - 273.0 * rho**4


def mean_enthalpy(T, radius):
    return float(np.sum(radius**3 * TABLE.enthalpy(T)) / np.sum(radius**3))


def test_uniform_field_round_trips_exactly():
    xy, radius = bed(3000, 1, polydisperse=True)
    T0 = 1073.15
    shells = np.full((xy.shape[0], 4), T0)
    stream = hf.Stream(xy, np.full(xy.shape[0], T0), radius, flux=np.random.default_rng(2).uniform(0.5, 2, xy.shape[0]),
                       shells=shells, shell_weight=np.full(4, 0.25))  # fmt: skip
    field = hf.build(stream, hf.CrossSection(8, 4, R_TUBE), TABLE)
    assert np.all(field.temperature == T0) and field.cup_temperature == T0
    target, target_radius = bed(2000, 3, polydisperse=True)
    handed = hf.assign(field, target, target_radius, TABLE)
    assert np.all(handed.temperature == T0)
    assert handed.correction == 0.0 and handed.residual == 0.0


@pytest.mark.parametrize("rings", [4, 8, 16])
def test_radial_profile_is_recovered_to_the_grid_resolution(rings):
    """Piecewise constant on equal-area rings: the error at a point is at most the profile's change
    across its ring (plus the ring's sampling noise, none here: the profile is exactly radial)."""
    xy, radius = bed(40000, 4)
    grid = hf.CrossSection(rings, 1, R_TUBE)
    field = hf.build(hf.Stream(xy, profile(xy), radius), grid, TABLE)
    target, _ = bed(5000, 5)
    error = np.abs(field.sample(target)[:, 0] - profile(target))
    edges = grid.ring_edges()
    ring = grid.cell_of(target)
    bound = profile(np.column_stack([edges[ring], 0 * ring])) - profile(np.column_stack([edges[ring + 1], 0 * ring]))
    assert np.all(error <= bound + 1e-9)
    # And the error shrinks with the grid: the ring widths at the wall set it.
    assert error.max() <= 273.0 * (1 - (1 - 1 / rings) ** 2) + 1e-9


@pytest.mark.parametrize("seed", range(5))
def test_enthalpy_is_conserved_to_round_off_on_random_beds(seed):
    """Random profile, noise, radii and fluxes; the receiving bed packed otherwise: the correction
    is not zero, and after it the mixing-cup enthalpy in equals the mass-weighted enthalpy out."""
    rng = np.random.default_rng(seed)
    xy, radius = bed(int(rng.integers(500, 3000)), 10 + seed, polydisperse=True)
    T = profile(xy) * rng.uniform(0.9, 1.0) + rng.normal(0, 5, xy.shape[0])
    flux = rng.uniform(0.2, 1.0, xy.shape[0])
    grid = hf.CrossSection(int(rng.integers(2, 12)), int(rng.integers(1, 6)), R_TUBE)
    field = hf.build(hf.Stream(xy, T, radius, flux=flux), grid, TABLE)
    h = TABLE.enthalpy(T)
    h_in = math.fsum(radius**3 * flux * h) / math.fsum(radius**3 * flux)
    assert field.cup_enthalpy(TABLE) == pytest.approx(h_in, rel=1e-13, abs=0)
    target, target_radius = bed(int(rng.integers(500, 3000)), 20 + seed, polydisperse=True)
    handed = hf.assign(field, target, target_radius, TABLE)
    h_out = math.fsum(target_radius**3 * TABLE.enthalpy(handed.temperature[:, 0])) / math.fsum(target_radius**3)
    assert abs(h_out - h_in) <= 1e-13 * abs(h_in)
    assert handed.correction != 0.0 and abs(handed.residual) <= 1e-13 * abs(h_in)
    # The correction in kelvin is the shift divided by c_p at the cup temperature.
    cp = 271.5 * (field.cup_temperature - 273.15) ** 0.1719
    assert handed.correction_K == pytest.approx(handed.correction / cp, rel=1e-3)


def test_mixing_is_weighted_by_mass_not_by_count():
    """Two particle sizes in one cell, at two temperatures: the cell's temperature is the enthalpy
    mean weighted by r^3, so eight small particles weigh as one large one."""
    xy = np.zeros((9, 2))
    radius = np.array([D] + [D / 2] * 8)
    T = np.array([1000.0] + [800.0] * 8)
    field = hf.build(hf.Stream(xy, T, radius), hf.CrossSection(1, 1, R_TUBE), TABLE)
    expected = TABLE.temperature(0.5 * (TABLE.enthalpy(1000.0) + TABLE.enthalpy(800.0)))
    assert field.temperature[0, 0] == pytest.approx(float(expected), abs=1e-9)
    assert field.temperature[0, 0] != pytest.approx(np.mean(T))  # not the count's mean (822 K)
    # And the flux factor weighs as mass: a slow large particle counts as much as its mass times speed.
    slow = hf.build(hf.Stream(xy, T, radius, flux=np.array([0.125] + [1.0] * 8)), hf.CrossSection(1, 1, R_TUBE), TABLE)
    expected = TABLE.temperature((TABLE.enthalpy(1000.0) + 8 * TABLE.enthalpy(800.0)) / 9)
    assert slow.temperature[0, 0] == pytest.approx(float(expected), abs=1e-9)


def test_received_polydisperse_particles_conserve_by_mass():
    """The receiving particles' mean enthalpy is weighted by their masses: a bed of large particles
    in the hot core and small ones at the cold wall needs a different shift than a monodisperse one."""
    xy, radius = bed(5000, 7)
    field = hf.build(hf.Stream(xy, profile(xy), radius), hf.CrossSection(8, 1, R_TUBE), TABLE)
    target, _ = bed(3000, 8)
    rho = np.hypot(target[:, 0], target[:, 1]) / R_TUBE
    graded = np.where(rho < 0.5, 1.3, 0.7) * D / 2
    mono = hf.assign(field, target, D / 2, TABLE)
    poly = hf.assign(field, target, graded, TABLE)
    assert poly.correction < mono.correction  # the hot core weighs more: shifted down
    assert mean_enthalpy(poly.temperature[:, 0], graded) == pytest.approx(field.cup_enthalpy(TABLE), rel=1e-13)


def test_shells_are_mapped_and_conserved():
    xy, radius = bed(2000, 9)
    T = profile(xy)
    surface = T - 20.0 * np.hypot(xy[:, 0], xy[:, 1]) / R_TUBE  # the surface colder towards the wall
    weight = np.array([0.1, 0.3, 0.6])
    shells = np.column_stack([T + 0.4 * (T - surface), T + 0.1 * (T - surface), surface])
    T = TABLE.temperature(TABLE.enthalpy(shells) @ weight)  # the particles' means, of their nodes
    field = hf.build(hf.Stream(xy, T, radius, shells=shells, shell_weight=weight), hf.CrossSection(6, 1, R_TUBE), TABLE)
    assert field.shells == 3
    handed = hf.assign(field, *bed(1000, 10), TABLE)
    assert handed.temperature.shape == (1000, 4)
    assert np.all(handed.temperature[:, 3] < handed.temperature[:, 1])
    # The nodes are shifted with the mean: the particle's mean enthalpy is its nodes' weighted mean.
    np.testing.assert_allclose(handed.enthalpy[:, 1:] @ weight, handed.enthalpy[:, 0], rtol=1e-12)
    np.testing.assert_array_equal(field.shell_weight, weight)


def test_empty_cells_take_the_nearest_filled_cell():
    xy = np.array([[0.1e-3, 0.0], [4.4e-3, 0.0]])  # in the first and the last of 8 rings
    field = hf.build(hf.Stream(xy, np.array([1000.0, 800.0]), np.full(2, D / 2)), hf.CrossSection(8, 1, R_TUBE), TABLE)
    assert field.filled == 6
    ring_T = field.temperature[:, 0]
    assert ring_T[0] == 1000.0 and ring_T[-1] == 800.0
    # Ring centres at R sqrt((k + 1/2) / 8): rings 1-2 lie nearer the axis's sample, 3-6 the wall's.
    assert np.all(ring_T[1:3] == 1000.0) and np.all(ring_T[3:7] == 800.0)


def test_file_round_trip(tmp_path):
    xy, radius = bed(500, 11)
    field = hf.build(hf.Stream(xy, profile(xy), radius), hf.CrossSection(5, 3, R_TUBE), TABLE)
    save_field(tmp_path / "field.h5", field)
    again = load_field(tmp_path / "field.h5")
    assert again.grid == field.grid and again.cup_temperature == field.cup_temperature
    for name in ("temperature", "weight", "count", "shell_weight"):
        np.testing.assert_array_equal(getattr(again, name), getattr(field, name))
    (tmp_path / "other.h5").write_bytes(b"not hdf5")
    with pytest.raises(DPHTError, match="hand-over field"):
        load_field(tmp_path / "other.h5")


def test_bad_streams_are_refused():
    xy, radius = bed(10, 12)
    with pytest.raises(DPHTError, match="temperature must be finite"):
        hf.Stream(xy, np.full(10, np.nan), radius)
    with pytest.raises(DPHTError, match="expected xy"):
        hf.Stream(xy[:5], np.full(10, 900.0), radius)
    with pytest.raises(DPHTError, match="rings and sectors"):
        hf.CrossSection(0, 1, R_TUBE)
    field = hf.build(hf.Stream(xy, np.full(10, 900.0), radius), hf.CrossSection(2, 1, R_TUBE), TABLE)
    with pytest.raises(DPHTError, match="finite position"):
        hf.assign(field, np.array([[np.nan, 0.0]]), D / 2, TABLE)
