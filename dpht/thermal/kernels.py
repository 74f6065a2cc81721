"""The one pair conductance and its wall counterpart, composed from the enabled modes, and the
compiled heat-rate kernels that use them.

Each heat-transfer mode is one small numba function of its registry entry
(:mod:`dpht.thermal.modes`; the functions in :mod:`dpht.closures.conductance`). For a model's
modes, :func:`pair_side` composes the particle-particle modes' laws, in registry order, into one
:class:`PairSide`: ``conductance`` (W/K) of a pair, which the explicit kernel here, the
integrators' network (:mod:`dpht.thermal.network`, hence the implicit and multirate integrators)
and the screening (through the network) all call, and its parts; :func:`wall_side` composes the
particle-wall modes into one :class:`WallSide` whose ``columns`` give each PW mode's conductance
(the wall-heat columns, PW_MODES in order). A disabled mode is not in the composition at all
(the compositions are compiled per set of enabled modes and cached). Every mode is a conductance
G (W/K) between two temperatures, so one pair contributes ``G (T_j - T_i)`` (W) to particle i and
exactly the negative to particle j, and the sum of conductances per particle bounds the explicit
time step (see :mod:`dpht.thermal.integrate`).

The kernels take plain arrays and a few typed records: the cell grid
(:class:`dpht.thermal.neighbors.Grid`), the output arrays (:class:`dpht.thermal.integrate.Rates`)
and one flat tuple per side, :meth:`dpht.thermal.model.ThermalModel.state`: the side's
:class:`dpht.closures.conductance.Side`, then each enabled mode's
:class:`~dpht.closures.conductance.ModeParams` and table fields, unpacked by the side's
``unflatten`` into ``(side, own, tables)`` (one record and one table per enabled mode). Two limits
of numba's parallel loops (0.68) shape this: it hands records to its threads one level deep only
(a record of records, or a tuple of records, stops the compilation: hence the flat tuple, unpacked
inside the function the loop calls), and it silently drops the loop's writes into an array reached
through a record's field (``pairs.G[e] = ...``) or unpacked together with others (``G, below =
pairs.G, pairs.below``, or ``... = pairs``). So a parallel kernel writes in a function the loop
calls, or takes each array its loop writes out of its record in an assignment of its own before
the loop (``G = pairs.G``). Serial kernels and the functions a parallel loop calls take records,
and records of records, freely.

The composed functions (:data:`dpht.closures.conductance.PIECE`) are inlined (numba IR) into the
loop that calls them, so they cost no call and take the loop's options: the explicit kernel's
fast-math contraction, the network's none (each path as it was with the physics written out in
it). The loops are compiled without reference counting (:data:`LOOP`; they neither create nor
keep arrays): otherwise handing the tables down an inlined composition reference-counts their
arrays at every pair from every thread (three times the time, measured).

Modes and equations of the DPHT paper (see :mod:`dpht.thermal.modes`): ``pp_contact`` Eqs. 2-4,
``pw_contact`` Eqs. 5-7, ``pfp`` Eqs. 8-17, ``pfw`` Eqs. 18-24, ``pp_radiation`` Eq. 25,
``pw_radiation`` Eq. 26.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numba as nb
import numpy as np

from dpht.closures.conductance import PIECE, RADIATIVE, ModeParams, Side
from dpht.closures.contact import radiative_conductance
from dpht.thermal.neighbors import candidates, traversal
from dpht.util.interp import Table1D, Table2D
from dpht.util.numba_cache import composed


class PairSide(NamedTuple):
    """The particle-particle modes of a model, composed (numba functions)."""

    unflatten: object  # (state) -> (side, own, tables)
    conductance: object  # (r2, Ti, Tj, side, own, tables) -> (G W/K, clamped look-ups, G of the MEAN laws, RADIATIVE coefficient)
    mean: object  # (r2, T_mean, side, own, tables) -> (G of the MEAN laws W/K, clamped look-ups)
    reach: object  # (own) -> the MEAN laws' largest cutoff (m2): mean is 0 from it on
    rates: object  # the explicit kernel, see _pair_rates


class WallSide(NamedTuple):
    """The particle-wall modes of a model, composed (numba functions)."""

    unflatten: object  # (state) -> (side, own, tables)
    columns: object  # (d, Ti, Tw, side, own, tables) -> (G W/K per PW mode, a tuple; clamped look-ups)
    rates: object  # the explicit kernel, see _wall_rates


# How a composition starts: no mode yet.
@nb.njit(**PIECE)
def _no_mean(x, T_mean, side, own, tables):
    return 0.0, 0


@nb.njit(**PIECE)
def _no_coefficient(x, T_mean, side, own, tables):
    return 0.0


@nb.njit(**PIECE)
def _no_columns(x, Ti, Tw, side, own, tables):
    return (), 0


def _unflatten(laws: tuple):
    """``state`` -> ``(side, own, tables)`` for the enabled laws (state layout: see the module docstring)."""

    @composed()
    def unflatten(state):
        return Side(state[0], state[1], state[2]), (), ()

    at = len(Side._fields)
    for law in laws:
        unflatten = _then_unflatten(unflatten, at, law.table)
        at += len(ModeParams._fields) + len(law.table._fields)
    return unflatten


def _then_unflatten(before, at, table):
    c, k = at, at + 1
    if table is Table1D:
        x0, dx, values = at + 2, at + 3, at + 4

        @composed()
        def unflatten(state):
            side, own, tables = before(state)
            return side, own + (ModeParams(state[c], state[k]),), tables + (Table1D(state[x0], state[dx], state[values]),)

        return unflatten
    if table is Table2D:
        x0, dx, y0, dy, values = at + 2, at + 3, at + 4, at + 5, at + 6

        @composed()
        def unflatten(state):
            side, own, tables = before(state)
            table = Table2D(state[x0], state[dx], state[y0], state[dy], state[values])
            return side, own + (ModeParams(state[c], state[k]),), tables + (table,)

        return unflatten
    raise TypeError(f"a law's table is Table1D or Table2D, not {table}")


def _then_mean(before, k, conductance):
    @nb.njit(**PIECE)
    def mean(x, T_mean, side, own, tables):
        G, below = before(x, T_mean, side, own, tables)
        if x < own[k].cutoff:
            value, clamped = conductance(x, T_mean, side, own[k], tables[k])
            G += value
            below += clamped
        return G, below

    return mean


@nb.njit(**PIECE)
def _no_reach(own):
    return 0.0


def _then_reach(before, k):
    @nb.njit(**PIECE)
    def reach(own):
        return max(before(own), own[k].cutoff)

    return reach


def _then_coefficient(before, k, conductance):
    @nb.njit(**PIECE)
    def coefficient(x, T_mean, side, own, tables):
        c = before(x, T_mean, side, own, tables)
        if x < own[k].cutoff:
            c += conductance(x, T_mean, side, own[k], tables[k])[0]
        return c

    return coefficient


def _then_column(before, k, conductance, radiative):
    """One more PW column: the mode's conductance, or 0 where it is disabled (``k`` None)."""
    if k is None:

        @nb.njit(**PIECE)
        def off(d, Ti, Tw, side, own, tables):
            G, below = before(d, Ti, Tw, side, own, tables)
            return G + (0.0,), below

        return off

    @nb.njit(**PIECE)
    def columns(d, Ti, Tw, side, own, tables):
        G, below = before(d, Ti, Tw, side, own, tables)
        g = 0.0
        clamped = 0
        if d < own[k].cutoff:
            value, clamped = conductance(d, 0.5 * (Ti + Tw), side, own[k], tables[k])
            g = radiative_conductance(value, Ti, Tw) if radiative else value  # Eq. 26 as a conductance
        return G + (g,), below + clamped

    return columns


