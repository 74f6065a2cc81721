"""The sheared periodic box run by LIGGGHTS (dpht.dem.sheared): a small box packed and sheared with
Lees-Edwards boundaries; its flow is a homogeneous simple shear and its frames' geometry is the
thermal stage's. LIGGGHTS-PUBLIC 3.8.0 builds no ghost particles in triclinic boxes: there the run
is refused (and the test of the run skipped) until a DEM code whose triclinic boxes work runs it."""

from __future__ import annotations

import numpy as np
import pytest

from dem_scene import needs_liggghts
from sheared_scene import SPEC, spec_with
from dpht.dem import dumps
from dpht.dem.liggghts import run_liggghts
from dpht.dem.sheared import PROBE, ShearedBoxParams, run_sheared_box, triclinic_ghosts
from dpht.errors import ExternalToolError
from dpht.thermal import neighbors

D = SPEC["particles"]["diameter"]
# A 6-diameter box at 0.5 (216 particles), Pe 2.5: a shear rate of 20 1/s (Eq. 9), one strain in
# 5,000 steps; friction 0.5 and no rolling friction.
SMALL = spec_with(
    contact={"friction": {"pp": 0.5, "pw": 0.5}, "rolling_friction": {"pp": 0.0, "pw": 0.0}},
    sheared_box={"size": 6, "solid_fraction": 0.5, "peclet": 2.5, "steady_strain": 1.0, "strain": 2.0},
)


@pytest.fixture(scope="module")
def ghosts(tmp_path_factory):
    """The ghost particles of this LIGGGHTS's triclinic probe (dpht.dem.sheared.triclinic_ghosts)."""
    return triclinic_ghosts(tmp_path_factory.mktemp("probe"))


@needs_liggghts
def test_a_liggghts_without_triclinic_ghosts_is_refused(tmp_path, ghosts):
    """The probe's two particles touch through the box's x faces: the orthogonal box of the same
    deck has their two ghosts (the probe can see ghosts), the triclinic one none, and the run refuses."""
    if ghosts:
        pytest.skip("this LIGGGHTS builds ghost particles in triclinic boxes")
    probe = triclinic_ghosts(tmp_path / "probe")
    orthogonal = (tmp_path / "probe" / PROBE).read_text().replace("prism 0.0 0.006 0.0 0.006 0.0 0.006 0.0 0.0 0.0",
                                                                 "block 0.0 0.006 0.0 0.006 0.0 0.006")
    assert orthogonal != (tmp_path / "probe" / PROBE).read_text()
    (tmp_path / "probe" / "orthogonal.in").write_text(orthogonal)
    run_liggghts("orthogonal.in", tmp_path / "probe", tmp_path / "probe" / "orthogonal.txt")
    counts = [line.split()[1] for line in (tmp_path / "probe" / "orthogonal.txt").read_text().splitlines()
              if line.startswith("Nghost:")]
    assert probe == 0 and counts == ["2"]
    with pytest.raises(ExternalToolError, match="no ghost particles across the periodic faces of a triclinic box"):
        run_sheared_box(SMALL, tmp_path / "work", tmp_path / "positions.h5", log=lambda line: None)
    assert not (tmp_path / "positions.h5").exists() and not (tmp_path / "work" / "shear.in").exists()


@needs_liggghts
def test_liggghts_shears_the_box_homogeneously_and_the_cell_list_follows_its_tilt(tmp_path, ghosts):
    if not ghosts:
        pytest.skip("this LIGGGHTS (LIGGGHTS-PUBLIC 3.8.0 does) builds no ghost particles in triclinic boxes")
    params = ShearedBoxParams.from_spec(SMALL)
    assert abs(params.shear_rate - 20.0) < 1e-9
    summary = run_sheared_box(SMALL, tmp_path / "work", tmp_path / "positions.h5", bins=6, log=lambda line: None)
    profile = summary["profile"]
    # A homogeneous simple shear: the mean x velocity linear across y at the set rate, no slip.
    assert abs(profile["shear_rate_1_s"] / params.shear_rate - 1.0) < 0.1, profile
    assert profile["linearity"] < 0.1 and abs(profile["offset_m_s"]) < 0.05 * params.shear_rate * params.edge, profile
    # The solid fraction held: every particle kept, spread evenly across y.
    assert profile["lost_particles"] == 0
    solid = np.array(profile["solid_fraction"])
    assert abs(solid.mean() - params.solid_fraction) < 1e-12 and np.all(np.abs(solid / solid.mean() - 1.0) < 0.15), solid
    with dumps.PositionsFile(tmp_path / "positions.h5") as positions:
        assert positions.sheared and positions.n_particles == params.n_particles
        steps = params.steps()
        assert positions.steps[0] == steps["steady_end"] and positions.steps[-1] == steps["shear_end"]
        # The tilt at full precision: it grows by the shear rate x edge x time between dumps, less flips.
        change = np.diff(positions.tilts)
        change -= params.edge * np.round(change / params.edge)
        expected = params.shear_rate * params.edge * params.dump_interval * params.timestep
        assert np.max(np.abs(change / expected - 1.0)) < 1e-9 and np.any(np.diff(positions.tilts) < 0)
        # In LIGGGHTS' own frames, the sheared cell list finds every pair a nearest-image search finds,
        # and no two particles overlap through the images by more than they do inside the box: the
        # tilt's sign and size are the DEM's.
        lo, hi = (np.asarray(positions.attrs[k], float) for k in ("box_lo", "box_hi"))
        for index in np.argsort(-np.abs(positions.tilts), kind="stable")[:3].tolist():  # the most tilted frames
            frame = positions.frame(index)
            cells = neighbors.build(frame.positions, 1.5 * D, box_lo=lo, box_hi=hi, periodic=(True,) * 3, tilt=frame.tilt)
            first, second, r2 = neighbors.pair_list(cells, 1.5 * D)
            i, j = cells.order[first], cells.order[second]
            ref = neighbors.brute_force_pairs(frame.positions, 1.5 * D, box_lo=lo, box_hi=hi, periodic=(True,) * 3,
                                              tilt=frame.tilt)
            assert set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())) == set(zip(*(r.tolist() for r in ref)))
            overlap = (D - np.sqrt(r2)) / D
            across = np.abs(frame.positions[i, 1] - frame.positions[j, 1]) > 0.5 * params.edge
            assert across.sum() > 10 and overlap[across].max() < max(0.02, 2.0 * overlap[~across].max()), index
