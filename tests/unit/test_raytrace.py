"""Monte Carlo RDF ray tracer: exact view factors, reciprocity, sum rule, determinism, grid walk."""

import numba
import numpy as np
import pytest
import trimesh

from dpht.radiation import raytrace
from dpht.errors import DPHTError
from dpht.radiation.raytrace import MeshWall, PlaneWall, trace
from dpht.verification.cases.radiation import binomial_stderr, sphere_sphere_view_factor


def random_bed(n, seed, box=8.0, r_min=0.35, r_max=0.5):
    """Spheres with random radii in the cube [0, box)^3, not overlapping even across periodic
    faces (random sequential addition)."""
    rng = np.random.default_rng(seed)
    centres, radii = np.zeros((0, 3)), np.zeros(0)
    while len(centres) < n:
        c = rng.random(3) * box
        r = rng.uniform(r_min, r_max)
        gap = c - centres
        gap -= box * np.round(gap / box)
        if np.all(np.linalg.norm(gap, axis=1) > r + radii):
            centres = np.vstack([centres, c])
            radii = np.append(radii, r)
    return centres, radii


def test_philox_known_answers():
    """Philox4x32-10 against the Random123 known-answer vectors (Salmon et al. 2011)."""
    u = np.uint64
    cases = [
        ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
        ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
        (
            (0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344),
            (0xA4093822, 0x299F31D0),
            (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1),
        ),
    ]
    for counter, key, expected in cases:
        assert tuple(int(w) for w in raytrace.philox4x32(*map(u, counter), *map(u, key))) == expected


@pytest.mark.parametrize("gap", [0.0, 0.3, 4.0])
def test_black_sphere_sees_half_of_a_black_plane(gap):
    rays = 100_000
    result = trace([[0.2, -0.1, 1.0 + gap]], 1.0, 1.0, rays, walls=[PlaneWall((0, 0, 0), (0, 0, 1), 1.0)])
    assert abs(result.walls[0, 0] - 0.5) < 4 * binomial_stderr(0.5, rays)
    assert result.counts.sum() == 0  # nothing comes back to a black emitter
    assert result.wall_counts[0, 0] + result.lost_counts[0] == rays


def test_large_mesh_square_acts_like_the_plane():
    """Two triangles 2000 radii wide below a black sphere: 1/2 minus the tiny grazing fraction
    (< 1e-3) that passes beyond the edge."""
    w = 1000.0
    corners = np.array([[-w, -w, 0], [w, -w, 0], [w, w, 0], [-w, w, 0.0]])
    square = MeshWall(corners, np.array([[0, 1, 2], [0, 2, 3]]), 1.0)
    rays = 100_000
    result = trace([[0.0, 0.0, 1.5]], 1.0, 1.0, rays, walls=[square])
    assert abs(result.walls[0, 0] - 0.5) < 4 * binomial_stderr(0.5, rays) + 1e-3


@pytest.mark.parametrize("distance, r2", [(2.05, 1.0), (3.0, 1.0), (3.5, 2.0)])
def test_two_black_spheres_match_view_factor_quadrature(distance, r2):
    reference = sphere_sphere_view_factor(distance, 1.0, r2)
    rays = 300_000
    result = trace([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0 + distance]], [1.0, r2], 1.0, rays, emitters=[0])
    assert abs(result.matrix[0, 1] - reference) < 4 * binomial_stderr(reference, rays)


def test_view_factor_quadrature_small_sphere_limit():
    """The quadrature itself: a small sphere sees a sphere of radius r at distance d with the
    solid-angle fraction (1 - sqrt(1 - (r/d)^2)) / 2, and F12 A1 = F21 A2."""
    exact = (1 - np.sqrt(1 - (1 / 3) ** 2)) / 2
    assert abs(sphere_sphere_view_factor(3.0, 1e-3, 1.0) - exact) < 1e-5 * exact
    assert abs(sphere_sphere_view_factor(3.0, 1.0, 1.5) - 1.5**2 * sphere_sphere_view_factor(3.0, 1.5, 1.0)) < 1e-6


