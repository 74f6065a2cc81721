"""The conductance network of one frame, for the integrators that work on its fixed geometry.

The explicit integrator re-traverses the cell list at every sub-step (:mod:`dpht.thermal.kernels`).
The implicit and multirate integrators instead list the frame's pairs once, through the same
traversal (:func:`dpht.thermal.neighbors.pair_list`), with the squared centre distance of each pair,
and the wall contacts from the frame's per-zone element and distance arrays (the one wall-contact
representation, :class:`dpht.thermal.integrate.Frame`). From that stored geometry the conductances
at any temperatures are a cheap loop over pairs and contacts that calls the very functions of the
rate kernels (the one composed pair conductance and its wall counterpart,
:func:`dpht.thermal.kernels.pair_side`/``wall_side``), so k(T), the HTC tables' temperature
dependence and the radiation secant are evaluated as the explicit path does (to round-off: the
explicit loop contracts multiply-adds); on request also their slopes in the end temperatures
(:class:`Slopes`, Newton's Jacobian).

The network is a graph Laplacian: one node per particle (its enthalpy is the unknown), one edge per
pair, and Dirichlet wall contacts on the diagonal. Its matrix ``C + c dt L(G)`` is symmetric and
diagonally dominant (with the slopes, the Jacobian ``C - c dt dq/dT``, not symmetric), with a
sparsity fixed for the frame (CSR, columns sorted, the diagonal included, the pairs numbered in the
order of its upper triangle), so the implicit integrator refills only its values. The kernels take
it as three typed records: :class:`Pairs` and :class:`Contacts` (geometry, and the conductances of
the last evaluation) and :class:`Rows` (the matrix's structure and each node's contacts). For
resolved particles (:mod:`dpht.thermal.intraparticle`) a node is a particle's surface node, the one
the pairs and wall contacts see: the implicit integrator condenses each particle's interior onto it,
which changes only the diagonal ``C`` and the right-hand side.

Every per-node sum runs in a fixed order (row by row of the CSR structure), in parallel over
nodes, so results are the same for any thread count, and each pair's heat enters its two rows as
``G (T_j - T_i)`` and ``G (T_i - T_j)``: exact negatives, so the pair terms cancel in the total.
"""

from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np
import scipy.sparse as sparse

from dpht.closures.contact import radiative_slope
from dpht.thermal import neighbors
from dpht.thermal.integrate import Frame, temperatures
from dpht.thermal.kernels import LOOP, PairSide, WallSide, pair_side, wall_side
from dpht.thermal.model import ThermalModel
from dpht.util import krylov
from dpht.util.numba_cache import composed


# Below this many nodes the network's many small kernels run on one thread: waking the thread pool
# costs more than the work (and much more on a loaded machine). Results do not depend on it.
SMALL = 20_000
# Relative temperature step of the forward differences that give the conductances' slopes (Newton's
# Jacobian): the tables are linear between their nodes and radiation is smooth, so the slopes are
# exact to about this relative size (round-off: 1e-16 / 1e-7).
SLOPE_STEP = 1e-7


@contextlib.contextmanager
def threads_for(n: int):
    """Run the block on one numba thread when the network is small (see :data:`SMALL`)."""
    saved = nb.get_num_threads()
    if n < SMALL and saved > 1:
        nb.set_num_threads(1)
    try:
        yield
    finally:
        nb.set_num_threads(saved)


class Pairs(NamedTuple):
    """The frame's particle pairs, (E,) each, and their conductances at the last evaluation."""

    first: np.ndarray  # int64, pair ends (frame order), first < second, pairs in the order of the matrix's upper triangle
    second: np.ndarray  # int64
    r2: np.ndarray  # m2, squared centre distance
    G: np.ndarray  # W/K
    below: np.ndarray  # uint8, 1 where the PFP look-up fell below its table's first distance (clamped there)


class Contacts(NamedTuple):
    """The frame's wall contacts, (W,) each (particle-major, then wall surface), and their
    conductances at the last evaluation."""

    particle: np.ndarray  # int64, frame order
    element: np.ndarray  # int64, wall element
    distance: np.ndarray  # m, centre to wall
    G: np.ndarray  # (W, P) W/K by PW mode (the model's PW modes in order)
    below: np.ndarray  # uint8, 1 where the PFW look-up fell below its table's first distance (clamped there)


class Rows(NamedTuple):
    """Each node's row: its entries of the matrix (CSR, columns sorted, the diagonal included) and its wall contacts."""

    indptr: np.ndarray  # (n + 1,) int64
    indices: np.ndarray  # (nnz,) int32, columns
    entry_pair: np.ndarray  # (nnz,) int32, pair of each off-diagonal entry, -1 on the diagonal
    contact_start: np.ndarray  # (n + 1,) int64, CSR offsets of each node's contacts


