"""Reproducible random packings of equal spheres: a periodic box, or a slab between two hard walls.

Algorithm: Lubachevsky-Stillinger growth (Lubachevsky & Stillinger 1990, J. Stat. Phys. 60, 561;
event-driven form as in Skoge, Donev, Stillinger & Torquato 2006, Phys. Rev. E 74, 041127).
Points start uniformly at random (seeded PCG64) with random velocities; hard spheres grow at a
constant diameter rate ``a`` while moving ballistically between exact pair, wall and cell-crossing
events. A collision reflects the normal relative velocity in the frame of the growing surfaces and
adds ``2a`` to it, so the spheres separate faster than they grow and never overlap; velocities are
rescaled to unit temperature every ``20 N`` events. Growth stops at the target solid fraction, so
the packing is overlap-free to rounding error. The default rate ``a = 0.01`` (unit thermal speed)
is fast enough to avoid crystallisation and slow enough to pass the random-close-packing target
0.64 before jamming (measured for 4,000 spheres: ``a = 0.1`` jams at 0.629, ``a = 0.03`` at 0.639;
``a = 0.01`` reaches 0.64 after about 5 million events, 15-30 s here). The event loop is serial,
hence identical for any thread count; it releases the GIL, so packings can run in parallel threads.

With walls (``wall_axis``), spheres also collide with two flat hard walls at the box faces normal
to that axis and crowd against them in layers, as in a real bed; the target is then the solid
fraction of one region (``match``): the *bulk*, farther than ``bulk_margin`` radii from both walls,
or the *near-wall* band, within one particle diameter of either wall (what the DEM report measures
at the tube wall, dpht.dem.report). Growth stops just past it and the spheres are then shrunk in
place (a fraction of a per cent) to match it exactly. Internally the final radius is 1; positions
are scaled to ``radius``.

Pinned spheres (:class:`Pins`, with walls only) sit at chosen lateral positions and chosen
centre-to-wall distances ``h`` (in final radii) while the others pack around them: a pinned sphere
is an obstacle of infinite mass whose centre moves away from its wall at ``h a / 2``, so that its
distance stays ``h`` current radii as the spheres grow, and a mobile sphere that hits it takes the
whole collision impulse. The result samples beds *conditioned on* a particle at distance ``h``,
also where the packing protocol alone almost never puts one (between the dense first layer and the
second); dpht.radiation.tables emits from such spheres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit
from scipy.optimize import brentq

from dpht.dem.dumps import DumpFrame, write_positions
from dpht.errors import DPHTError

SPHERE_VOLUME = 4.0 / 3.0 * np.pi  # of a unit sphere
RANDOM_CLOSE_PACKING = 0.645  # the densest solid fraction asked for
_COLLISION, _CROSSING, _WALL_LOW, _WALL_HIGH, _NO_EVENT = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class Packing:
    """A packing of ``n`` spheres of radius ``radius`` (m) in ``box`` ([[lo], [hi]], m)."""

    positions: np.ndarray  # (n, 3) centres, m
    radius: float
    box: np.ndarray
    periodic: tuple[bool, bool, bool]
    wall_axis: int | None  # hard walls at box[0, axis] and box[1, axis], or None
    solid_fraction: float  # measured in the matched region (``match``)
    match: str  # "box" (periodic), "bulk" or "near_wall" (see the module docstring)
    max_overlap: float  # largest particle-particle or particle-wall overlap / radius
    events: int  # collisions and cell crossings processed
    n_pinned: int = 0  # the last n_pinned spheres are the pinned ones, in the order given


@dataclass(frozen=True)
class Pins:
    """Spheres held at chosen places in a slab between walls (see the module docstring).

    lateral: (K, 2) positions along the two periodic axes (in axis order) as fractions of the box
    edge, in [0, 1); distance: (K,) centre-to-wall distance in radii (>= 1); high: (K,) True for
    the wall at box[1, wall_axis], False for the one at box[0, wall_axis].
    """

    lateral: np.ndarray
    distance: np.ndarray
    high: np.ndarray

    def __len__(self) -> int:
        return len(self.distance)


# --------------------------------------------------------------------------------------------
# Event-driven kernel. Units: box lengths ``length``, diameter sigma(t) = rate * t.


@njit(cache=True)
def _heap_sift(heap, where, key, k):
    """Restore the min-heap property (on ``key[heap[.]]``) after the key in heap slot ``k``
    changed, the rest being a valid heap."""
    n = heap.shape[0]
    item = heap[k]
    while k > 0:  # up
        parent = (k - 1) >> 1
        if key[heap[parent]] <= key[item]:
            break
        heap[k] = heap[parent]
        where[heap[k]] = k
        k = parent
    while True:  # down
        child = 2 * k + 1
        if child >= n:
            break
        if child + 1 < n and key[heap[child + 1]] < key[heap[child]]:
            child += 1
        if key[heap[child]] >= key[item]:
            break
        heap[k] = heap[child]
        where[heap[k]] = k
        k = child
    heap[k] = item
    where[item] = k


@njit(cache=True)
def _predict(i, t, x, v, tl, grid, wall_axis, rate, stamp, events, pinned):
    """Earliest event of particle ``i`` (whose position is current at time ``t``), stored in
    ``events`` = (time, kind, partner or crossed face, partner's stamp). Pinned spheres never
    reach a wall and never meet each other (their distances are checked in :func:`pack`)."""
    cell_of, head, nxt, length, dims, size = grid
    ev_time, ev_kind, ev_other, ev_stamp = events
    sigma = rate * t
    c = cell_of[i]
    ci = (c // (dims[1] * dims[2]), (c // dims[2]) % dims[1], c % dims[2])
    best = np.inf
    kind = _NO_EVENT
    other = -1
    # Leaving the cell through one of its faces.
    for a in range(3):
        if v[i, a] > 0.0:
            tau = ((ci[a] + 1) * size[a] - x[i, a]) / v[i, a]
            other_a = 2 * a + 1
        elif v[i, a] < 0.0:
            tau = (ci[a] * size[a] - x[i, a]) / v[i, a]
            other_a = 2 * a
        else:
            continue
        if a == wall_axis and ((v[i, a] > 0.0 and ci[a] == dims[a] - 1) or (v[i, a] < 0.0 and ci[a] == 0)):
            continue  # the wall comes first
        if max(tau, 0.0) < best:
            best, kind, other = max(tau, 0.0), _CROSSING, other_a
    # Hitting a wall: the gap x - sigma/2 closes at speed a/2 - v.
    if wall_axis >= 0 and not pinned[i]:
        w = wall_axis
        gap = x[i, w] - 0.5 * sigma
        if v[i, w] < 0.5 * rate:
            tau = max(gap, 0.0) / (0.5 * rate - v[i, w])
            if tau < best:
                best, kind, other = tau, _WALL_LOW, -1
        gap = length[w] - x[i, w] - 0.5 * sigma
        if v[i, w] > -0.5 * rate:
            tau = max(gap, 0.0) / (v[i, w] + 0.5 * rate)
            if tau < best:
                best, kind, other = tau, _WALL_HIGH, -1
    # Colliding with a neighbour: |dx + dv tau| = sigma + a tau.
    for d0 in range(-1, 2):
        a0 = ci[0] + d0
        if wall_axis == 0 and (a0 < 0 or a0 >= dims[0]):
            continue
        s0 = length[0] * ((a0 >= dims[0]) - (a0 < 0))  # image shift across a periodic face
        a0 %= dims[0]
        for d1 in range(-1, 2):
            a1 = ci[1] + d1
            if wall_axis == 1 and (a1 < 0 or a1 >= dims[1]):
                continue
            s1 = length[1] * ((a1 >= dims[1]) - (a1 < 0))
            a1 %= dims[1]
            for d2 in range(-1, 2):
                a2 = ci[2] + d2
                if wall_axis == 2 and (a2 < 0 or a2 >= dims[2]):
                    continue
                s2 = length[2] * ((a2 >= dims[2]) - (a2 < 0))
                a2 %= dims[2]
                j = head[(a0 * dims[1] + a1) * dims[2] + a2]
                while j >= 0:
                    if j != i and not (pinned[i] and pinned[j]):
                        dt = t - tl[j]
                        dx = x[i, 0] - (x[j, 0] + v[j, 0] * dt + s0)
                        dy = x[i, 1] - (x[j, 1] + v[j, 1] * dt + s1)
                        dz = x[i, 2] - (x[j, 2] + v[j, 2] * dt + s2)
                        ux = v[i, 0] - v[j, 0]
                        uy = v[i, 1] - v[j, 1]
                        uz = v[i, 2] - v[j, 2]
                        aa = ux * ux + uy * uy + uz * uz - rate * rate
                        bb = dx * ux + dy * uy + dz * uz - sigma * rate
                        cc = dx * dx + dy * dy + dz * dz - sigma * sigma
                        tau = np.inf
                        if cc <= 0.0:
                            if bb < 0.0:
                                tau = 0.0
                        elif not (aa >= 0.0 and bb >= 0.0):
                            disc = bb * bb - aa * cc
                            if disc >= 0.0:
                                tau = cc / (np.sqrt(disc) - bb)
                        if tau < best:
                            best, kind, other = tau, _COLLISION, j
                    j = nxt[j]
    ev_time[i] = t + best
    ev_kind[i] = kind
    ev_other[i] = other
    ev_stamp[i] = stamp[other] if kind == _COLLISION else 0


@njit(cache=True)
def _reschedule(i, t, x, v, tl, grid, wall_axis, rate, stamp, events, heap, where, pinned):
    """Predict particle ``i``'s next event and move it to its place in the event heap."""
    _predict(i, t, x, v, tl, grid, wall_axis, rate, stamp, events, pinned)
    _heap_sift(heap, where, events[0], where[i])


@njit(cache=True)
def _advance(i, t, x, v, tl):
    """Move particle ``i`` ballistically to time ``t``."""
    dt = t - tl[i]
    x[i, 0] += v[i, 0] * dt
    x[i, 1] += v[i, 1] * dt
    x[i, 2] += v[i, 2] * dt
    tl[i] = t


@njit(cache=True)
def _unlink(i, cell_of, head, nxt, prv):
    if prv[i] >= 0:
        nxt[prv[i]] = nxt[i]
    else:
        head[cell_of[i]] = nxt[i]
    if nxt[i] >= 0:
        prv[nxt[i]] = prv[i]


@njit(cache=True)
def _link(i, c, cell_of, head, nxt, prv):
    cell_of[i] = c
    prv[i] = -1
    nxt[i] = head[c]
    if head[c] >= 0:
        prv[head[c]] = i
    head[c] = i


@njit(cache=True)
def _cells(x, size, dims):
    """Linked cell lists: (cell of each particle, first particle per cell, next, previous)."""
    n = x.shape[0]
    cell_of = np.empty(n, np.int64)
    head = np.full(dims[0] * dims[1] * dims[2], -1, np.int64)
    nxt = np.empty(n, np.int64)
    prv = np.empty(n, np.int64)
    for i in range(n):
        c = 0
        for a in range(3):
            c = c * dims[a] + min(max(int(x[i, a] / size[a]), 0), dims[a] - 1)
        _link(i, c, cell_of, head, nxt, prv)
    return cell_of, head, nxt, prv


@njit(cache=True, nogil=True)
def _grow(x, v, t, t_stop, rate, length, dims, wall_axis, max_events, pinned):
    """Run events from time ``t`` until ``t_stop`` or ``max_events``; positions are returned
    synchronised to the final time, which is returned with the number of events processed.
    ``pinned`` (n,) bool marks the spheres of infinite mass, whose velocities never change."""
    n = x.shape[0]
    size = length / dims
    tl = np.full(n, t)
    cell_of, head, nxt, prv = _cells(x, size, dims)
    grid = (cell_of, head, nxt, length, dims, size)
    stamp = np.zeros(n, np.int64)  # velocity changes so far: invalidates others' predictions
    events = (np.empty(n), np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64))
    ev_time, ev_kind, ev_other, ev_stamp = events
    for i in range(n):
        _predict(i, t, x, v, tl, grid, wall_axis, rate, stamp, events, pinned)
    heap = np.argsort(ev_time, kind="mergesort")  # a sorted array is a valid heap
    where = np.empty(n, np.int64)
    where[heap] = np.arange(n)

    done = 0
    while done < max_events:
        i = heap[0]
        if ev_time[i] > t_stop:
            t = t_stop
            break
        t = ev_time[i]
        kind = ev_kind[i]
        j = ev_other[i]
        if kind == _COLLISION and stamp[j] != ev_stamp[i]:  # partner moved differently since
            _advance(i, t, x, v, tl)
            _reschedule(i, t, x, v, tl, grid, wall_axis, rate, stamp, events, heap, where, pinned)
            continue
        done += 1
        _advance(i, t, x, v, tl)
        if kind == _CROSSING:
            a = ev_other[i] // 2
            step = 1 if ev_other[i] % 2 == 1 else -1
            c = cell_of[i]
            c0, c1, c2 = c // (dims[1] * dims[2]), (c // dims[2]) % dims[1], c % dims[2]
            ca = (c0, c1, c2)[a] + step
            if ca < 0 or ca >= dims[a]:  # periodic face: wrap the position
                ca -= step * dims[a]
                x[i, a] -= step * length[a]
            if a == 0:
                c0 = ca
            elif a == 1:
                c1 = ca
            else:
                c2 = ca
            _unlink(i, cell_of, head, nxt, prv)
            _link(i, (c0 * dims[1] + c1) * dims[2] + c2, cell_of, head, nxt, prv)
        elif kind == _WALL_LOW or kind == _WALL_HIGH:
            # Reflect the velocity away from the wall and make it exceed the growth rate a/2 of
            # the radius: w' = max(-w, 0) + a.
            away = v[i, wall_axis] if kind == _WALL_LOW else -v[i, wall_axis]
            away = max(-away, 0.0) + rate
            v[i, wall_axis] = away if kind == _WALL_LOW else -away
            stamp[i] += 1
        else:
            _advance(j, t, x, v, tl)
            d0 = x[i, 0] - x[j, 0]
            d1 = x[i, 1] - x[j, 1]
            d2 = x[i, 2] - x[j, 2]
            if wall_axis != 0:
                d0 -= length[0] * np.floor(d0 / length[0] + 0.5)
            if wall_axis != 1:
                d1 -= length[1] * np.floor(d1 / length[1] + 0.5)
            if wall_axis != 2:
                d2 -= length[2] * np.floor(d2 / length[2] + 0.5)
            norm = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            d0 /= norm
            d1 /= norm
            d2 /= norm
            # Separation speed w; elastic in the frame of the growing surfaces, plus 2a:
            # w' = max(-w, 0) + 2a, shared equally, or all taken by the mobile sphere when the
            # other is pinned.
            w = (v[i, 0] - v[j, 0]) * d0 + (v[i, 1] - v[j, 1]) * d1 + (v[i, 2] - v[j, 2]) * d2
            dw = max(-w, 0.0) + 2.0 * rate - w
            share_i = 0.0 if pinned[i] else (1.0 if pinned[j] else 0.5)
            share_j = 1.0 - share_i
            v[i, 0] += share_i * dw * d0
            v[i, 1] += share_i * dw * d1
            v[i, 2] += share_i * dw * d2
            v[j, 0] -= share_j * dw * d0
            v[j, 1] -= share_j * dw * d1
            v[j, 2] -= share_j * dw * d2
            if not pinned[i]:
                stamp[i] += 1
            if not pinned[j]:
                stamp[j] += 1
            _reschedule(j, t, x, v, tl, grid, wall_axis, rate, stamp, events, heap, where, pinned)
        _reschedule(i, t, x, v, tl, grid, wall_axis, rate, stamp, events, heap, where, pinned)
    for i in range(n):
        _advance(i, t, x, v, tl)
    return t, done


