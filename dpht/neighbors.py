"""Cell lists for particle pairs within a cutoff: O(N) build, each pair visited once, race-free.

Particles are counting-sorted into a uniform grid whose cells are at least ``cutoff / reach`` wide,
so a particle's partners lie within ``reach`` cells along each axis. Cells are numbered with the
*slow* axis outermost (the longest or periodic axis) and the *fast* axis innermost; the cells a
particle must search along the fast axis are then one contiguous run of sorted particles.

Each pair is visited once through a half stencil: from cell ``(a, b, c)`` the neighbour rows with
slow offset > 0, or slow offset 0 and mid offset > 0 (all fast offsets), plus the particle's own
row from itself forward. Pair contributions are written to both particles. To do that in parallel
without races, and with the same floating-point summation order for any thread count, cells are
grouped into *slabs* of ``reach`` cell layers along the slow axis. A slab's half stencil only
reaches into itself and the next slab, so all even slabs can run at once, then all odd slabs (and,
on a periodic slow axis with an odd slab count, the last slab alone).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .errors import DPHTError

# Expected particles per cutoff-sized cell above which half-size cells (reach 2) pay off.
_DENSE_CELL = 24.0
# Segment arrays are sized for the largest reach used here.
MAX_REACH = 2
MAX_SEGMENTS = 2 * ((2 * MAX_REACH + 1) ** 2 // 2 + 1)


@dataclass(frozen=True)
class CellList:
    """Particles sorted into cells; all arrays are in the permuted axis order (slow, mid, fast)."""

    order: np.ndarray  # (N,) sorted position -> original particle index
    positions: np.ndarray  # (N, 3) float64, sorted and permuted to (slow, mid, fast) axes
    cell_start: np.ndarray  # (n_cells + 1,) first sorted particle of each cell
    shape: np.ndarray  # (3,) cells along (slow, mid, fast)
    lengths: np.ndarray  # (3,) periodic box lengths along (slow, mid, fast); 0 where open
    axes: np.ndarray  # (3,) original axis of (slow, mid, fast)
    reach: int
    cutoff: float  # the largest pair distance the cells were sized for (m)
    slab_colours: tuple  # tuple of int64 arrays: slabs that may run concurrently


def build(
    positions: np.ndarray,
    cutoff: float,
    *,
    box_lo=None,
    box_hi=None,
    periodic=(False, False, False),
    reach: int | None = None,
) -> CellList:
    """Sort ``positions`` (N, 3) into a cell list for pairs closer than ``cutoff`` (m).

    Periodic axes need ``box_lo``/``box_hi`` and a box at least ``2 * reach + 1`` cells long, so
    that no pair is seen through two images. Positions must be finite; callers drop lost particles.
    """
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise DPHTError(f"positions must have shape (N, 3), got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise DPHTError("positions contain NaN or inf; drop lost particles before building cells")
    if not cutoff > 0:
        raise DPHTError(f"cutoff must be > 0, got {cutoff}")
    periodic = np.asarray(periodic, dtype=bool)
    n = len(pos)
    lo = pos.min(axis=0) if n else np.zeros(3)
    hi = pos.max(axis=0) if n else np.zeros(3)
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
    if reach not in (1, 2):
        raise DPHTError(f"reach must be 1 or 2, got {reach}")

    # Slow axis: a periodic axis if any (slab colouring wraps there), else the longest one.
    candidates = np.flatnonzero(periodic) if periodic.any() else np.arange(3)
    slow = int(candidates[np.argmax(extent[candidates])])
    rest = [a for a in range(3) if a != slow]
    rest.sort(key=lambda a: -extent[a])
    axes = np.array([slow, rest[0], rest[1]], dtype=np.int64)

    width = cutoff / reach
    shape = np.maximum(np.floor(extent[axes] / width).astype(np.int64), 1)
    lengths = np.where(periodic[axes], extent[axes], 0.0)
    for k in range(3):
        if periodic[axes[k]]:
            if shape[k] < 2 * reach + 1:
                raise DPHTError(
                    f"periodic axis {'xyz'[axes[k]]} is {extent[axes[k]]:.4g} m long; it must be at least "
                    f"{(2 * reach + 1) * width:.4g} m ({2 * reach + 1} cells of cutoff/{reach}) for this cutoff"
                )
            if k == 0:
                shape[0] -= shape[0] % reach  # whole slabs along a periodic slow axis
    size = np.where(extent[axes] > 0, extent[axes] / shape, 1.0)

    permuted = np.ascontiguousarray(pos[:, axes])
    order, cell_start = _counting_sort(permuted, lo[axes], size, shape, periodic[axes])
    return CellList(
        order=order,
        positions=np.ascontiguousarray(permuted[order]),
        cell_start=cell_start,
        shape=shape,
        lengths=lengths,
        axes=axes,
        reach=int(reach),
        cutoff=float(cutoff),
        slab_colours=_slab_colours(int(shape[0]), reach, bool(periodic[axes[0]])),
    )


def _slab_colours(n_slow: int, reach: int, periodic: bool) -> tuple:
    n_slabs = -(-n_slow // reach)
    slabs = np.arange(n_slabs, dtype=np.int64)
    if periodic and n_slabs % 2 == 1 and n_slabs > 1:
        # The last (even) slab writes into slab 0 across the boundary: give it its own phase.
        return (slabs[:-1:2].copy(), slabs[1::2].copy(), slabs[-1:].copy())
    return (slabs[0::2].copy(), slabs[1::2].copy())


@nb.njit(cache=True)
def _counting_sort(pos, lo, size, shape, periodic):
    n = pos.shape[0]
    n_cells = shape[0] * shape[1] * shape[2]
    cell = np.empty(n, dtype=np.int64)
    count = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n):
        index = 0
        for k in range(3):
            c = int(np.floor((pos[i, k] - lo[k]) / size[k]))
            if periodic[k]:
                c %= shape[k]
            else:
                c = min(max(c, 0), shape[k] - 1)
            index = index * shape[k] + c
        cell[i] = index
        count[index + 1] += 1
    for c in range(n_cells):
        count[c + 1] += count[c]
    start = count.copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):  # stable: ties keep input order, so the sort is deterministic
        order[start[cell[i]]] = i
        start[cell[i]] += 1
    return order, count


@nb.njit(cache=True)
def cell_segments(cell_start, shape, lengths, reach, a, b, c, seg, shift):
    """Half-stencil neighbour runs of cell (a, b, c); returns their count.

    Run ``s`` covers sorted particles ``seg[s, 0] <= j < seg[s, 1]``, whose positions must be
    shifted by ``shift[s]`` (a periodic image); ``seg[s, 2] == 1`` marks the cell's own row, where
    a particle ``i`` pairs only with ``j > i``.
    """
    n_mid, n_fast = shape[1], shape[2]
    count = 0
    for da in range(0, reach + 1):
        aa = a + da
        sa = 0.0
        if aa >= shape[0]:
            if lengths[0] == 0.0:
                break
            aa -= shape[0]
            sa = lengths[0]
        for db in range(-reach, reach + 1):
            if da == 0 and db < 0:
                continue
            bb = b + db
            sb = 0.0
            if bb < 0 or bb >= n_mid:
                if lengths[1] == 0.0:
                    continue
                sb = -lengths[1] if bb < 0 else lengths[1]
                bb = bb % n_mid
            own = da == 0 and db == 0
            c0 = c if own else c - reach
            c1 = c + reach
            row = (aa * n_mid + bb) * n_fast
            # Up to two runs along the fast axis: in range, and wrapped through a periodic boundary.
            lo_in, hi_in = max(c0, 0), min(c1, n_fast - 1)
            if lo_in <= hi_in:
                seg[count, 0] = cell_start[row + lo_in]
                seg[count, 1] = cell_start[row + hi_in + 1]
                seg[count, 2] = 1 if own else 0
                shift[count, 0], shift[count, 1], shift[count, 2] = sa, sb, 0.0
                count += 1
            if lengths[2] != 0.0:
                if c0 < 0:
                    seg[count, 0] = cell_start[row + c0 + n_fast]
                    seg[count, 1] = cell_start[row + n_fast]
                    seg[count, 2] = 0
                    shift[count, 0], shift[count, 1], shift[count, 2] = sa, sb, -lengths[2]
                    count += 1
                if c1 >= n_fast:
                    seg[count, 0] = cell_start[row]
                    seg[count, 1] = cell_start[row + c1 - n_fast + 1]
                    seg[count, 2] = 0
                    shift[count, 0], shift[count, 1], shift[count, 2] = sa, sb, lengths[2]
                    count += 1
    return count


@nb.njit(cache=True)
def _pairs(cell_start, shape, lengths, reach, pos, cut2):
    seg = np.empty((MAX_SEGMENTS, 3), dtype=np.int64)
    shift = np.empty((MAX_SEGMENTS, 3))
    first, second = [], []
    for a in range(shape[0]):
        for b in range(shape[1]):
            for c in range(shape[2]):
                cell = (a * shape[1] + b) * shape[2] + c
                n_seg = cell_segments(cell_start, shape, lengths, reach, a, b, c, seg, shift)
                for i in range(cell_start[cell], cell_start[cell + 1]):
                    for s in range(n_seg):
                        for j in range(max(seg[s, 0], i + 1) if seg[s, 2] else seg[s, 0], seg[s, 1]):
                            dx = pos[j, 0] + shift[s, 0] - pos[i, 0]
                            dy = pos[j, 1] + shift[s, 1] - pos[i, 1]
                            dz = pos[j, 2] + shift[s, 2] - pos[i, 2]
                            if dx * dx + dy * dy + dz * dz < cut2:
                                first.append(i)
                                second.append(j)
    return np.array(first, dtype=np.int64), np.array(second, dtype=np.int64)


def pairs(cells: CellList, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """All pairs closer than ``cutoff`` as original indices ``(i, j)``, each pair once, ``i != j``.

    Serial; for tests, static beds and diagnostics. The heat kernels traverse the same stencil.
    """
    if cutoff > cells.cutoff:
        raise DPHTError(f"cutoff {cutoff} exceeds the cutoff {cells.cutoff} the cell list was built for")
    i, j = _pairs(cells.cell_start, cells.shape, cells.lengths, cells.reach, cells.positions, cutoff * cutoff)
    return cells.order[i], cells.order[j]


def brute_force_pairs(positions, cutoff, *, box_lo=None, box_hi=None, periodic=(False, False, False)):
    """Reference all-pairs search (minimum image on periodic axes), O(N^2) memory-light numpy."""
    pos = np.asarray(positions, dtype=np.float64)
    periodic = np.asarray(periodic, dtype=bool)
    length = np.ones(3)
    if periodic.any():
        length = np.where(periodic, np.asarray(box_hi, float) - np.asarray(box_lo, float), 1.0)
    first, second = [], []
    for i in range(len(pos) - 1):
        d = pos[i + 1 :] - pos[i]
        d -= periodic * np.round(d / length) * length
        close = np.flatnonzero(np.einsum("ij,ij->i", d, d) < cutoff * cutoff) + i + 1
        first.append(np.full(close.size, i))
        second.append(close)
    if not first:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(first).astype(np.int64), np.concatenate(second).astype(np.int64)