@dataclass
class Network:
    """Pairs and wall contacts of one frame, in the frame's (cell-sorted) particle order."""

    n: int  # nodes (particles)
    pairs: Pairs
    contacts: Contacts
    rows: Rows

    def clamped(self) -> dict:
        """Look-ups clamped below a table's first distance in the last evaluation (as
        :meth:`dpht.thermal.integrate.Rates.clamped`)."""
        return {"pfp_distance": int(self.pairs.below.sum()), "pfw_distance": int(self.contacts.below.sum())}


class OnNetwork:
    """Base of the integrators that work on the frame's network: it is assembled once per frame
    object (a frozen bed keeps one) and evaluated at the frame's start temperatures."""

    def __init__(self, model: ThermalModel):
        self.model = model
        self._frame = None

    def network(self, frame: Frame) -> Network:
        if frame is not self._frame:
            self._frame, self.net = frame, assemble(self.model, frame)
            self.prepare(self.net)
        return self.net

    def prepare(self, net: Network) -> None:
        """Allocate work arrays for a new network."""

    def checkpoint(self) -> dict:
        """The counts (the network itself is rebuilt from the frame, bit for bit)."""
        return {f"{self.name}/stats": {k: int(v) for k, v in self.stats.items()}}

    def restore(self, saved: dict) -> None:
        self.stats.update(saved[f"{self.name}/stats"])

    def begin(self, frame: Frame, h: np.ndarray, start=None, shells: np.ndarray | None = None):
        """The frame's network with its conductances at the start temperatures ``T0`` (frame order;
        of the surface nodes of resolved particles, whose node enthalpies are ``shells``), ``T0``, a
        zero wall-heat array and the look-ups clamped at the start."""
        net = self.network(frame)
        T0 = start.T if start is not None else temperatures(self.model, h, frame.particles, shells, mean=False)[0]
        conductances(self.model, net, T0)
        return net, T0, np.zeros((self.model.n_elements, len(self.model.names("pw")))), net.clamped()


def assemble(model: ThermalModel, frame: Frame) -> Network:
    """List the frame's pairs (within the largest PP cutoff) and wall contacts, and build the CSR
    structure of its matrix."""
    n = frame.particles.size
    if frame.cells is not None and model.modes & set(model.names("pp")):
        first, second, r2 = neighbors.pair_list(frame.cells, model.pair_cutoff)
    else:
        first, second, r2 = np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    contact_i, contact_e, contact_d, contact_start = _contacts(frame.wall_element, frame.wall_distance)
    indptr, indices, entry_pair, first, second, r2 = _structure(n, first, second, r2)
    return Network(n, Pairs(first, second, r2, np.zeros(first.size), np.zeros(first.size, np.uint8)),
                   Contacts(contact_i, contact_e, contact_d, np.zeros((contact_i.size, len(model.names("pw")))),
                            np.zeros(contact_i.size, np.uint8)),
                   Rows(indptr, indices, entry_pair, contact_start))  # fmt: skip


@nb.njit(cache=True)
def _contacts(element, distance):
    n = element.shape[1]
    start = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        start[i + 1] = start[i]
        for z in range(element.shape[0]):
            start[i + 1] += element[z, i] >= 0
    contact_i = np.empty(start[n], dtype=np.int64)
    contact_e = np.empty(start[n], dtype=np.int64)
    contact_d = np.empty(start[n])
    w = 0
    for i in range(n):
        for z in range(element.shape[0]):
            if element[z, i] >= 0:
                contact_i[w], contact_e[w], contact_d[w] = i, element[z, i], distance[z, i]
                w += 1
    return contact_i, contact_e, contact_d, start


@nb.njit(cache=True)
def row_offsets(n, first, second, diagonal):
    """CSR offsets (n + 1,) of rows holding one entry per pair end (and one diagonal entry per row
    with ``diagonal``), and a copy of their starts to fill them with."""
    indptr = np.zeros(n + 1, dtype=np.int64)
    for e in range(first.size):
        indptr[first[e] + 1] += 1
        indptr[second[e] + 1] += 1
    for i in range(n):
        indptr[i + 1] += indptr[i] + (1 if diagonal else 0)
    return indptr, indptr[:-1].copy()


