"""The cell list finds exactly the pairs a brute-force search finds, each once."""

import numpy as np
import pytest

from dpht.thermal import neighbors
from dpht.errors import DPHTError

BOX = np.array([0.02, 0.015, 0.03])


def pair_set(i, j):
    return set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist()))


@pytest.mark.parametrize("periodic", [(False, False, False), (False, False, True), (True, True, True), (True, False, False), (False, True, False)])
@pytest.mark.parametrize("reach", [1, 2])
def test_cell_list_equals_brute_force(periodic, reach):
    rng = np.random.default_rng(reach + 7 * sum(periodic))
    pos = rng.random((2500, 3)) * BOX
    cut = 0.0021
    cells = neighbors.build(pos, cut, box_lo=np.zeros(3), box_hi=BOX, periodic=periodic, reach=reach)
    i, j = neighbors.pairs(cells, cut)
    assert len(i) == len(pair_set(i, j)), "a pair was visited twice"
    assert np.all(i != j)
    ref = pair_set(*neighbors.brute_force_pairs(pos, cut, box_lo=np.zeros(3), box_hi=BOX, periodic=periodic))
    assert pair_set(i, j) == ref
    assert len(ref) > 1000


def test_clustered_positions_and_smaller_query_cutoff():
    rng = np.random.default_rng(3)
    pos = np.concatenate([rng.normal(0, 1e-3, (800, 3)), rng.normal(0.01, 3e-3, (800, 3))])
    cells = neighbors.build(pos, 2e-3)
    for cut in (2e-3, 1.2e-3):
        assert pair_set(*neighbors.pairs(cells, cut)) == pair_set(*neighbors.brute_force_pairs(pos, cut))
    with pytest.raises(DPHTError, match="exceeds"):
        neighbors.pairs(cells, 3e-3)


def test_slab_colours_never_write_the_same_slab_concurrently():
    for n_slow, reach, periodic in [(9, 1, True), (10, 2, True), (7, 1, False), (3, 1, True)]:
        colours = neighbors._slab_colours(n_slow, reach, periodic)
        n_slabs = -(-n_slow // reach)
        assert sorted(np.concatenate(colours).tolist()) == list(range(n_slabs))
        for slabs in colours:
            written = [s for slab in slabs for s in (slab, (slab + 1) % n_slabs if periodic else slab + 1)]
            assert len(written) == len(set(written)) or len(slabs) == 1


def test_lost_particles_are_left_out():
    rng = np.random.default_rng(3)
    pos = rng.uniform(0, 1e-2, (300, 3))
    pos[[5, 17, 200]] = [[np.nan, 0, 0], [0, np.inf, 0], [np.nan] * 3]
    cells = neighbors.build(pos, 2e-3)
    kept = np.setdiff1d(np.arange(300), [5, 17, 200])
    assert sorted(cells.order.tolist()) == kept.tolist()
    i, j = neighbors.pairs(cells, 2e-3)
    ref_i, ref_j = neighbors.brute_force_pairs(pos[kept], 2e-3)
    assert {tuple(sorted(p)) for p in zip(i, j)} == {tuple(sorted(p)) for p in zip(kept[ref_i], kept[ref_j])}


def test_bad_input_is_named():
    with pytest.raises(DPHTError, match="shape"):
        neighbors.build(np.zeros((4, 2)), 1.0)
    with pytest.raises(DPHTError, match="periodic axis z"):
        neighbors.build(np.zeros((2, 3)), 0.01, box_lo=np.zeros(3), box_hi=np.array([1, 1, 0.02]), periodic=(False, False, True))


def test_short_periodic_slice_of_a_sparse_bed():
    """A periodic axis 2.6 cutoffs long (a short slice of a tube, thermal.slice) is too short for
    whole-cutoff cells; the default picks half-cutoff cells and still finds every pair once."""
    box = np.array([0.02, 0.02, 2.6 * 0.0021])
    pos = np.random.default_rng(5).random((400, 3)) * box
    periodic = (False, False, True)
    cells = neighbors.build(pos, 0.0021, box_lo=np.zeros(3), box_hi=box, periodic=periodic)
    i, j = neighbors.pairs(cells, 0.0021)
    ref = pair_set(*neighbors.brute_force_pairs(pos, 0.0021, box_lo=np.zeros(3), box_hi=box, periodic=periodic))
    assert len(i) == len(ref) and pair_set(i, j) == ref and len(ref) > 50
    with pytest.raises(DPHTError, match="periodic axis z"):
        neighbors.build(pos, 0.0021, box_lo=np.zeros(3), box_hi=box, periodic=periodic, reach=1)
