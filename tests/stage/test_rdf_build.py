"""RDF tables from traced packings, and the ``rdf`` command for one bed."""

import h5py
import numpy as np
import pytest

from dpht.closures import rdf
from dpht.radiation import tables as rdf_build
from dpht.__main__ import main
from dpht.errors import DPHTError
from dpht.radiation.raytrace import PlaneWall, trace
from dpht.verification.cases.radiation import sphere_sphere_view_factor


def test_binned_mean_and_cluster_standard_error():
    """Bin means are pair averages; the standard error is the delta-method one across emitters,
    checked here against its definition written out for one bin."""
    rng = np.random.default_rng(0)
    n_clusters = 30
    cluster = rng.integers(0, n_clusters, 3000)
    distance = rng.uniform(2.0, 4.0, 3000)
    value = 1.0 / distance + 0.01 * rng.standard_normal(3000)
    edges = np.array([2.0, 3.0, 4.0, 5.0])
    mean, stderr, samples = rdf_build.binned_mean(cluster, distance, value, edges, n_clusters)
    first = distance < 3.0
    assert mean[0] == pytest.approx(value[first].mean())
    s = np.bincount(cluster[first], value[first], n_clusters)
    p = np.bincount(cluster[first], None, n_clusters)
    expected = np.sqrt(n_clusters / (n_clusters - 1) * np.sum((s - mean[0] * p) ** 2)) / p.sum()
    assert stderr[0] == pytest.approx(expected)
    assert samples[0] == np.unique(cluster[first]).size
    assert np.isnan(mean[2]) and np.isnan(stderr[2]) and samples[2] == 0  # no samples beyond 4


LOOSE = (5e-3, 2e-2)  # stated standard errors a few hundred rays reach


@pytest.fixture(scope="module")
def black_tables():
    """Black particles and walls at one dilute solid fraction, with few rays: a quick build
    through the whole pipeline. For black surfaces an RDF is a view factor inside the bed."""
    return rdf_build.build_tables(
        1.0, 1.0, [0.25], pw_solid_fractions=[0.2], rays=400, n_particles=1700, emitters=1000, seed=3, stderr=LOOSE
    )


def test_tables_fall_with_distance_and_every_entry_is_measured(black_tables, tmp_path):
    # Neighbours can only shadow: near contact the RDF lies below the free-space view factor of
    # two touching spheres (quadrature) or of a sphere touching a plane (1/2), but not far below
    # in a dilute bed.
    free = {"pp": sphere_sphere_view_factor(2.0001), "pw": 0.5}
    for kind, target in zip(("pp", "pw"), LOOSE):
        table = getattr(black_tables, kind)
        assert table.rays == 400
        assert np.all(np.isfinite(table.rdf)) and np.all(table.rdf >= 0)
        assert 0.6 * free[kind] < table.rdf[0, 0] < free[kind] + 3 * table.stderr[0, 0]
        assert table.rdf[0, -1] < 0.02 * table.rdf[0, 0]
        assert rdf_build.monotone_violations(table) == []
        # Every entry from enough emitters to reach the stated standard error; nothing interpolated.
        assert table.stderr_target == target and table.min_samples == rdf_build.MIN_SAMPLES
        assert np.all(table.stderr <= target) and np.all(table.samples >= rdf_build.MIN_SAMPLES)
        assert np.all(np.isfinite(table.binning_error)) and np.all(table.binning_error >= 0)
    assert "pinned emitters" in black_tables.source
    rdf.save(tmp_path / "t.h5", black_tables)
    loaded = rdf.load(tmp_path / "t.h5")
    assert np.array_equal(loaded.pw.rdf, black_tables.pw.rdf) and loaded.pp.rays == 400
    assert np.array_equal(loaded.pw.samples, black_tables.pw.samples)
    assert np.array_equal(loaded.pp.binning_error, black_tables.pp.binning_error)
    with h5py.File(tmp_path / "t.h5") as f:
        assert f["pp"].attrs["solid_fraction_region"] == "bulk" and f["pw"].attrs["solid_fraction_region"] == "near_wall"


def test_binning_error_finds_a_kink_that_wide_bins_smooth():
    """Samples of a V-shaped RDF (the shadowing dip at two diameters, exaggerated): bins 0.25 R wide
    that straddle the kink miss its bottom by far more than the noise; the table's bins do not."""
    rng = np.random.default_rng(4)
    n = 400
    cluster = np.repeat(np.arange(n), 400)
    distance = rng.uniform(3.5, 4.5, cluster.size)
    value = 0.002 + 0.004 * np.abs(distance - 4.0) + 1e-4 * rng.standard_normal(cluster.size)
    data = rdf_build.Samples(cluster, distance, value, n)
    wide = rdf_build.Row.measure(data, np.arange(3.5, 4.5 + 1e-9, 0.25))
    fine = rdf_build.Row.measure(data, rdf_build._steps(3.5, (3.8, 0.05), (4.2, 0.025), (4.5, 0.05)))
    # A chord over 4 +- 0.125 misses the vertex by 0.004 * 0.125 / 2 = 2.5e-4. (At both ends the
    # table holds its end values over half a bin: 0.004 * 0.025 = 1e-4 there.)
    assert wide.binning_error.max() > 1.5e-4
    assert fine.binning_error[1:-1].max() < 4e-5 and fine.binning_error[[0, -1]].max() < 1.2e-4