def test_reciprocity_and_sum_rule_in_a_gray_bed():
    """eps_i A_i D_ij = eps_j A_j D_ji with reflections (gray, diffuse), for unequal radii and
    emissivities; the per-ray sum rule holds exactly."""
    centres, radii = random_bed(40, seed=1, box=4.5)
    eps = np.random.default_rng(2).uniform(0.5, 1.0, len(radii))
    rays = 40_000
    result = trace(centres, radii, eps, rays, walls=[PlaneWall((0, 0, -0.5), (0, 0, 1), 0.7)], seed=5)
    total = np.asarray(result.counts.sum(axis=1)).ravel() + result.wall_counts.sum(axis=1) + result.lost_counts
    assert np.all(total == rays)
    d = result.matrix.toarray()
    weight = eps * radii**2  # eps A / (4 pi)
    flux = weight[:, None] * d
    var = weight[:, None] ** 2 * binomial_stderr(d, rays) ** 2
    i, j = np.triu_indices(len(radii), 1)
    seen = (d[i, j] + d[j, i]) * rays > 50
    z = (flux[i, j] - flux[j, i])[seen] / np.sqrt(var[i, j] + var[j, i])[seen]
    assert seen.sum() > 100
    assert np.max(np.abs(z)) < 5
    assert 0.7 < np.mean(z**2) < 1.3  # the differences are pure Monte Carlo noise


def test_sum_rule_periodic_bed_with_mesh_and_plane():
    """Periodic in x and y, a gray floor plane and a reflecting triangle roof: no ray is lost
    sideways, counts add up exactly, non-emitters have empty rows."""
    centres, radii = random_bed(60, seed=3, box=6.0)
    roof = MeshWall(np.array([[0, 0, 7.0], [6, 0, 7], [6, 6, 7], [0, 6, 7]]), np.array([[0, 1, 2], [0, 2, 3]]), 0.0)
    box = [[0, 0, 0], [6, 6, 7]]
    emitters = np.arange(0, 60, 3)
    rays = 5_000
    result = trace(
        centres, radii, 0.8, rays, walls=[PlaneWall((0, 0, -0.6), (0, 0, 1), 0.5), roof], box=box,
        periodic=(True, True, False), emitters=emitters,
    )  # fmt: skip
    total = np.asarray(result.counts.sum(axis=1)).ravel() + result.wall_counts.sum(axis=1) + result.lost_counts
    assert np.all(total[emitters] == rays)
    assert np.all(np.delete(total, emitters) == 0)
    assert result.wall_counts[:, 1].sum() == 0  # a perfect reflector absorbs nothing
    # The roof spans the periodic cell, so the bed is closed: at most a rare numerical leak
    # along the edges of its two triangles.
    assert result.lost_counts.sum() <= 1e-5 * rays * emitters.size


def test_black_closed_mesh_absorbs_everything():
    shell = trimesh.creation.icosphere(subdivisions=2, radius=3.0)
    rays = 50_000
    result = trace([[0.3, 0.0, -0.2]], 1.0, 0.5, rays, walls=[MeshWall(shell.vertices, shell.faces, 1.0)])
    assert result.lost_counts[0] == 0
    assert result.wall_counts[0, 0] + result.counts[0, 0] == rays


def test_same_result_on_one_and_two_threads():
    centres, radii = random_bed(80, seed=4, box=6.0)
    box = [[0, 0, 0], [6, 6, 6]]
    before = numba.get_num_threads()
    results = []
    try:
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            results.append(trace(centres, radii, 0.65, 2_000, box=box, periodic=(True,) * 3, seed=11))
    finally:
        numba.set_num_threads(before)
    a, b = results
    assert (a.counts != b.counts).nnz == 0
    assert np.array_equal(a.wall_counts, b.wall_counts) and np.array_equal(a.lost_counts, b.lost_counts)
    other_seed = trace(centres, radii, 0.65, 2_000, box=box, periodic=(True,) * 3, seed=12)
    assert (a.counts != other_seed.counts).nnz > 0


# --------------------------------------------------------------------------------------------
# Grid walk against an independent brute-force first hit (same random numbers)