@njit(cache=True, nogil=True)
def _max_overlap(x, sigma, length, dims, wall_axis):
    """Largest pair or wall overlap for spheres of diameter ``sigma`` (cells at least sigma wide)."""
    n = x.shape[0]
    cell_of, head, nxt, _ = _cells(x, length / dims, dims)
    worst = 0.0
    for i in range(n):
        if wall_axis >= 0:
            worst = max(worst, 0.5 * sigma - x[i, wall_axis], x[i, wall_axis] + 0.5 * sigma - length[wall_axis])
        c = cell_of[i]
        for d0 in range(-1, 2):
            for d1 in range(-1, 2):
                for d2 in range(-1, 2):
                    a0 = c // (dims[1] * dims[2]) + d0
                    a1 = (c // dims[2]) % dims[1] + d1
                    a2 = c % dims[2] + d2
                    outside = (a0 < 0 or a0 >= dims[0], a1 < 0 or a1 >= dims[1], a2 < 0 or a2 >= dims[2])
                    if wall_axis >= 0 and outside[wall_axis]:
                        continue
                    j = head[((a0 % dims[0]) * dims[1] + a1 % dims[1]) * dims[2] + a2 % dims[2]]
                    while j >= 0:
                        if j > i:
                            r2 = 0.0
                            for a in range(3):
                                d = x[i, a] - x[j, a]
                                if a != wall_axis:
                                    d -= length[a] * np.floor(d / length[a] + 0.5)
                                r2 += d * d
                            worst = max(worst, sigma - np.sqrt(r2))
                        j = nxt[j]
    return worst


# --------------------------------------------------------------------------------------------
# Measures


def slab_solid_fraction(positions, radius, lower, upper, axis, area):
    """Solid fraction of the slab ``lower <= x[axis] <= upper`` (cross-section ``area``, m^2):
    exact volume of the spheres' parts inside it (spherical caps) over the slab volume."""
    x = np.asarray(positions)[:, axis]
    u1 = np.clip(lower - x, -radius, radius)
    u2 = np.clip(upper - x, -radius, radius)
    volume = np.pi * ((radius**2 * u2 - u2**3 / 3) - (radius**2 * u1 - u1**3 / 3))
    return float(volume.sum() / (area * (upper - lower)))


def near_wall_solid_fraction(positions, radius, box, axis):
    """Solid fraction within one particle diameter of the two walls normal to ``axis`` at the
    faces of ``box``, both bands pooled (as dpht.dem.report measures it at a tube wall)."""
    lo, hi = box[0, axis], box[1, axis]
    area = float(np.prod(np.delete(box[1] - box[0], axis)))
    return 0.5 * (
        slab_solid_fraction(positions, radius, lo, lo + 2 * radius, axis, area)
        + slab_solid_fraction(positions, radius, hi - 2 * radius, hi, axis, area)
    )


# --------------------------------------------------------------------------------------------
# Driver


MATCHES = ("bulk", "near_wall")
PIN_CLEARANCE = 3.0  # radii: smallest lateral distance between two pinned spheres at one wall


def pack(
    n: int,
    solid_fraction: float,
    *,
    radius: float = 1.0,
    aspect=(1.0, 1.0, 1.0),
    wall_axis: int | None = None,
    seed: int = 0,
    rate: float = 0.01,
    bulk_margin: float = 5.0,
    match: str = "bulk",
    pins: Pins | None = None,
) -> Packing:
    """Pack ``n`` spheres of radius ``radius`` (m) at ``solid_fraction`` (0 < phi <= 0.645).

    aspect: box edge ratios. wall_axis: None for a fully periodic box, else 0/1/2 for hard walls at
    the two box faces normal to that axis (periodic along the other two); the solid fraction of the
    region ``match`` is then matched exactly: "bulk" (farther than ``bulk_margin`` radii from the
    walls) or "near_wall" (within one diameter of either wall; the box is then sized for ``n``
    spheres at random close packing and comes out larger). pins: spheres held at chosen places
    (walls only), included in ``n`` and returned last; their distances must stay a radius short of
    the slab's middle. rate: diameter growth per unit time at unit
    thermal speed. Raises DPHTError if the spheres jam first.
    """
    if int(n) != n or n < 2:
        raise DPHTError(f"n: expected an integer >= 2, got {n!r}")
    if not 0.0 < solid_fraction <= RANDOM_CLOSE_PACKING:
        raise DPHTError(
            f"solid_fraction must lie in (0, {RANDOM_CLOSE_PACKING}] (random close packing); got {solid_fraction!r}"
        )
    if not radius > 0.0:
        raise DPHTError(f"radius must be positive; got {radius!r}")
    aspect = np.asarray(aspect, dtype=float)
    if aspect.shape != (3,) or not np.all(aspect > 0):
        raise DPHTError(f"aspect: expected three positive numbers, got {aspect.tolist()}")
    if wall_axis not in (None, 0, 1, 2):
        raise DPHTError(f"wall_axis: expected None, 0, 1 or 2, got {wall_axis!r}")
    if not 0.0 < rate <= 1.0:
        raise DPHTError(f"rate must lie in (0, 1]; got {rate!r}")
    if match not in MATCHES:
        raise DPHTError(f"match: expected one of {MATCHES}, got {match!r}")
    axis = -1 if wall_axis is None else int(wall_axis)

    # Box for final radius 1 at the target solid fraction (whole box; with walls a first guess). The
    # near-wall band is looser than the rest: size that box for random close packing instead, so
    # that the target is met with a diameter of at most 2, as the cells need (the box is then
    # ``aspect`` scaled to at least the size asked for, in final radii).
    near_wall = axis >= 0 and match == "near_wall"
    box_fraction = RANDOM_CLOSE_PACKING if near_wall else solid_fraction
    length = aspect * (n * SPHERE_VOLUME / box_fraction / np.prod(aspect)) ** (1 / 3)
    dims = np.floor(length / 2.0).astype(np.int64)  # cells at least one final diameter wide
    if np.any(dims < 3):
        raise DPHTError(f"n = {n} is too few: the box must be at least 6 radii wide on every axis")
    if axis >= 0 and length[axis] <= 2 * bulk_margin + 2:
        raise DPHTError(
            f"n = {n} is too few for walls: the slab is {length[axis]:.1f} radii thick; the bulk region "
            f"needs more than 2 * bulk_margin + 2 = {2 * bulk_margin + 2:g}"
        )
    rng = np.random.Generator(np.random.PCG64(seed))
    x = rng.random((n, 3)) * length
    v = rng.standard_normal((n, 3))
    pinned = np.zeros(n, bool)
    if pins is not None and len(pins):
        _place_pins(pins, x, v, pinned, length, axis, rate)
    mobile = ~pinned
    t = 0.0
    events = 0

    def measure(sigma):
        if axis < 0:
            return n * np.pi / 6 * sigma**3 / np.prod(length)
        if near_wall:
            return near_wall_solid_fraction(x, 0.5 * sigma, np.array([np.zeros(3), length]), axis)
        area = np.prod(np.delete(length, axis))
        margin = bulk_margin * 0.5 * sigma
        return slab_solid_fraction(x, 0.5 * sigma, margin, length[axis] - margin, axis, area)

    # Grow to diameter 2: exactly the target when periodic. With walls the matched region's value
    # steers: grow in stages towards the diameter that matches it plus 0.1 %, starting 5 % short of
    # the whole box at the target, possibly a little beyond 2; then shrink the spheres in place to
    # match it exactly.
    sigma_goal = 2.0 if axis < 0 else 2.0 * (0.95 * solid_fraction / box_fraction) ** (1 / 3)
    for _ in range(20):
        t_stop = sigma_goal / rate
        while t < t_stop:
            if axis < 0:
                v -= v.mean(axis=0)
            v[mobile] *= np.sqrt(3.0 / np.mean(np.sum(v[mobile] ** 2, axis=1)))  # unit temperature
            t_before = t
            t, done = _grow(x, v, t, t_stop, rate, length, dims, axis, 20 * n, pinned)
            events += done
            if t - t_before < 1e-6 * t:  # the collision rate diverges: jammed
                raise DPHTError(
                    f"packing jammed at solid fraction {measure(rate * t):.4f} before reaching {solid_fraction}"
                )
        sigma = rate * t
        measured = measure(sigma)
        if axis < 0:
            break
        if measured >= solid_fraction:
            if measure(0.9 * sigma) >= solid_fraction:
                raise DPHTError(f"{match} solid fraction cannot be matched to {solid_fraction} by shrinking")
            sigma = brentq(lambda s: measure(s) - solid_fraction, 0.9 * sigma, sigma, xtol=1e-14)
            measured = measure(sigma)
            break
        # The bulk value goes as sigma^3 at fixed positions; the near-wall band's faster (it widens
        # with the spheres): take its local exponent, so the next stage lands just past the target.
        exponent = np.log(measured / measure(0.99 * sigma)) / -np.log(0.99) if near_wall else 3.0
        sigma_goal = sigma * (1.001 * solid_fraction / measured) ** (1 / max(exponent, 1.0))
        if sigma_goal > np.min(length / dims):  # the cells must stay a diameter wide
            raise DPHTError(f"{match} solid fraction {measured:.4f} cannot reach {solid_fraction} in this box")
    else:
        raise DPHTError(f"{match} solid fraction {measured:.4f} could not be matched to {solid_fraction}")
    for a in range(3):
        if a != axis:
            x[:, a] = np.mod(x[:, a], length[a])
    scale = 2.0 * radius / sigma
    overlap = _max_overlap(x, sigma, length, dims, axis) / (0.5 * sigma)
    box = np.array([np.zeros(3), length * scale])
    periodic = tuple(a != axis for a in range(3))
    return Packing(
        x * scale, float(radius), box, periodic, wall_axis, float(measured), "box" if axis < 0 else match,
        float(overlap), events, int(pinned.sum()),
    )  # fmt: skip


def _place_pins(pins: Pins, x, v, pinned, length, axis, rate):
    """Put the pinned spheres last in ``x``/``v``: lateral place fixed, centre at ``h sigma / 2``
    from its wall at every time (sigma = rate t), i.e. velocity ``h rate / 2`` away from it."""
    k = len(pins)
    lateral = np.asarray(pins.lateral, dtype=float)
    h = np.asarray(pins.distance, dtype=float)
    high = np.asarray(pins.high, dtype=bool)
    if axis < 0:
        raise DPHTError("pins need walls (wall_axis)")
    if lateral.shape != (k, 2) or h.shape != (k,) or high.shape != (k,) or k > x.shape[0] // 2:
        raise DPHTError(f"pins: expected lateral (K, 2), distance (K,), high (K,) with K <= n / 2; got K = {k}")
    if np.any((lateral < 0) | (lateral >= 1)) or not np.all(h >= 1.0) or np.any(h > 0.5 * length[axis] - 1):
        raise DPHTError("pins: lateral fractions must lie in [0, 1) and distances in [1, half the slab - 1] radii")
    free = [a for a in range(3) if a != axis]
    place = lateral * length[free]
    for side in (False, True):
        at = place[high == side]
        gap = np.abs(at[:, None, :] - at[None, :, :])
        gap = np.minimum(gap, length[free] - gap)
        close = np.hypot(gap[..., 0], gap[..., 1])
        np.fill_diagonal(close, np.inf)
        if close.size and close.min() < PIN_CLEARANCE:
            raise DPHTError(f"pins: two pinned spheres at one wall are closer than {PIN_CLEARANCE:g} radii laterally")
    first = x.shape[0] - k
    x[first:, free] = place
    x[first:, axis] = np.where(high, length[axis], 0.0)
    v[first:] = 0.0
    v[first:, axis] = np.where(high, -1.0, 1.0) * 0.5 * rate * h
    pinned[first:] = True


def write_packed_bed(path: str | Path, packing: Packing, *, density: float) -> None:
    """Write ``packing`` as a positions file of one frame (:mod:`dpht.dem.dumps`), ``density`` kg/m^3,
    for the thermal stage's frozen-bed mode (``thermal.frozen_bed``) without a DEM run.

    Periodic axes of the packing stay periodic; the box is the packing's.
    """
    positions = np.asarray(packing.positions, dtype=np.float64)
    ids = np.arange(1, len(positions) + 1, dtype=np.int64)
    frame = DumpFrame(0, np.asarray(packing.box[0], float), np.asarray(packing.box[1], float), tuple(packing.periodic),
                      ids, positions, np.zeros(positions.shape, dtype=np.int32))  # fmt: skip
    write_positions(Path(path), [frame], radius=packing.radius, density=density, timestep=1.0, dump_interval=1)
