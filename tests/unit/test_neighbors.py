"""The cell list finds exactly the pairs a brute-force search finds, each once."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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


# --- the sheared (Lees-Edwards, triclinic xy) box -------------------------------------------------


def min_image_r2(pos, lengths, tilt):
    """Squared distance and vector of every pair (i < j) to the nearest image of j in the lattice
    a = (Lx, 0, 0), b = (tilt, Ly, 0), c = (0, 0, Lz) (any tilt up to 1.5 Lx): the separation
    brought within half a period in y, then in x and z, then the nearest of its 45 neighbouring images."""
    a = np.array([lengths[0], 0.0, 0.0])
    b = np.array([tilt, lengths[1], 0.0])
    c = np.array([0.0, 0.0, lengths[2]])
    shifts = np.array([i * a + j * b + k * c for i in range(-2, 3) for j in range(-1, 2) for k in range(-1, 2)])
    d = pos[None, :, :] - pos[:, None, :]
    d -= np.round(d[..., 1] / lengths[1])[..., None] * b
    d[..., [0, 2]] -= np.round(d[..., [0, 2]] / lengths[[0, 2]]) * lengths[[0, 2]]
    images = d[:, :, None, :] + shifts
    r2 = np.einsum("ijsk,ijsk->ijs", images, images)
    nearest = np.argmin(r2, axis=2)
    i, j = np.triu_indices(len(pos), 1)
    return i, j, r2[i, j, nearest[i, j]], images[i, j, nearest[i, j]]


def sheared_bed(seed, n, lengths, tilt, faces):
    """``n`` particles in the sheared box at lo = (-1, 0.5, 2) mm, some put exactly on its faces,
    edges and corners, some given as other periodic images (up to two periods off in each axis)."""
    rng = np.random.default_rng(seed)
    lo = np.array([-1e-3, 0.5e-3, 2e-3])
    frac = rng.random((n, 3))
    corners = rng.choice(n, size=min(faces, n), replace=False)
    frac[corners] = rng.choice([0.0, 1.0 - 1e-12, 1.0, 1e-12], size=(corners.size, 3))
    pos = lo + frac * lengths
    images = rng.integers(-2, 3, size=(n, 3)) * (rng.random(n) < 0.3)[:, None]
    pos += images[:, [0]] * [lengths[0], 0, 0] + images[:, [1]] * [tilt, lengths[1], 0] + images[:, [2]] * [0, 0, lengths[2]]
    return lo, pos


@settings(derandomize=True, database=None, deadline=None, max_examples=25)
@given(seed=st.integers(0, 2**31), stretch=st.tuples(*[st.floats(3.0, 5.5)] * 3),
       tilt_fraction=st.one_of(st.sampled_from([0.5, -0.5, 0.4999999, -0.4999999, 0.25, 1.0, -1.5]), st.floats(-0.5, 0.5)),
       faces=st.integers(0, 60), reach=st.sampled_from([1, 2, None]))
def test_sheared_cell_list_equals_minimum_image_search(seed, stretch, tilt_fraction, faces, reach):
    """Every pair within the cutoff through the sheared box's nearest image, once, with its exact
    squared distance: tilts at and beyond half the x length (the equivalent box LIGGGHTS flips to),
    particles on faces, edges and corners and given as far images."""
    cut = 1.5e-3
    lengths = np.array(stretch) * cut
    tilt = tilt_fraction * lengths[0]
    lo, pos = sheared_bed(seed, 150, lengths, tilt, faces)
    periodic = (True, True, True)
    cells = neighbors.build(pos, cut, box_lo=lo, box_hi=lo + lengths, periodic=periodic, tilt=tilt, reach=reach)
    assert cells.axes[2] == 0 or tilt == 0.0, "x is the fast axis of a sheared box"
    first, second, r2 = neighbors.pair_list(cells, cut)
    i, j = cells.order[first], cells.order[second]
    found = dict(zip(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist()), r2.tolist()))
    assert len(found) == len(i), "a pair was visited twice"
    ri, rj, ref_r2, ref_d = min_image_r2(pos, lengths, tilt)
    sure = np.abs(ref_r2 - cut * cut) > 1e-9 * cut * cut  # pairs not on the cutoff to rounding
    expected = {(a, b) for a, b, r, ok in zip(ri.tolist(), rj.tolist(), ref_r2.tolist(), sure) if ok and r < cut * cut}
    assert expected <= set(found) and set(found) - expected <= {(a, b) for a, b, ok in zip(ri, rj, sure) if not ok}
    reference = dict(zip(zip(ri.tolist(), rj.tolist()), ref_r2.tolist()))
    assert max((abs(found[p] - reference[p]) for p in found), default=0.0) < 1e-12 * cut * cut
    # The separation vectors point to the same nearest images (from i to j, whichever is first).
    vectors = dict(zip(zip(ri.tolist(), rj.tolist()), ref_d))
    sign = np.where(i < j, 1.0, -1.0)[:, None]
    got = sign * neighbors.separations(cells, first, second)
    want = np.array([vectors[(a, b)] for a, b in zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())]).reshape(-1, 3)
    assert np.allclose(got, want, rtol=0, atol=1e-12 * cut) and np.allclose(np.einsum("ij,ij->i", got, got), r2, rtol=1e-12)
    # The wrapped coordinates lie in the orthogonal box.
    assert np.all(cells.coords >= lo[cells.axes, None]) and np.all(cells.coords <= (lo + lengths)[cells.axes, None])
    # The reference search of the module agrees wherever the minimum image is unambiguous.
    bi, bj = neighbors.brute_force_pairs(pos, cut, box_lo=lo, box_hi=lo + lengths, periodic=periodic, tilt=tilt)
    assert {p for p in zip(bi.tolist(), bj.tolist())} ^ expected <= {(a, b) for a, b, ok in zip(ri, rj, sure) if not ok}


def test_sheared_box_matches_the_equivalent_boxes_and_the_orthogonal_one():
    """A tilt of a whole x length is the orthogonal box; tilts a length apart give the same pairs."""
    rng = np.random.default_rng(11)
    box = np.array([0.012, 0.010, 0.011])
    pos = rng.random((1500, 3)) * box
    cut = 2.1e-3
    kw = dict(box_lo=np.zeros(3), box_hi=box, periodic=(True, True, True))
    plain = pair_set(*neighbors.pairs(neighbors.build(pos, cut, **kw), cut))
    assert pair_set(*neighbors.pairs(neighbors.build(pos, cut, tilt=box[0], **kw), cut)) == plain
    tilted = pair_set(*neighbors.pairs(neighbors.build(pos, cut, tilt=0.3 * box[0], **kw), cut))
    assert tilted != plain
    assert pair_set(*neighbors.pairs(neighbors.build(pos, cut, tilt=-0.7 * box[0], **kw), cut)) == tilted


def test_sheared_box_needs_periodic_x_and_y():
    with pytest.raises(DPHTError, match="periodic x and y"):
        neighbors.build(np.zeros((2, 3)), 0.01, box_lo=np.zeros(3), box_hi=np.ones(3), periodic=(True, False, True), tilt=0.1)
    with pytest.raises(DPHTError, match="finite tilt"):
        neighbors.build(np.zeros((2, 3)), 0.01, box_lo=np.zeros(3), box_hi=np.ones(3), periodic=(True, True, True), tilt=np.nan)