@functools.cache
def pair_side(laws: tuple) -> PairSide:
    """The particle-particle composition for ``laws``: per PP mode in registry order its
    :class:`dpht.closures.conductance.Law`, or None where the mode is disabled."""
    enabled = [law for law in laws if law is not None]
    mean, coefficient, reach = _no_mean, _no_coefficient, _no_reach
    for k, law in enumerate(enabled):
        if law.temperature == RADIATIVE:
            coefficient = _then_coefficient(coefficient, k, law.conductance)
        else:
            mean, reach = _then_mean(mean, k, law.conductance), _then_reach(reach, k)
    radiative = any(law.temperature == RADIATIVE for law in enabled)

    @nb.njit(**PIECE)
    def conductance(r2, Ti, Tj, side, own, tables):
        """The pair's conductance (W/K) at squared centre distance ``r2`` (m2) and temperatures
        ``Ti``, ``Tj`` (K): the sum of its enabled modes (registry order), the MEAN laws at the mean
        temperature, the RADIATIVE laws' coefficients summed into one secant (Eq. 25); also the
        clamped look-ups and the two parts (for the Jacobian's slopes)."""
        T_mean = 0.5 * (Ti + Tj)
        G, below = mean(r2, T_mean, side, own, tables) if r2 < reach(own) else (0.0, 0)  # most pairs only radiate
        c = 0.0
        if radiative:
            c = coefficient(r2, T_mean, side, own, tables)
            return G + radiative_conductance(c, Ti, Tj), below, G, c
        return G, below, G, c

    unflatten = _unflatten(tuple(enabled))
    return PairSide(unflatten, conductance, mean, reach, _pair_rates(unflatten, conductance))


@functools.cache
def wall_side(laws: tuple) -> WallSide:
    """The particle-wall composition for ``laws`` (per PW mode in registry order, None where disabled)."""
    columns = _no_columns
    k = 0
    for law in laws:
        columns = _then_column(columns, None if law is None else k, None if law is None else law.conductance,
                               law is not None and law.temperature == RADIATIVE)  # fmt: skip
        k += law is not None
    unflatten = _unflatten(tuple(law for law in laws if law is not None))
    return WallSide(unflatten, columns, _wall_rates(unflatten, columns))


