"""Cell lists for particle pairs within a cutoff: O(N) build, each pair visited once, race-free.

Particles are counting-sorted (in parallel, except the O(N) scatter) into a grid whose cells are
``cutoff / reach`` wide along the *slow* and *mid* axes and a few times narrower along the *fast*
one. Cells are numbered with the slow axis outermost (the longest or periodic axis) and the fast
axis innermost, so a row of cells along the fast axis is one contiguous run of sorted particles; a
particle's partners lie in the rows within ``reach`` rows along the slow and mid axes, and each
particle clips each row to the chord of its cutoff sphere (coordinates are stored per axis so the
distance loop vectorises).

Each pair is visited once through a half stencil: from row ``(a, b)`` the neighbour rows with
slow offset > 0, or slow offset 0 and mid offset > 0, plus the particle's own row from itself
forward. Pair contributions are written to both particles. To do that in parallel without races,
and with the same floating-point summation order for any thread count, rows are grouped into
*slabs* of ``reach`` cell layers along the slow axis. A slab's half stencil only reaches into itself
and the next slab, so all even slabs can run at once, then all odd slabs (and, on a periodic slow
axis with an odd slab count, the last slab alone).

A sheared periodic box (Lees-Edwards; LIGGGHTS' triclinic box with tilt factor xy) is the
orthogonal box whose periodic image across y is shifted by the tilt along x. Particles are wrapped
into the orthogonal box (a y image moves them by the tilt along x), x is made the fast axis, and a
neighbour row reached across the y boundary is that row shifted along x by the tilt: each particle
clips it to its cutoff chord as it does any periodic image along the fast axis, so the cells, the
half stencil and the slab colouring are those of the orthogonal box.

The compiled traversals read the grid as one typed record, :class:`Grid`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

from dpht.errors import DPHTError

# Expected particles per cutoff-sized cell above which half-size cells (reach 2) pay off.
_DENSE_CELL = 24.0
# Fast cells are this many times finer than slow and mid cells.
_FAST_SPLIT = 3
# int(x + _FLOOR_SHIFT) - _FLOOR_SHIFT is floor(x) for x > -_FLOOR_SHIFT, without a call to floor.
_FLOOR_SHIFT = 1 << 20
# Run arrays are sized for the largest reach used here (up to 3 runs per neighbour row).
MAX_REACH = 2
MAX_RUNS = 3 * ((2 * MAX_REACH + 1) ** 2 // 2 + 1)


class Grid(NamedTuple):
    """The cell grid and its slab schedule, in the permuted axis order (slow, mid, fast)."""

    cell_start: np.ndarray  # (n_cells + 1,) int64, first sorted particle of each cell
    shape: np.ndarray  # (3,) int64, cells along (slow, mid, fast)
    lo: np.ndarray  # (3,) grid origin (m)
    size: np.ndarray  # (3,) cell edge lengths (m)
    lengths: np.ndarray  # (3,) periodic box lengths along (slow, mid, fast) (m); 0 where open
    shear: np.ndarray  # (2,) shift along the fast axis (m) of the image one period along slow, mid: the tilt on y, else 0
    reach: int  # slow and mid cells are cutoff / reach wide; fast cells _FAST_SPLIT times narrower
    colour_start: np.ndarray  # (n_colours + 1,) int64, CSR offsets into colour_slabs
    colour_slabs: np.ndarray  # int64 slabs of each colour: the slabs of one colour may run concurrently


@dataclass(frozen=True)
class CellList:
    """Particles sorted into cells; all arrays are in the permuted axis order (slow, mid, fast)."""

    order: np.ndarray  # (N,) sorted position -> original particle index
    coords: np.ndarray  # (3, N) float64, sorted, axes permuted to (slow, mid, fast), wrapped into the orthogonal box
    grid: Grid
    axes: np.ndarray  # (3,) original axis of (slow, mid, fast)
    cutoff: float  # the largest pair distance the cells were sized for (m)


def build(
    positions: np.ndarray,
    cutoff: float,
    *,
    box_lo=None,
    box_hi=None,
    periodic=(False, False, False),
    tilt: float = 0.0,
    reach: int | None = None,
) -> CellList:
    """Sort ``positions`` (N, 3) into a cell list for pairs closer than ``cutoff`` (m).

    Rows with a non-finite coordinate (particles lost by the DEM) are left out of ``order``.
    Periodic axes need ``box_lo``/``box_hi`` and a box at least ``2 * reach + 1`` cells long, so
    that no pair is seen through two images. ``tilt`` (m) is the xy tilt factor of a sheared box
    (x and y periodic): the image one period up in y lies ``tilt`` further along x. Any tilt is
    taken (LIGGGHTS keeps it within half the x length, flipping the box by one x length, an
    equivalent box).
    """
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise DPHTError(f"positions must have shape (N, 3), got {pos.shape}")
    if not cutoff > 0:
        raise DPHTError(f"cutoff must be > 0, got {cutoff}")
    periodic = np.asarray(periodic, dtype=bool)
    tilt = float(tilt)
    if not math.isfinite(tilt) or (tilt != 0.0 and not (periodic[0] and periodic[1])):
        raise DPHTError(f"tilt {tilt} m: a sheared box needs a finite tilt and periodic x and y, got periodic {periodic.tolist()}")
    n, lo, hi = _finite_bounds(pos)
    if periodic.any():
        if box_lo is None or box_hi is None:
            raise DPHTError("periodic axes need box_lo and box_hi")
        box_lo, box_hi = np.asarray(box_lo, float), np.asarray(box_hi, float)
        lo = np.where(periodic, box_lo, lo)
        hi = np.where(periodic, box_hi, hi)
    extent = np.maximum(hi - lo, 0.0)

    if reach is None:
        volume = np.prod(np.maximum(extent, cutoff))
        per_cell = n * cutoff**3 / volume if volume > 0 else 0.0
        reach = 2 if per_cell > _DENSE_CELL else 1
        # A periodic axis shorter than 3 cutoffs (a short slice of a tube) still fits 5 half-cutoff cells.
        if reach == 1 and np.any(periodic & (extent < 3.0 * cutoff)):
            reach = 2
    if reach not in (1, 2):
        raise DPHTError(f"reach must be 1 or 2, got {reach}")

    # Slow axis: a periodic axis if any (slab colouring wraps there), else the longest one; in a
    # sheared box x is the fast axis, along which a row's image across y is shifted by the tilt.
    axes = _axis_order(extent, periodic, sheared=tilt != 0.0)

    # Fast cells are finer: clipping a row to a particle's cutoff chord then wastes less of its
    # ends, at no extra cost (about 17% fewer candidate distances at reach 2).
    reaches = np.array([reach, reach, _FAST_SPLIT * reach], dtype=np.int64)
    width = cutoff / reaches
    shape = np.maximum(np.floor(extent[axes] / width).astype(np.int64), 1)
    lengths = np.where(periodic[axes], extent[axes], 0.0)
    for k in range(3):
        if periodic[axes[k]]:
            if shape[k] < 2 * reaches[k] + 1:
                raise DPHTError(
                    f"periodic axis {'xyz'[axes[k]]} is {extent[axes[k]]:.4g} m long; it must be at least "
                    f"{(2 * reaches[k] + 1) * width[k]:.4g} m ({2 * reaches[k] + 1} cells of cutoff/{reaches[k]}) for this cutoff"
                )
            if k == 0:  # whole slabs along a periodic slow axis, an even number when there is room
                shape[0] -= shape[0] % (2 * reach if shape[0] >= 4 * reach else reach)
    size = np.where(extent[axes] > 0, extent[axes] / shape, 1.0)
    lo = np.ascontiguousarray(lo[axes])
    # The tilt as the equivalent one within half the x length: a row's images along x at -L, 0, +L
    # shifted by it then cover every cutoff chord (L > 2 cutoffs).
    tilt = tilt - extent[0] * round(tilt / extent[0]) if tilt != 0.0 else 0.0
    gradient = int(np.flatnonzero(axes == 1)[0]) if tilt != 0.0 else -1  # the slow or mid position of y
    shear = np.array([tilt if gradient == k else 0.0 for k in range(2)])
    cell = _cell_index(pos, axes, lo, size, shape, lengths, gradient, tilt)
    order, cell_start = _counting_sort(cell, n, int(np.prod(shape)))
    colours = _slab_colours(int(shape[0]), reach, bool(periodic[axes[0]]))
    grid = Grid(
        cell_start, shape, lo, size, lengths, shear, int(reach),
        colour_start=np.concatenate([[0], np.cumsum([len(c) for c in colours])]).astype(np.int64),
        colour_slabs=np.concatenate(colours).astype(np.int64),
    )  # fmt: skip
    coords = _gather(pos, order, axes, lo, lengths, gradient, tilt)
    return CellList(order=order, coords=coords, grid=grid, axes=axes, cutoff=float(cutoff))


def _axis_order(extent: np.ndarray, periodic: np.ndarray, sheared: bool) -> np.ndarray:
    """Original axes of (slow, mid, fast): slow a periodic axis if any, the longest of those
    allowed; fast x in a sheared box, else the shortest of the rest."""
    allowed = [a for a in range(3) if not (sheared and a == 0)]
    candidates = [a for a in allowed if periodic[a]] or allowed
    slow = max(candidates, key=lambda a: (extent[a], -a))
    rest = sorted((a for a in range(3) if a != slow), key=lambda a: (sheared and a == 0, -extent[a]))
    return np.array([slow, rest[0], rest[1]], dtype=np.int64)


def _slab_colours(n_slow: int, reach: int, periodic: bool) -> tuple:
    n_slabs = -(-n_slow // reach)
    slabs = np.arange(n_slabs, dtype=np.int64)
    if periodic and n_slabs % 2 == 1 and n_slabs > 1:
        # The last (even) slab writes into slab 0 across the boundary: give it its own phase.
        return (slabs[:-1:2].copy(), slabs[1::2].copy(), slabs[-1:].copy())
    return (slabs[0::2].copy(), slabs[1::2].copy())


@nb.njit(cache=True)
def _finite_bounds(pos):
    """Count, lower and upper corner of the rows of ``pos`` with finite coordinates."""
    lo = np.zeros(3)
    hi = np.zeros(3)
    n = 0
    for i in range(pos.shape[0]):
        if not (math.isfinite(pos[i, 0]) and math.isfinite(pos[i, 1]) and math.isfinite(pos[i, 2])):
            continue
        for k in range(3):
            if n == 0 or pos[i, k] < lo[k]:
                lo[k] = pos[i, k]
            if n == 0 or pos[i, k] > hi[k]:
                hi[k] = pos[i, k]
        n += 1
    return n, lo, hi


@nb.njit(cache=True)
def _wrap(x, lo, length):
    """``x`` wrapped into [lo, lo + length) on a periodic axis (``length > 0``), else unchanged."""
    if length > 0.0 and not lo <= x < lo + length:  # the modulo only for the few outside
        return lo + (x - lo) % length
    return x


@nb.njit(cache=True)
def _in_box(pos, i, axes, lo, lengths, gradient, tilt):
    """Particle ``i``'s coordinates (slow, mid, fast), wrapped into the orthogonal box on periodic
    axes; across the y boundary of a sheared box (``gradient``, the slow or mid position of y, or
    -1) its image also moves by ``tilt`` per period along the fast axis x."""
    s, m, f = pos[i, axes[0]], pos[i, axes[1]], pos[i, axes[2]]
    if gradient < 0:
        return _wrap(s, lo[0], lengths[0]), _wrap(m, lo[1], lengths[1]), _wrap(f, lo[2], lengths[2])
    y, y_lo, period = (s, lo[0], lengths[0]) if gradient == 0 else (m, lo[1], lengths[1])
    periods = np.floor((y - y_lo) / period)
    if periods != 0.0 and math.isfinite(periods):
        # Clamped, not wrapped again: a rounding to y_lo + period must not move y a period
        # without moving x by the tilt.
        y = min(max(y - periods * period, y_lo), y_lo + period)
        f -= periods * tilt
    f = _wrap(f, lo[2], lengths[2])
    if gradient == 0:
        return y, _wrap(m, lo[1], lengths[1]), f
    return _wrap(s, lo[0], lengths[0]), y, f


@nb.njit(cache=True, parallel=True)
def _cell_index(pos, axes, lo, size, shape, lengths, gradient, tilt):
    """Cell of every particle (-1 for a non-finite position), in parallel."""
    cell = np.empty(pos.shape[0], dtype=np.int64)
    for i in nb.prange(pos.shape[0]):
        c = _in_box(pos, i, axes, lo, lengths, gradient, tilt)
        index = 0
        for k in range(3):
            x = c[k]
            if not math.isfinite(x):
                index = -1
                break
            index = index * shape[k] + min(max(int(math.floor((x - lo[k]) / size[k])), 0), shape[k] - 1)
        cell[i] = index
    return cell


@nb.njit(cache=True)
def _counting_sort(cell, n, n_cells):
    """Stable counting sort of the ``n`` particles with a cell (>= 0) by cell: ties keep input
    order, so the result is deterministic."""
    count = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(cell.size):
        if cell[i] >= 0:
            count[cell[i] + 1] += 1
    for c in range(n_cells):
        count[c + 1] += count[c]
    start = count[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(cell.size):
        if cell[i] >= 0:
            order[start[cell[i]]] = i
            start[cell[i]] += 1
    return order, count


@nb.njit(cache=True, parallel=True)
def _gather(pos, order, axes, lo, lengths, gradient, tilt):
    """Sorted coordinates (3, N) in the permuted axis order, wrapped into the orthogonal box."""
    coords = np.empty((3, order.size))
    for s in nb.prange(order.size):
        c = _in_box(pos, order[s], axes, lo, lengths, gradient, tilt)
        for k in range(3):
            coords[k, s] = c[k]
    return coords


@nb.njit(cache=True)
def row_runs(grid, a, b, run_i, run_f):
    """Half-stencil neighbour runs of the particles in row (a, b); returns their count.

    A run is a whole row of cells along the fast axis, first cell ``run_i[r, 0]`` and cells
    ``run_i[r, 1]..run_i[r, 2]``, which each particle clips to its cutoff chord (so the runs do not
    depend on the particle's own fast cell). ``run_i[r, 3] == 1`` on the own row (pairs only with
    j > i, which also rules out the backward periodic image there). ``run_f[r]`` holds the row's
    low slow and mid coordinates and the image shift (slow, mid, fast) to add to its particles'
    coordinates (across y in a sheared box, the fast shift includes the tilt). The remaining
    columns are scratch for :func:`candidates`.
    """
    shape, lo, size, lengths, shear, reach = grid.shape, grid.lo, grid.size, grid.lengths, grid.shear, grid.reach
    n_mid, n_fast = shape[1], shape[2]
    count = 0
    for da in range(0, reach + 1):
        aa = a + da
        sa = 0.0
        fa = 0.0
        if aa >= shape[0]:
            if lengths[0] == 0.0:
                break
            aa -= shape[0]
            sa = lengths[0]
            fa = shear[0]
        for db in range(-reach, reach + 1):
            if da == 0 and db < 0:
                continue
            bb = b + db
            sb = 0.0
            fb = 0.0
            if bb < 0 or bb >= n_mid:
                if lengths[1] == 0.0:
                    continue
                sb = -lengths[1] if bb < 0 else lengths[1]
                fb = -shear[1] if bb < 0 else shear[1]
                bb = bb % n_mid
            own = da == 0 and db == 0
            # The row itself and, on a periodic fast axis, its images on either side.
            for part in range(3):
                if part > 0 and lengths[2] == 0.0:
                    break
                if part == 1 and own:
                    continue
                run_i[count, 0] = (aa * n_mid + bb) * n_fast
                run_i[count, 1] = 0
                run_i[count, 2] = n_fast - 1
                run_i[count, 3] = 1 if own and part == 0 else 0
                run_f[count, 0] = lo[0] + aa * size[0] + sa
                run_f[count, 1] = lo[1] + bb * size[1] + sb
                run_f[count, 2] = sa
                run_f[count, 3] = sb
                run_f[count, 4] = (0.0, -lengths[2], lengths[2])[part] + fa + fb
                count += 1
    return count


@nb.njit(cache=True)
def buffers():
    """Work arrays of a traversal: ``run_i``, ``run_f`` (the runs of a row, then a particle's
    spans of them) and the hit buffers ``hit_j``, ``hit_r2`` (grown by :func:`prepare_row`)."""
    return np.empty((MAX_RUNS, 6), dtype=np.int64), np.empty((MAX_RUNS, 8)), np.empty(256, dtype=np.uint64), np.empty(256)


@nb.njit(cache=True)
def prepare_row(grid, a, b, run_i, run_f, hit_j, hit_r2):
    """Runs of row (a, b) and hit buffers large enough for any of its particles.

    Returns ``(n_run, hit_j, hit_r2)``; the buffers are the given ones unless they had to grow.
    """
    n_run = row_runs(grid, a, b, run_i, run_f)
    cell_start = grid.cell_start
    need = 0  # particles in all runs, unclipped
    for r in range(n_run):
        need += cell_start[run_i[r, 0] + run_i[r, 2] + 1] - cell_start[run_i[r, 0] + run_i[r, 1]]
    if need > hit_j.size:
        hit_j, hit_r2 = np.empty(2 * need, dtype=np.uint64), np.empty(2 * need)
    return n_run, hit_j, hit_r2


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def candidates(i, coords, cell_start, lo, size, run_i, run_f, n_run, cut2, hit_j, hit_r2):
    """Partners j of sorted particle i closer than sqrt(cut2); returns their count.

    Fills ``hit_j`` (unsigned) and ``hit_r2`` (squared distance, m2). First each run is clipped to
    the cells the cutoff sphere can reach, given the particle's gap to the row in the slow and mid
    directions; the spans left are kept in spare columns of the run arrays. Then the distances of
    all spans are computed branch-free and compressed, so the caller's physics loop only sees hits.
    Doing the two apart keeps the distance loop tight; unsigned indices spare numba's
    negative-index wrap-around in it. Called once per particle and not inlined, it takes the three
    arrays of the :class:`Grid` it reads rather than the whole record (each argument costs a copy).
    """
    xs, xm, xf = coords[0, i], coords[1, i], coords[2, i]
    inv = 1.0 / size[2]
    u = (xf - lo[2]) * inv + _FLOOR_SHIFT  # fast position in cells, shifted so int() floors
    spans = 0
    for r in range(n_run):
        gs = max(0.0, run_f[r, 0] - xs, xs - run_f[r, 0] - size[0])
        gm = max(0.0, run_f[r, 1] - xm, xm - run_f[r, 1] - size[1])
        rem = cut2 - gs * gs - gm * gm
        if rem <= 0.0:
            continue
        # A chord widened by a millionth of a cell: rounding can only add a cell, never drop one.
        w = math.sqrt(rem) * inv + 1e-6
        v = u - run_f[r, 4] * inv
        k0 = max(run_i[r, 1], int(v - w) - _FLOOR_SHIFT)
        k1 = min(run_i[r, 2], int(v + w) - _FLOOR_SHIFT)
        if k0 > k1:
            continue
        j0 = cell_start[run_i[r, 0] + k0]
        j1 = cell_start[run_i[r, 0] + k1 + 1]
        if run_i[r, 3]:
            j0 = max(j0, i + 1)
        if j0 >= j1:
            continue
        run_i[spans, 4] = j0  # spans <= r: row `spans` was read already
        run_i[spans, 5] = j1
        run_f[spans, 5] = run_f[r, 2] - xs
        run_f[spans, 6] = run_f[r, 3] - xm
        run_f[spans, 7] = run_f[r, 4] - xf
        spans += 1
    slow, mid, fast = coords[0], coords[1], coords[2]
    h = np.uint64(0)
    for s in range(spans):
        ds, dm, df = run_f[s, 5], run_f[s, 6], run_f[s, 7]
        for j in range(np.uint64(run_i[s, 4]), np.uint64(run_i[s, 5])):
            a = slow[j] + ds
            b = mid[j] + dm
            c = fast[j] + df
            r2 = a * a + b * b + c * c
            hit_j[h] = j
            hit_r2[h] = r2
            h += np.uint64(r2 < cut2)
    return np.int64(h)


def traversal(visit):
    """The one pair traversal, compiled for the per-particle function ``visit``.

    Returns ``visit_slab(slab, grid, coords, cut2, state)``, which takes every pair owned by the
    cells of ``slab`` closer than sqrt(cut2), row by row in a fixed order: for each row it calls
    ``visit(first, last, n_run, run_i, run_f, hit_j, hit_r2, coords, cell_start, lo, size, cut2,
    state)``, and ``visit`` finds each of the row's particles ``first <= i < last`` its partners with
    :func:`candidates` and uses them; ``state`` is a tuple of what ``visit`` reads and writes (the
    heat-rate kernel's: the temperatures, the output record and the modes' parameters and tables),
    unpacked once per row (unpacking it per particle would reference-count its arrays from every
    thread at every particle, which halves the speed). The heat-rate
    kernel (``rates`` of :func:`dpht.thermal.kernels.pair_side`) and the pair list of the implicit and
    multirate integrators (:func:`pair_list`) both traverse through here. ``visit`` is bound at
    compile time (a closure, which numba caches by its cell contents) rather than passed as an
    argument, which would make the compiled traversal hold a Python object and not cache. Within
    a slab the mid axis is outermost: the slab's layers then share their neighbour rows while they
    are in cache.
    """

    @nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
    def visit_slab(slab, grid, coords, cut2, state):
        run_i, run_f, hit_j, hit_r2 = buffers()
        cell_start, shape, reach, lo, size = grid.cell_start, grid.shape, grid.reach, grid.lo, grid.size
        for b in range(shape[1]):
            for a in range(slab * reach, min((slab + 1) * reach, shape[0])):
                n_run, hit_j, hit_r2 = prepare_row(grid, a, b, run_i, run_f, hit_j, hit_r2)
                row = (a * shape[1] + b) * shape[2]
                visit(cell_start[row], cell_start[row + shape[2]], n_run, run_i, run_f, hit_j, hit_r2, coords, cell_start, lo,
                      size, cut2, state)  # fmt: skip

    return visit_slab


@nb.njit(cache=True)
def _count(first, last, n_run, run_i, run_f, hit_j, hit_r2, coords, cell_start, lo, size, cut2, state):
    count = state[0]
    for i in range(first, last):
        count[0] += candidates(i, coords, cell_start, lo, size, run_i, run_f, n_run, cut2, hit_j, hit_r2)


@nb.njit(cache=True)
def _fill(start, last, n_run, run_i, run_f, hit_j, hit_r2, coords, cell_start, lo, size, cut2, state):
    first, second, r2, cursor = state
    for i in range(start, last):
        n_hit = candidates(i, coords, cell_start, lo, size, run_i, run_f, n_run, cut2, hit_j, hit_r2)
        at = cursor[0]
        for k in range(n_hit):
            first[at + k] = i
            second[at + k] = hit_j[k]
            r2[at + k] = hit_r2[k]
        cursor[0] = at + n_hit


_count_slab, _fill_slab = traversal(_count), traversal(_fill)


@nb.njit(cache=True, parallel=True)
def _pair_list(grid, coords, cut2):
    n_slabs = -(-grid.shape[0] // grid.reach)
    start = np.zeros(n_slabs + 1, dtype=np.int64)
    for s in nb.prange(n_slabs):
        count = np.zeros(1, dtype=np.int64)
        _count_slab(s, grid, coords, cut2, (count,))
        start[s + 1] = count[0]
    for s in range(n_slabs):
        start[s + 1] += start[s]
    first = np.empty(start[n_slabs], dtype=np.int64)
    second = np.empty(start[n_slabs], dtype=np.int64)
    r2 = np.empty(start[n_slabs])
    for s in nb.prange(n_slabs):
        cursor = np.full(1, start[s], dtype=np.int64)
        _fill_slab(s, grid, coords, cut2, (first, second, r2, cursor))
    return first, second, r2


def pair_list(cells: CellList, cutoff: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pair closer than ``cutoff`` (m) as sorted indices ``(i, j, r2)``, each pair once, with
    the squared centre distance r2 (m2, periodic images included).

    The order is the traversal's (slab by slab, each slab's particles in a fixed order), whatever
    the thread count: two passes over the slabs in parallel, one counting and one filling.
    """
    if cutoff > cells.cutoff:
        raise DPHTError(f"cutoff {cutoff} exceeds the cutoff {cells.cutoff} the cell list was built for")
    return _pair_list(cells.grid, cells.coords, cutoff * cutoff)


