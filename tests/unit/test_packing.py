"""Random sphere packings (Lubachevsky-Stillinger growth): target reached, no overlaps, deterministic."""

import numba
import numpy as np
import pytest
from scipy.spatial import cKDTree

from dpht.errors import DPHTError
from dpht.radiation.packing import SPHERE_VOLUME, Pins, near_wall_solid_fraction, pack, slab_solid_fraction


def smallest_gap(p):
    """Smallest surface gap between two spheres (periodic images included), in radii."""
    length = p.box[1] - p.box[0]
    periodic = np.array(p.periodic)
    tree = cKDTree(np.mod(p.positions - p.box[0], length) if periodic.all() else p.positions,
                   boxsize=length if periodic.all() else None)  # fmt: skip
    distance, _ = tree.query(tree.data, k=2)
    return distance[:, 1].min() / p.radius - 2.0


@pytest.fixture(scope="module")
def packings():
    return {phi: pack(1500, phi, radius=0.5e-3, seed=7) for phi in (0.25, 0.45, 0.64)}


@pytest.mark.parametrize("phi", [0.25, 0.45, 0.64])
def test_periodic_packing_reaches_target_without_overlaps(packings, phi):
    p = packings[phi]
    length = p.box[1] - p.box[0]
    assert abs(len(p.positions) * SPHERE_VOLUME * p.radius**3 / np.prod(length) - phi) < 1e-9
    assert p.max_overlap < 1e-9
    assert smallest_gap(p) > -1e-9  # independent check of the reported overlap
    assert np.all((p.positions >= p.box[0]) & (p.positions <= p.box[1]))


def test_close_packing_is_random_not_crystalline(packings):
    """At 0.64 a random packing has about 6 near-contacts per sphere; a crystal would have 12."""
    p = packings[0.64]
    length = p.box[1] - p.box[0]
    tree = cKDTree(np.mod(p.positions, length), boxsize=length)
    contacts = np.array([len(n) - 1 for n in tree.query_ball_point(tree.data, 2.02 * p.radius)])
    assert 4.5 < contacts.mean() < 8.0


def test_slab_between_walls_matches_bulk_solid_fraction():
    p = pack(2000, 0.55, aspect=(1, 1, 2), wall_axis=2, seed=5, radius=2.0)
    z = p.positions[:, 2]
    lo, hi = p.box[:, 2]
    area = np.prod(p.box[1, :2] - p.box[0, :2])
    bulk = slab_solid_fraction(p.positions, p.radius, lo + 5 * p.radius, hi - 5 * p.radius, 2, area)
    assert abs(bulk - 0.55) < 1e-9 and abs(p.solid_fraction - bulk) < 1e-9
    assert p.periodic == (True, True, False)
    assert z.min() - lo >= p.radius * (1 - 1e-9) and hi - z.max() >= p.radius * (1 - 1e-9)
    # Spheres crowd against the wall (the first layer): at least 3 times the bulk density there.
    near = np.sum(z - lo < 1.1 * p.radius)
    bulk_number = 0.55 / (SPHERE_VOLUME * p.radius**3) * area * 0.1 * p.radius
    assert near > 3 * bulk_number
    assert p.max_overlap < 1e-9


def test_slab_solid_fraction_is_exact_for_caps():
    area, r = 4.0, 0.5
    one = np.array([[0.0, 0.0, 1.0]])
    assert slab_solid_fraction(one, r, 0.0, 2.0, 2, area) == pytest.approx(SPHERE_VOLUME * r**3 / (area * 2))
    assert slab_solid_fraction(one, r, 1.0, 3.0, 2, area) == pytest.approx(SPHERE_VOLUME * r**3 / 2 / (area * 2))


def test_packing_is_deterministic_and_seeded():
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = pack(600, 0.6, seed=1)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        b = pack(600, 0.6, seed=1)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, pack(600, 0.6, seed=2).positions)