@pytest.mark.parametrize(
    "args, kwargs, message",
    [
        ((0.0, 0.5), {}, "particle_emissivity"),
        ((0.5, 1.1), {}, "wall_emissivity"),
        ((0.5, 0.5, [0.45, 0.35]), {}, "solid_fractions"),
        ((0.5, 0.5, [0.64]), {"n_particles": 3000}, "n_particles = 3000 is too small"),
        ((0.5, 0.5), {"pw_solid_fractions": [0.3, 0.7]}, "pw_solid_fractions"),
        ((0.5, 0.5), {"emitters": 5}, "at least 20 emitters"),
        ((0.5, 0.5), {"format": "dpht-rdf-1"}, "cannot be built"),
    ],
)
def test_build_rejects_bad_arguments(args, kwargs, message):
    with pytest.raises(DPHTError, match=message):
        rdf_build.build_tables(*args, **kwargs)


def test_monotone_check_flags_a_rise():
    rises = np.array([[0.05, 0.06, 0.01]])
    table = rdf.RDFTable(np.array([2.0, 3.0, 4.0]), np.array([0.5]), rises, np.full((1, 3), 1e-3))
    assert rdf_build.monotone_violations(table) == [(0.5, 2.0, 3.0)]


# --------------------------------------------------------------------------------------------
# python -m dpht rdf


def run_cli(tmp_path, lines, *extra):
    positions = tmp_path / "bed.txt"
    positions.write_text("\n".join(lines) + "\n")
    out = tmp_path / "rdf.csv"
    code = main(["rdf", str(positions), "--out", str(out), *extra])
    return code, out


def test_cli_writes_the_rdf_matrix(tmp_path):
    lines = ["# x y z (m)", "0 0 0.001", "0.0021, 0, 0.001", "", "0 0.0021 0.001  # third"]
    code, out = run_cli(
        tmp_path, lines, "--radius", "0.001", "--emissivity", "0.8", "--rays", "2000",
        "--wall-plane", "0", "0", "0", "0", "0", "1", "--wall-emissivity", "0.6", "--seed", "4",
    )  # fmt: skip
    assert code == 0
    table = np.loadtxt(out, delimiter=",")
    assert table.shape == (3, 5)
    assert np.allclose(table.sum(axis=1), 1.0, atol=1e-9)
    positions = [[0, 0, 0.001], [0.0021, 0, 0.001], [0, 0.0021, 0.001]]
    result = trace(positions, 0.001, 0.8, 2000, walls=[PlaneWall((0, 0, 0), (0, 0, 1), 0.6)], seed=4)
    assert np.allclose(table[:, :3], result.matrix.toarray()) and np.allclose(table[:, 3], result.walls[:, 0])


@pytest.mark.parametrize(
    "lines, extra, message",
    [
        (["0 0 0", "1 2"], [], "bed.txt:2: expected three numbers"),
        (["0 0 0", "1 2 x"], [], "bed.txt:2"),
        (["0 0 0"], ["--radius", "-1"], "--radius must be positive"),
        (["0 0 0"], ["--emissivity", "0"], "--emissivity must lie in"),
        (["0 0 0"], ["--emissivity", "1.5"], "--emissivity must lie in"),
        (["0 0 0"], ["--wall-emissivity", "-0.1"], "--wall-emissivity must lie in"),
        (["0 0 0"], ["--periodic", "xw", "--box", "0", "0", "0", "1", "1", "1"], "--periodic"),
        (["# nothing"], [], "contains no particles"),
    ],
)
def test_cli_reports_bad_input(tmp_path, capsys, lines, extra, message):
    args = {"--radius": "0.1", "--emissivity": "0.5", "--rays": "10"}
    for flag in ("--radius", "--emissivity"):
        if flag in extra:
            args.pop(flag)
    flat = [item for pair in args.items() for item in pair]
    code, _ = run_cli(tmp_path, lines, *flat, *extra)
    assert code == 2
    assert message in capsys.readouterr().err


def test_cli_reports_a_missing_file(tmp_path, capsys):
    out = str(tmp_path / "o.csv")
    code = main(["rdf", str(tmp_path / "none.txt"), "--radius", "1", "--emissivity", "1", "--rays", "1", "--out", out])
    assert code == 2 and "none.txt does not exist" in capsys.readouterr().err
