"""RDF table format: save/load, solid-fraction and emissivity interpolation."""

import h5py
import numpy as np
import pytest

from dpht.closures import rdf
from dpht.errors import DPHTError

D = np.linspace(2.0, 10.0, 17)
PHI = np.array([0.45, 0.55, 0.64])


def table(eps_p, eps_w, d=D):
    """RDFs that are linear in both emissivities, so interpolation must be exact."""
    pp = (0.05 + 0.03 * eps_p) * np.exp(-(d - 2.0))[None, :] * (1 + PHI[:, None])
    pw = (0.2 + 0.1 * eps_p + 0.2 * eps_w) * np.exp(-(d - 2.0))[None, :] * (1 + PHI[:, None])
    err = np.full_like(pp, 1e-3)
    return rdf.RDFTables(rdf.RDFTable(d, PHI, pp, err, rays=100), rdf.RDFTable(d, PHI, pw, err, rays=100), eps_p, eps_w)


def test_save_load_round_trip(tmp_path):
    t = table(0.65, 0.6)
    rdf.save(tmp_path / "t.h5", t)
    back = rdf.load(tmp_path / "t.h5")
    np.testing.assert_array_equal(back.pw.rdf, t.pw.rdf)
    assert (back.particle_emissivity, back.wall_emissivity, back.pp.rays) == (0.65, 0.6, 100)


def test_emissivity_interpolation_on_a_grid_is_exact_for_linear_dependence():
    grid = [table(p, w) for p in (0.6, 0.9) for w in (0.4, 1.0)]
    mixed = rdf.for_emissivities(grid, 0.7, 0.55)
    expected = table(0.7, 0.55)
    np.testing.assert_allclose(mixed.pp.rdf, expected.pp.rdf, rtol=1e-13)
    np.testing.assert_allclose(mixed.pw.rdf, expected.pw.rdf, rtol=1e-13)
    assert np.all(mixed.pw.stderr < 1e-3)  # a weighted mean of independent estimates
    one = rdf.for_emissivities([table(0.65, 0.6)], 0.65, 0.6)
    np.testing.assert_array_equal(one.pp.rdf, table(0.65, 0.6).pp.rdf)


def test_emissivity_interpolation_errors():
    with pytest.raises(DPHTError, match="outside the built RDF tables"):
        rdf.for_emissivities([table(0.6, 0.4), table(0.9, 0.4)], 0.95, 0.4)
    with pytest.raises(DPHTError, match="grid of emissivities"):
        rdf.for_emissivities([table(0.6, 0.4), table(0.9, 1.0)], 0.7, 0.5)
    with pytest.raises(DPHTError, match="share their distance"):
        rdf.for_emissivities([table(0.6, 0.4), table(0.9, 0.4, d=D * 1.1)], 0.7, 0.4)


def test_solid_fraction_interpolation():
    t = table(0.65, 0.6).pp
    d0, dd, values = t.at_solid_fraction(0.5, n_distance=len(D))
    assert d0 == D[0] and dd == pytest.approx(D[1] - D[0])
    np.testing.assert_allclose(values, 0.5 * (t.rdf[0] + t.rdf[1]), rtol=1e-12)
    with pytest.raises(DPHTError, match="outside"):
        t.at_solid_fraction(0.2)


def test_files_say_which_solid_fraction_indexes_each_table(tmp_path):
    """PP is read at the bulk solid fraction, PW at the near-wall one; the file says so, and a file
    that says otherwise, or an old-format file (PW keyed by its slab's bulk), is refused."""
    path = tmp_path / "t.h5"
    rdf.save(path, table(0.65, 0.6))
    with h5py.File(path, "r+") as f:
        assert (f["pp"].attrs["solid_fraction_region"], f["pw"].attrs["solid_fraction_region"]) == ("bulk", "near_wall")
        f["pw"].attrs["solid_fraction_region"] = "bulk"
    with pytest.raises(DPHTError, match="solid_fraction_region = 'bulk'; expected 'near_wall'"):
        rdf.load(path)
    with h5py.File(path, "r+") as f:
        del f["pw"].attrs["solid_fraction_region"]
        f.attrs["format"] = "dpht-rdf-1"
    with pytest.raises(DPHTError, match="old format dpht-rdf-1.*rebuild it"):
        rdf.load(path)


def test_samples_and_binning_errors_round_trip_and_mix():
    t = table(0.65, 0.6)
    counts = np.full(t.pp.rdf.shape, 40)
    binning = np.full(t.pp.rdf.shape, 1e-4)
    pp = rdf.RDFTable(t.pp.distance, PHI, t.pp.rdf, t.pp.stderr, 100, counts, binning, 5e-4, 20)
    tables = [rdf.RDFTables(pp, pp, p, 0.6) for p in (0.6, 0.9)]
    mixed = rdf.for_emissivities(tables, 0.7, 0.6)
    assert np.all(mixed.pp.samples == 40) and np.allclose(mixed.pp.binning_error, 1e-4)
    assert (mixed.pp.stderr_target, mixed.pp.min_samples) == (5e-4, 20)


def test_default_resampling_keeps_the_narrowest_bins():
    """The default uniform grid has four points per narrowest bin: a table with 0.01 R bins at
    contact comes back through the grid unchanged at its nodes."""
    d = np.concatenate([np.arange(2.005, 2.1, 0.01), np.arange(2.125, 6.0, 0.05)])
    values = np.exp(-5 * (d - 2.0))[None, :].repeat(3, axis=0)
    t = rdf.RDFTable(d, PHI, values, np.zeros_like(values))
    d0, dd, grid = t.at_solid_fraction(0.5)
    assert dd <= 0.01 / 4 + 1e-12
    assert np.abs(np.interp(d, d0 + dd * np.arange(grid.size), grid) - values[0]).max() < 2e-4 * values[0, 0]