def separations(cells: CellList, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Vectors (M, 3) in m, along x, y, z, from sorted particles ``first`` to the nearest periodic
    image of sorted particles ``second`` (pairs of :func:`pair_list`): in a sheared box a period in
    y moves the image by the tilt along x. The nearest image for pairs closer than half the box,
    as every pair within the cutoff of a cell list is."""
    d = cells.coords[:, second] - cells.coords[:, first]
    lengths, shear = cells.grid.lengths, cells.grid.shear
    for k in (0, 1):  # slow and mid first: across y they move the fast axis x by the tilt
        if lengths[k] > 0.0:
            periods = np.round(d[k] / lengths[k])
            d[k] -= periods * lengths[k]
            d[2] -= periods * shear[k]
    if lengths[2] > 0.0:
        d[2] -= np.round(d[2] / lengths[2]) * lengths[2]
    out = np.empty((d.shape[1], 3))
    out[:, cells.axes] = d.T
    return out


def pairs(cells: CellList, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """All pairs closer than ``cutoff`` as original indices ``(i, j)``, each pair once, ``i != j``.

    For tests, static beds and diagnostics; the order is that of :func:`pair_list`.
    """
    i, j, _ = pair_list(cells, cutoff)
    return cells.order[i], cells.order[j]


def brute_force_pairs(positions, cutoff, *, box_lo=None, box_hi=None, periodic=(False, False, False), tilt=0.0):
    """Reference all-pairs search (minimum image on periodic axes), O(N^2) memory-light numpy.

    In a sheared box (``tilt``, see :func:`build`) the y image is taken first, shifting x by the
    tilt, then the x and z images: the nearest image for any pair closer than half the box.
    """
    pos = np.asarray(positions, dtype=np.float64)
    periodic = np.asarray(periodic, dtype=bool)
    length = np.ones(3)
    if periodic.any():
        length = np.where(periodic, np.asarray(box_hi, float) - np.asarray(box_lo, float), 1.0)
    first, second = [], []
    for i in range(len(pos) - 1):
        d = pos[i + 1 :] - pos[i]
        if tilt:
            periods = np.round(d[:, 1] / length[1])
            d[:, 0] -= periods * tilt
            d[:, 1] -= periods * length[1]
        d -= periodic * np.round(d / length) * length
        close = np.flatnonzero(np.einsum("ij,ij->i", d, d) < cutoff * cutoff) + i + 1
        first.append(np.full(close.size, i))
        second.append(close)
    if not first:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(first).astype(np.int64), np.concatenate(second).astype(np.int64)