def test_too_fast_growth_jams_below_the_target_and_says_so():
    with pytest.raises(DPHTError, match="jammed at solid fraction 0.6"):
        pack(1000, 0.645, rate=0.1, seed=1)


@pytest.mark.parametrize(
    "args, kwargs, message",
    [
        ((1000, 0.7), {}, "solid_fraction"),
        ((10, 0.5), {}, "too few"),
        ((1000, 0.5), {"wall_axis": 3}, "wall_axis"),
        ((1000, 0.5), {"radius": 0.0}, "radius"),
        ((2000, 0.5), {"wall_axis": 2, "aspect": (1, 1, 0.25)}, "too few for walls"),
    ],
)
def test_bad_arguments_are_reported(args, kwargs, message):
    with pytest.raises(DPHTError, match=message):
        pack(*args, **kwargs)


def test_slab_matches_the_near_wall_solid_fraction_the_dem_report_measures():
    """The PW RDF tables are indexed by this: the solid fraction within one diameter of the walls."""
    p = pack(2000, 0.5, aspect=(1, 1, 2), wall_axis=2, seed=5, match="near_wall")
    assert p.match == "near_wall" and abs(p.solid_fraction - 0.5) < 1e-9
    assert abs(near_wall_solid_fraction(p.positions, p.radius, p.box, 2) - 0.5) < 1e-9
    assert p.max_overlap < 1e-9 and smallest_gap_slab(p) > -1e-9


def smallest_gap_slab(p):
    """Smallest surface gap (radii) in a slab periodic in x and y (images by replication)."""
    length = p.box[1] - p.box[0]
    images = np.concatenate([p.positions + [i * length[0], j * length[1], 0] for i in (-1, 0, 1) for j in (-1, 0, 1)])
    distance, _ = cKDTree(images).query(p.positions, k=2)
    return distance[:, 1].min() / p.radius - 2.0


def test_pinned_spheres_stay_at_their_wall_distances_and_the_rest_packs_around_them():
    """Pins where the unpinned packing puts almost nobody (between the first and second layers)."""
    k = 8
    lateral = np.column_stack([(np.arange(k) % 4 + 0.5) / 4, (np.arange(k) // 4 + 0.5) / 2])
    distance = np.linspace(1.2, 2.3, k)
    high = np.arange(k) % 2 == 1
    p = pack(1200, 0.5, aspect=(1, 1, 1), wall_axis=2, seed=3, match="near_wall", pins=Pins(lateral, distance, high))
    pinned = p.positions[-k:]
    to_wall = np.where(high, p.box[1, 2] - pinned[:, 2], pinned[:, 2] - p.box[0, 2]) / p.radius
    assert p.n_pinned == k and np.allclose(to_wall, distance, rtol=3e-3)  # to within the final shrink
    assert np.allclose(pinned[:, :2] / (p.box[1, :2] - p.box[0, :2]), lateral, atol=1e-12)
    assert p.max_overlap < 1e-9 and smallest_gap_slab(p) > -1e-9
    assert abs(p.solid_fraction - 0.5) < 1e-9


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"match": "bulk", "pins": Pins(np.zeros((1, 2)), np.ones(1), np.zeros(1, bool)), "wall_axis": None}, "pins need walls"),
        ({"pins": Pins(np.array([[0.1, 0.1], [0.12, 0.1]]), np.ones(2), np.zeros(2, bool))}, "closer than"),
        ({"pins": Pins(np.zeros((1, 2)), np.array([0.5]), np.zeros(1, bool))}, "distances in"),
        ({"match": "middle"}, "match"),
    ],
)
def test_bad_pins_and_matches_are_reported(kwargs, message):
    args = {"aspect": (1, 1, 1), "wall_axis": 2, "match": "near_wall", **kwargs}
    with pytest.raises(DPHTError, match=message):
        pack(1000, 0.4, **args)