@nb.njit(cache=True)
def _by_end(n, first, second, low):
    """The pairs sorted by their lower (``low``) or higher end, stably (a counting sort): CSR
    offsets (n + 1,) per particle and the pair numbers in that order."""
    offsets = np.zeros(n + 1, dtype=np.int64)
    for e in range(first.size):
        offsets[(min(first[e], second[e]) if low else max(first[e], second[e])) + 1] += 1
    for i in range(n):
        offsets[i + 1] += offsets[i]
    cursor = offsets[:-1].copy()
    order = np.empty(first.size, dtype=np.int64)
    for e in range(first.size):
        end = min(first[e], second[e]) if low else max(first[e], second[e])
        order[cursor[end]] = e
        cursor[end] += 1
    return offsets, order


@nb.njit(cache=True, parallel=True)
def _structure(n, first, second, r2):
    """The pairs renumbered in the order of the matrix's upper triangle, row by row (``first <
    second``; the matrix's kernels then read the pair arrays in order for the upper triangle and in
    a few running streams for the lower, twice as fast as in the traversal's order), and the CSR
    rows of the symmetric matrix: per row the lower entries, the diagonal, the upper entries,
    columns sorted. Serial counting sorts, then parallel over rows: the same for any thread count."""
    upper, by_low = _by_end(n, first, second, True)
    new_first = np.empty(first.size, dtype=np.int64)
    new_second = np.empty(first.size, dtype=np.int64)
    new_r2 = np.empty(first.size)
    for i in nb.prange(n):  # each row's pairs by their higher end: an insertion sort (they come nearly sorted)
        for k in range(upper[i], upper[i + 1]):
            e = by_low[k]
            j, d = max(first[e], second[e]), r2[e]
            new_first[k] = i
            m = k
            while m > upper[i] and new_second[m - 1] > j:
                new_second[m], new_r2[m] = new_second[m - 1], new_r2[m - 1]
                m -= 1
            new_second[m], new_r2[m] = j, d
    lower, by_high = _by_end(n, new_first, new_second, False)  # stable: each row's lower entries by column
    indptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        indptr[i + 1] = indptr[i] + (lower[i + 1] - lower[i]) + 1 + (upper[i + 1] - upper[i])
    indices = np.empty(indptr[n], dtype=np.int32)
    entry = np.empty(indptr[n], dtype=np.int32)  # pair numbers: 2^31 pairs would need ~100 GB of network
    for i in nb.prange(n):
        k = indptr[i]
        for m in range(lower[i], lower[i + 1]):
            indices[k], entry[k] = new_first[by_high[m]], by_high[m]
            k += 1
        indices[k], entry[k] = i, -1
        k += 1
        for e in range(upper[i], upper[i + 1]):
            indices[k], entry[k] = new_second[e], e
            k += 1
    return indptr, indices, entry, new_first, new_second, new_r2


# Pairs and wall contacts per task of the conductance kernels' parallel loops: each task unpacks the
# model's state once (see dpht.thermal.kernels) and evaluates its block in order.
BLOCK = 1 << 16