def brute_force_counts(centres, radii, eps, rays, seed, planes, box=None):
    """Trace with numpy, testing every sphere per flight. Uses the tracer's random-number and
    sampling helpers so that each ray sees the same numbers. With a periodic ``box`` the origin is
    wrapped into it and the 27 nearest images are tested; a hit beyond the distance at which
    farther images could intervene is not trusted: the ray is moved there and searched again."""
    n = len(centres)
    if box is not None:
        length = box[1] - box[0]
        shifts = np.array([[a, b, c] for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]) * length
        images = (centres[None, :, :] + shifts[:, None, :]).reshape(-1, 3)
        ids = np.tile(np.arange(n), len(shifts))
    else:
        images, ids = centres, np.arange(n)
    r_img = radii[ids]
    reach = np.inf if box is None else (box[1] - box[0]).min() - radii.max()
    counts = np.zeros((n, n + len(planes) + 1), np.int64)
    key = np.uint64(seed)
    for i in range(n):
        for ray in range(rays):
            u = raytrace._uniforms(key, i, ray, 0)
            normal = np.array(raytrace._sphere_normal(u[0], u[1]))
            o = centres[i] + radii[i] * normal
            d = np.array(raytrace._cosine_direction(*normal, u[2], u[3]))
            skip = -1
            event = 1
            while True:
                if box is not None:
                    o = box[0] + np.mod(o - box[0], box[1] - box[0])
                e = o - images
                b = e @ d
                c = np.sum(e * e, axis=1) - r_img**2
                disc = b * b - c
                ok = (b < 0) & (c > 0) & (disc > 0)
                t = np.full(len(images), np.inf)
                t[ok] = c[ok] / (np.sqrt(disc[ok]) - b[ok])
                k = int(np.argmin(t))
                best, kind = t[k], "sphere"
                for p, (point, pn, _) in enumerate(planes):
                    denom = d @ pn
                    if p != skip and denom != 0:
                        tp = ((point - o) @ pn) / denom
                        if 0 < tp < best:
                            best, kind, k = tp, "plane", p
                if best > reach:  # free flight up to reach: continue from there
                    o = o + reach * d
                    continue
                if not np.isfinite(best):
                    counts[i, -1] += 1
                    break
                u = raytrace._uniforms(key, i, ray, event)
                event += 1
                o = o + best * d
                skip = -1
                if kind == "sphere":
                    j = ids[k]
                    if u[0] < eps:
                        counts[i, j] += 1
                        break
                    normal = (o - images[k]) / radii[j]
                else:
                    point, pn, pe = planes[k]
                    if u[0] < pe:
                        counts[i, n + k] += 1
                        break
                    normal = -pn if pn @ d > 0 else pn
                    skip = k
                d = np.array(raytrace._cosine_direction(*normal, u[1], u[2]))
    return counts


@pytest.mark.parametrize("periodic", [False, True])
def test_grid_walk_equals_brute_force(periodic):
    centres, radii = random_bed(60, seed=6, box=4.0)  # dense enough to have no open channels
    box = np.array([[0.0, 0, 0], [4, 4, 4]]) if periodic else None
    planes = [] if periodic else [(np.array([0, 0, -0.2]), np.array([0, 0, 1.0]), 0.6)]
    eps, rays, seed = 0.6, 40, 99
    expected = brute_force_counts(centres, radii, eps, rays, seed, planes, box)
    result = trace(
        centres, radii, eps, rays, walls=[PlaneWall(p, n, e) for p, n, e in planes], box=box,
        periodic=(periodic,) * 3, seed=seed,
    )  # fmt: skip
    got = np.hstack([result.counts.toarray(), result.wall_counts, result.lost_counts[:, None]])
    assert np.array_equal(got, expected)


# --------------------------------------------------------------------------------------------
# Input errors


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(radius=-1.0), "radius"),
        (dict(emissivity=0.0), "emissivity"),
        (dict(emissivity=1.5), "emissivity"),
        (dict(rays_per_particle=0), "rays_per_particle"),
        (dict(periodic=(True, False, False)), "box is required"),
        (
            dict(box=[[0, 0, 0], [8, 8, 8]], periodic=(True, False, False), walls=[PlaneWall((0, 0, 0), (1, 0, 0), 1)]),
            "perpendicular",
        ),
        (dict(box=[[0, 0, 0], [2, 8, 8]], periodic=(True, False, False)), "3 particle diameters"),
        (dict(emitters=[5]), "emitters"),
        (dict(walls=[PlaneWall((0, 0, 0), (0, 0, 1), 2.0)]), "walls[0].emissivity"),
        (dict(seed=-1), "seed"),
    ],
)
def test_bad_input_is_reported(kwargs, message):
    args = dict(positions=[[1.0, 1, 1], [3, 1, 1]], radius=0.5, emissivity=0.8, rays_per_particle=10)
    args.update(kwargs)
    with pytest.raises(DPHTError, match=message.replace("[", r"\[").replace("]", r"\]")):
        trace(**args)