# The loops over pairs and contacts neither create nor keep arrays: compiled without reference
# counting (numba's _nrt option), they pass the tables down the inlined composition for free.
LOOP = {"error_model": "numpy", "_nrt": False}


def _pair_rates(unflatten, conductance):
    @composed(fastmath={"contract"}, **LOOP)
    def pair_visit(first, last, n_run, run_i, run_f, hit_j, hit_r2, coords, cell_start, lo, size, cut2, state):
        """Heat rates of the pairs of a row's particles, added to both sides (the traversal's visitor)."""
        T, rates, side, own, tables = state
        q, g_sum, clamped = rates.q, rates.g, rates.clamped_pairs
        for i in range(first, last):
            n_hit = candidates(i, coords, cell_start, lo, size, run_i, run_f, n_run, cut2, hit_j, hit_r2)
            Ti = T[i]
            q_i = 0.0
            g_i = 0.0
            n_clamped = 0
            for k in range(np.uint64(n_hit)):
                j = hit_j[k]
                Tj = T[j]
                G, below, _, _ = conductance(hit_r2[k], Ti, Tj, side, own, tables)
                n_clamped += below
                flux = G * (Tj - Ti)
                q_i += flux
                g_i += G
                q[j] -= flux
                g_sum[j] += G
            q[i] += q_i
            g_sum[i] += g_i
            clamped[i] += n_clamped  # i is the slab's own: no other thread writes it

    visit_slab = traversal(pair_visit)

    @composed(fastmath={"contract"}, error_model="numpy")
    def slab_rates(slab, grid, coords, T, rates, state):
        """Pairs owned by the cells of one slab, in the traversal's fixed order."""
        side, own, tables = unflatten(state)
        visit_slab(slab, grid, coords, side.reach, (T, rates, side, own, tables))

    @composed(parallel=True)
    def pair_rates(grid, coords, T, rates, state):
        """Add particle-particle heat rates (W) to ``rates.q``, conductance sums (W/K) to ``rates.g``
        and to ``rates.clamped_pairs[i]`` the count of particle i's look-ups below a table's first
        distance (clamped there).

        Arrays are in cell-sorted order (see :mod:`dpht.thermal.neighbors`): ``coords`` (3, N) m,
        ``T`` (N,) K. ``rates`` is a :class:`dpht.thermal.integrate.Rates`, ``state`` the model's PP
        state (module docstring). Slabs of one colour never write the same particles, so they run
        in parallel without races, in a fixed summation order for any thread count.
        """
        colour_start = grid.colour_start
        for colour in range(colour_start.size - 1):
            first = colour_start[colour]
            for t in nb.prange(colour_start[colour + 1] - first):
                slab_rates(grid.colour_slabs[first + t], grid, coords, T, rates, state)

    return pair_rates


def _wall_rates(unflatten, columns):
    @composed(**LOOP)
    def contacts(T, element, distance, element_T, rates, side, own, tables):
        q, g_sum, element_heat, clamped = rates.q, rates.g, rates.element_heat, rates.clamped_walls
        for i in range(element.shape[1]):
            Ti = T[i]
            for z in range(element.shape[0]):
                e = element[z, i]
                if e < 0:
                    continue
                Tw = element_T[e]
                G_mode, below = columns(distance[z, i], Ti, Tw, side, own, tables)
                clamped[0] += below
                G = 0.0
                for m in range(len(G_mode)):
                    G += G_mode[m]
                    element_heat[e, m] += G_mode[m] * (Tw - Ti)
                q[i] += G * (Tw - Ti)
                g_sum[i] += G

    @composed()
    def wall_rates(T, element, distance, element_T, rates, state):
        """Add particle-wall heat rates (W, into the particle) to ``rates.q`` and conductances to ``rates.g``.

        ``element[s, i]``/``distance[s, i]`` are particle i's contact with wall surface s (the frame's
        :class:`dpht.thermal.integrate.Frame` arrays): the element at the surface's nearest point and
        the centre-to-wall distance (m) (-1: no contact, beyond the cutoff or adiabatic there; see
        :mod:`dpht.thermal.model`); ``element_T`` the element temperatures (K). ``rates`` is a
        :class:`dpht.thermal.integrate.Rates`, ``state`` the model's PW state.
        ``rates.element_heat[e, column]`` gains the heat rate (W) through element e for each mode's
        column of PW_MODES; ``rates.clamped_walls[0]`` counts the look-ups below a table's first distance.
        Serial on purpose: per-element sums would race in parallel, and the loop is O(N) and cheap.
        """
        side, own, tables = unflatten(state)
        contacts(T, element, distance, element_T, rates, side, own, tables)

    return wall_rates