@functools.cache
def _pair_kernel(side: PairSide, slopes: bool):
    """The pairs' conductances through ``side.conductance`` (see :func:`conductances`)."""
    unflatten, conductance, mean, reach = side.unflatten, side.conductance, side.mean, side.reach

    # numba's python error model, not LOOP's numpy one: its checks of the tables' divisions leave
    # the loop early, which keeps LLVM from vectorising it. Vectorised, every pair computes every
    # mode's branch under masks (square roots, the 2-D table), though most pairs only radiate: 1.5
    # times the time at n = 1e5 (measured). The bits are the same either way.
    @composed(_nrt=False)
    def evaluate(start, stop, first, second, r2, G, below, S, T, side, own, tables):
        for e in range(np.uint64(start), np.uint64(stop)):  # unsigned: no negative-index wrap-around
            Ta, Tb = T[first[e]], T[second[e]]
            G[e], below[e], conduction, radiation = conductance(r2[e], Ta, Tb, side, own, tables)
            if slopes:  # radiation's exactly; the mean-temperature modes' by a forward difference, half to each end
                half = 0.0
                if r2[e] < reach(own):  # most pairs only radiate
                    T_mean = 0.5 * (Ta + Tb)
                    step = (T_mean + SLOPE_STEP * T_mean) - T_mean  # exact in binary
                    half = 0.5 * (mean(r2[e], T_mean + step, side, own, tables)[0] - conduction) / step
                S[e, 0] = G[e]
                S[e, 1] = half + radiative_slope(radiation, Ta, Tb)
                S[e, 2] = half + radiative_slope(radiation, Tb, Ta)

    @composed()
    def block(b, first, second, r2, G, below, S, T, state):
        side, own, tables = unflatten(state)
        evaluate(b * BLOCK, min((b + 1) * BLOCK, r2.size), first, second, r2, G, below, S, T, side, own, tables)

    @composed(parallel=True)
    def pair_conductances(pairs, S, T, state):
        first = pairs.first  # each array in an assignment of its own (see dpht.thermal.kernels)
        second = pairs.second
        r2 = pairs.r2
        G = pairs.G
        below = pairs.below
        for b in nb.prange(-(-r2.size // BLOCK)):
            block(b, first, second, r2, G, below, S, T, state)

    return pair_conductances


@functools.cache
def _wall_kernel(side: WallSide, slopes: bool):
    """The wall contacts' conductances through ``side.columns`` (see :func:`conductances`)."""
    unflatten, columns = side.unflatten, side.columns

    @composed(**LOOP)
    def evaluate(start, stop, contacts, Sw, T, element_T, side, own, tables):
        particle, element, distance, Gw, below = contacts
        for w in range(np.uint64(start), np.uint64(stop)):
            Ti, Tw = T[particle[w]], element_T[element[w]]
            G_mode, below[w] = columns(distance[w], Ti, Tw, side, own, tables)
            G = 0.0
            for m in range(len(G_mode)):
                Gw[w, m] = G_mode[m]
                G += G_mode[m]
            if slopes:  # a forward difference of the summed modes (few contacts: no need to split them)
                d = (Ti + SLOPE_STEP * Ti) - Ti
                up = columns(distance[w], Ti + d, Tw, side, own, tables)[0]
                G_up = 0.0
                for m in range(len(up)):
                    G_up += up[m]
                Sw[w] = (G_up - G) / d

    @composed()
    def block(b, contacts, Sw, T, element_T, state):
        side, own, tables = unflatten(state)
        evaluate(b * BLOCK, min((b + 1) * BLOCK, contacts.particle.size), contacts, Sw, T, element_T, side, own, tables)

    @composed(parallel=True)
    def wall_conductances(contacts, Sw, T, element_T, state):
        for b in nb.prange(-(-contacts.particle.size // BLOCK)):
            block(b, contacts, Sw, T, element_T, state)

    return wall_conductances


def conductances(model: ThermalModel, net: Network, T: np.ndarray, slopes: Slopes | None = None) -> None:
    """Pair and wall conductances (W/K) at temperatures ``T`` (K, frame order) into ``net.pairs.G``,
    ``net.contacts.G``, and with ``slopes`` their derivatives in the end temperatures (W/K^2) into it."""
    with_slopes = slopes is not None
    if slopes is None:
        slopes = Slopes(np.zeros((0, 3)), np.zeros(0))
    if net.pairs.first.size:
        _pair_kernel(pair_side(model.side_laws("pp")), with_slopes)(net.pairs, slopes.pairs, T, model.state("pp"))
    if net.contacts.particle.size:
        _wall_kernel(wall_side(model.side_laws("pw")), with_slopes)(net.contacts, slopes.walls, T, model.element_temperature,
                                                                    model.state("pw"))  # fmt: skip


@nb.njit(cache=True)
def contact_sum(Gw, w):
    """Wall contact w's conductance (W/K): its modes' summed in column order."""
    G = 0.0
    for m in range(Gw.shape[1]):
        G += Gw[w, m]
    return G


@nb.njit(cache=True, parallel=True)
def _rates(rows, pairs, contacts, T, element_T, q, g):
    indptr, indices, entry_pair, contact_start = rows.indptr, rows.indices, rows.entry_pair, rows.contact_start
    G, contact_e, Gw = pairs.G, contacts.element, contacts.G
    for i in nb.prange(indptr.size - 1):
        Ti = T[i]
        q_i = 0.0
        g_i = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            e = entry_pair[k]
            if e >= 0:
                q_i += G[e] * (T[indices[k]] - Ti)
                g_i += G[e]
        for w in range(contact_start[i], contact_start[i + 1]):
            G_w = contact_sum(Gw, w)
            q_i += G_w * (element_T[contact_e[w]] - Ti)
            g_i += G_w
        q[i] = q_i
        g[i] = g_i


def rates(model: ThermalModel, net: Network, T: np.ndarray, q: np.ndarray, g: np.ndarray) -> None:
    """Heat into each node (W) and its sum of conductances (W/K) with the conductances in ``net``."""
    _rates(net.rows, net.pairs, net.contacts, T, model.element_temperature, q, g)


@nb.njit(cache=True)
def _element_heat(contacts, T, element_T, weight, out):
    """Serial: per-element sums in contact order (deterministic)."""
    contact_i, contact_e, Gw = contacts.particle, contacts.element, contacts.G
    for w in range(contact_i.size):
        e = contact_e[w]
        dT = element_T[e] - T[contact_i[w]]
        for m in range(Gw.shape[1]):
            out[e, m] += weight * Gw[w, m] * dT


def element_heat(model: ThermalModel, net: Network, T: np.ndarray, weight: float, out: np.ndarray) -> None:
    """Add ``weight`` times the heat (W) through each wall element and PW mode to ``out``."""
    _element_heat(net.contacts, T, model.element_temperature, weight, out)


@nb.njit(cache=True, parallel=True)
def _fill(rows, pairs, contacts, S, Sw, T, element_T, capacity, scale, newton, data, q):
    """Rows of the iteration matrix into ``data`` and the heat into each node into ``q`` (one pass
    over the rows; the sums of ``q`` in the order of :func:`_rates`). Newton reads each pair's
    conductance and slopes from ``S`` (one cache line), Picard its conductance from ``pairs.G``."""
    indptr, indices, entry_pair, contact_start = rows.indptr, rows.indices, rows.entry_pair, rows.contact_start
    G, contact_e, Gw = pairs.G, contacts.element, contacts.G
    for i in nb.prange(indptr.size - 1):
        Ti = T[i]
        q_i = 0.0
        diagonal = 0.0
        own = indptr[i]
        for k in range(indptr[i], indptr[i + 1]):
            e = entry_pair[k]
            if e < 0:
                own = k
                continue
            j = indices[k]
            dT = T[j] - Ti
            if newton:  # d/dT_i and d/dT_j of G (T_j - T_i)
                G_e = S[e, 0]
                s_i, s_j = (S[e, 1], S[e, 2]) if i < j else (S[e, 2], S[e, 1])  # first < second
                data[k] = -scale * (G_e + dT * s_j)
                diagonal += G_e - dT * s_i
            else:
                G_e = G[e]
                data[k] = -scale * G_e
                diagonal += G_e
            q_i += G_e * dT
        for w in range(contact_start[i], contact_start[i + 1]):
            G_w = contact_sum(Gw, w)
            dT = element_T[contact_e[w]] - Ti
            q_i += G_w * dT
            diagonal += G_w - dT * Sw[w] if newton else G_w
        data[own] = capacity[i] + scale * diagonal
        q[i] = q_i


@dataclass
class Slopes:
    """The conductances' derivatives in their end temperatures (W/K^2), radiation's exact and the
    mean-temperature modes' by a forward difference of relative step :data:`SLOPE_STEP`:
    ``pairs[e]`` = (G, dG/dT_first, dG/dT_second), the conductance (W/K) repeated next to its
    slopes so that the matrix fill reads one cache line per pair; ``walls[w]`` of the contact's
    summed modes by the particle's temperature (a forward difference: few contacts)."""

    pairs: np.ndarray  # (E, 3)
    walls: np.ndarray  # (W,)

    @classmethod
    def of(cls, net: Network) -> Slopes:
        return cls(np.zeros((net.pairs.first.size, 3)), np.zeros(net.contacts.particle.size))


class Matrix:
    """The iteration matrix of a step, ``C - scale dq/dT`` (W/K; ``C = m c_p`` in J/K over a unit
    time, q the heat into each node), on the network's fixed sparsity (CSR, values refilled in
    place, also a scipy matrix). Picard (``slopes=None``): the conductances frozen, ``diag(C + scale
    g) - scale G``, symmetric and diagonally dominant; Newton: with the conductances' slopes, its
    Jacobian (not symmetric)."""

    def __init__(self, net: Network):
        self.net = net
        self.data = np.zeros(net.rows.indices.size)
        self.csr = sparse.csr_matrix((self.data, net.rows.indices, net.rows.indptr), shape=(net.n, net.n))
        self.csr.has_sorted_indices = True
        self.arrays = krylov.CSR(net.rows.indptr, net.rows.indices, self.data)
        self.diagonal_at = np.flatnonzero(net.rows.entry_pair < 0)  # one per row, in row order

    def fill(self, model: ThermalModel, T: np.ndarray, capacity: np.ndarray, scale: float, q: np.ndarray,
             slopes: Slopes | None = None) -> None:  # fmt: skip
        """Refill the values at temperatures ``T`` (conductances, and slopes for Newton, already in
        the network) and write the heat into each node (W) to ``q``."""
        net = self.net
        newton = slopes is not None
        S, Sw = (slopes.pairs, slopes.walls) if newton else (np.zeros((0, 3)), np.zeros(0))
        _fill(net.rows, net.pairs, net.contacts, S, Sw, T, model.element_temperature, capacity, scale, newton, self.data, q)

    def diagonal(self) -> np.ndarray:
        return self.data[self.diagonal_at]
