"""RDF table format: save/load, solid-fraction and emissivity interpolation."""

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
