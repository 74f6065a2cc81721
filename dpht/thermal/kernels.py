"""Compiled heat-rate kernels: particle-particle pairs and particle-wall contacts.

Each kernel is specialised on the enabled heat-transfer modes (numba literal booleans, one per
mode in the order of :data:`dpht.thermal.modes.PP_MODES` / ``PW_MODES``), so a disabled mode is
compiled out of the pair loop rather than tested per pair. Every mode is written as a conductance
G (W/K) between two temperatures, so one pair contributes ``G (T_j - T_i)`` (W) to particle i and
exactly the negative to particle j, and the sum of conductances per particle bounds the explicit
time step (see :mod:`dpht.thermal.integrate`).

The kernels take plain arrays and a few typed records: the cell grid
(:class:`dpht.thermal.neighbors.Grid`), the output arrays (:class:`dpht.thermal.integrate.Rates`),
one record of each side's scalar parameters (:class:`PairModes`, :class:`WallModes`) and one
uniform table per mode (:class:`dpht.util.interp.Table1D`/``Table2D``), grouped as
:class:`PairTables` / :class:`WallTables` with one field per mode, in flag order. Two limits of
numba's parallel loops (0.68) shape how a parallel kernel takes records: it hands them to its
threads one level deep only (a record of records stops the compilation, so the kernels take a
side's tables one by one, ``*model.pair_tables``), and it silently drops the loop's writes into
an array reached through a record's field (``pairs.G[e] = ...``) or unpacked together with others
(``G, below = pairs.G, pairs.below``, or ``... = pairs``). So a parallel kernel takes each array
its loop writes out of its record in an assignment of its own before the loop (``G = pairs.G``),
or writes in a function the loop calls. Serial kernels and the functions a parallel loop calls
take records, and records of records, freely.

Modes and equations of the DPHT paper (see :mod:`dpht.thermal.modes`): ``pp_contact`` Eqs. 2-4,
``pw_contact`` Eqs. 5-7, ``pfp`` Eqs. 8-17, ``pfw`` Eqs. 18-24, ``pp_radiation`` Eq. 25,
``pw_radiation`` Eq. 26.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numba as nb
import numpy as np
from numba import literally
from numba.core import types

from dpht.closures.contact import (
    pp_contact,
    pp_real_distance,
    pw_contact,
    pw_real_distance,
    radiative_conductance,
)
from dpht.thermal.modes import PP_MODES, PW_MODES, wall_column
from dpht.thermal.neighbors import candidates, traversal
from dpht.util.interp import Table1D, Table2D, table_1d, table_1d_inside, table_2d


class PairModes(NamedTuple):
    """Scalar parameters of the particle-particle modes."""

    radius: float  # m
    cutoff2: float  # m2, the squared neighbour-search cutoff (largest enabled PP cutoff)
    softening: float  # c_PP, Eq. 3 (contact radius, Eq. 4, and real distance, Eq. 17)
    pfp_cutoff2: float  # m2
    radiation_cutoff2: float  # m2
    radiation_coefficient: float  # eps_p A_p sigma, W/K^4


class PairTables(NamedTuple):
    """One table per particle-particle mode, fields in the order of PP_MODES."""

    pp_contact: Table1D  # k_s, W/(m K) over the pair's mean temperature (K)
    pfp: Table2D  # W/K over real centre distance (m) and mean temperature (K)
    pp_radiation: Table1D  # RDF over (centre distance / radius)^2, from 0 (see dpht.thermal.model)


class WallModes(NamedTuple):
    """Scalar parameters of the particle-wall modes."""

    radius: float  # m
    softening: float  # c_PW, Eq. 7 (contact radius, Eq. 5, and real distance, Eq. 24)
    pfw_cutoff: float  # m, centre-wall
    radiation_cutoff: float  # m
    radiation_coefficient: float  # eps_p A_p sigma, W/K^4


class WallTables(NamedTuple):
    """One table per particle-wall mode, fields in the order of PW_MODES."""

    pw_contact: Table1D  # 4 / (1/k_p + 1/k_w) (Eq. 6), W/(m K) over the mean temperature (K)
    pfw: Table2D  # W/K over real centre-wall distance (m) and mean temperature (K)
    pw_radiation: Table1D  # RDF over (centre-wall distance / radius)^2


if PairTables._fields != PP_MODES or WallTables._fields != PW_MODES:
    raise ImportError("dpht.thermal.kernels: the kernels' mode order differs from the registry dpht.thermal.modes")

# Columns of element_heat (and of thermal.h5:/wall_heat), compile-time constants in wall_rates.
_CONTACT, _PFW, _RADIATION = (wall_column(name) for name in PW_MODES)


class PairVisit(NamedTuple):
    """What the pair visitor reads and writes, built per slab by :func:`_slab_rates`. The
    traversal's ``state`` is ``(PairVisit, flags)``: the mode flags stay a plain tuple, the one
    container in which numba keeps them compile-time constants (a NamedTuple field would not)."""

    T: np.ndarray  # (N,) K, sorted order
    rates: tuple  # the output record, dpht.thermal.integrate.Rates: q, g and clamped_pairs are written
    p: PairModes
    tables: PairTables


@nb.njit(cache=True, parallel=True)
def pair_rates(grid, coords, T, rates, p, k_solid, pfp, rdf, pp_contact_on, pfp_on, pp_radiation_on):
    """Add particle-particle heat rates (W) to ``rates.q``, conductance sums (W/K) to ``rates.g``
    and to ``rates.clamped_pairs[i]`` the count of particle i's PFP look-ups below the table's
    first distance (clamped there, see :func:`pair_conduction`).

    Arrays are in cell-sorted order (see :mod:`dpht.thermal.neighbors`): ``coords`` (3, N) m,
    ``T`` (N,) K. ``rates`` is a :class:`dpht.thermal.integrate.Rates`, ``p`` a :class:`PairModes`,
    the tables those of :class:`PairTables`, one by one: a parallel loop hands records to its
    threads one level deep only (a nested record stops the compilation). The PP RDF is tabulated
    over squared centre distance in radii squared from 0, one step past the radiation cutoff, so
    radiation needs no square root and no clamping. The three flags are compile-time constants:
    each combination is its own compiled kernel. Slabs of one colour never write the same
    particles, so they run in parallel without races, in a fixed summation order for any thread
    count.
    """
    literally(pp_contact_on)
    literally(pfp_on)
    literally(pp_radiation_on)
    colour_start = grid.colour_start
    for colour in range(colour_start.size - 1):
        first = colour_start[colour]
        for t in nb.prange(colour_start[colour + 1] - first):
            _slab_rates(grid.colour_slabs[first + t], grid, coords, T, rates, p, k_solid, pfp, rdf,
                        (pp_contact_on, pfp_on, pp_radiation_on))  # fmt: skip


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _slab_rates(slab, grid, coords, T, rates, p, k_solid, pfp, rdf, flags):
    """Pairs owned by the cells of one slab, in the traversal's fixed order (see :func:`pair_rates`)."""
    _visit_slab(slab, grid, coords, p.cutoff2, (PairVisit(T, rates, p, PairTables(k_solid, pfp, rdf)), flags))


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _pair_visit(first, last, n_run, run_i, run_f, hit_j, hit_r2, coords, cell_start, lo, size, cut2, state):
    """Heat rates of the pairs of a row's particles, added to both sides (the visitor of :func:`_slab_rates`)."""
    visit, (pp_contact_on, pfp_on, pp_radiation_on) = state
    T, p, (k_solid, pfp, rdf) = visit.T, visit.p, visit.tables
    q, g_sum, clamped = visit.rates.q, visit.rates.g, visit.rates.clamped_pairs
    radius, softening = p.radius, p.softening
    rdf_values, rdf_scale = rdf.values, 1.0 / (radius * radius * rdf.dx)  # r2 (m2) to RDF grid steps
    for i in range(first, last):
        n_hit = candidates(i, coords, cell_start, lo, size, run_i, run_f, n_run, cut2, hit_j, hit_r2)
        Ti = T[i]
        q_i = 0.0
        g_i = 0.0
        n_clamped = 0
        for k in range(np.uint64(n_hit)):
            j = hit_j[k]
            r2 = hit_r2[k]
            Tj = T[j]
            # pair_conduction and pair_radiation written out: a call per pair, even numba-inlined, reference-counts the
            # tables' arrays at every pair and halves the kernel's speed (measured).
            G = 0.0
            if pp_contact_on:
                if r2 < 4.0 * radius * radius:  # touching: k_s at the mean temperature
                    G += pp_contact(r2, radius, table_1d(k_solid, 0.5 * (Ti + Tj)), softening)
            if pfp_on:
                if r2 < p.pfp_cutoff2:
                    d_real = pp_real_distance(math.sqrt(r2), radius, softening)
                    G += table_2d(pfp, d_real, 0.5 * (Ti + Tj))
                    n_clamped += d_real < pfp.x0
            if pp_radiation_on:
                if r2 < p.radiation_cutoff2:
                    D = table_1d_inside(rdf_values, r2 * rdf_scale)
                    G += radiative_conductance(p.radiation_coefficient * D, Ti, Tj)
            flux = G * (Tj - Ti)
            q_i += flux
            g_i += G
            q[j] -= flux
            g_sum[j] += G
        q[i] += q_i
        g_sum[i] += g_i
        clamped[i] += n_clamped  # i is the slab's own: no other thread writes it


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy", inline="always")
def pair_conduction(r2, T_mean, p, k_solid, pfp, pp_contact_on, pfp_on):
    """The enabled PP modes of one pair that depend on its mean temperature ``T_mean`` (K) only,
    at squared centre distance ``r2`` (m2): contact and gas gap (W/K); and 1 if the PFP look-up fell
    below the table's first distance (clamped there: deep overlaps without softening), else 0. Zero
    from :func:`conduction_reach2` on: a pair loop skips the call there, as each call
    reference-counts the tables' arrays (which costs more than the radiation of most pairs)."""
    radius = p.radius
    G = 0.0
    below = 0
    if pp_contact_on:
        if r2 < 4.0 * radius * radius:  # touching: k_s at the mean temperature
            G += pp_contact(r2, radius, table_1d(k_solid, T_mean), p.softening)
    if pfp_on:
        if r2 < p.pfp_cutoff2:
            d_real = pp_real_distance(math.sqrt(r2), radius, p.softening)
            G += table_2d(pfp, d_real, T_mean)
            below = d_real < pfp.x0
    return G, below


@nb.njit(cache=True, inline="always")
def conduction_reach2(p, pp_contact_on, pfp_on):
    """Squared centre distance (m2) from which :func:`pair_conduction` is zero."""
    return max(4.0 * p.radius * p.radius if pp_contact_on else 0.0, p.pfp_cutoff2 if pfp_on else 0.0)


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy", inline="always")
def pair_radiation(r2, p, rdf_values, rdf_scale, pp_radiation_on):
    """The radiation coefficient ``eps_p A_p sigma D`` (W/K^4) of one pair at squared centre
    distance ``r2`` (m2), 0 beyond the cutoff or disabled: its conductance is
    ``radiative_conductance(coefficient, T_i, T_j)`` (Eq. 25). ``rdf_values`` and ``rdf_scale`` are
    the PP RDF table's values and the factor from r2 to its grid steps (hoisted out of the pair loops)."""
    if pp_radiation_on:
        if r2 < p.radiation_cutoff2:
            return p.radiation_coefficient * table_1d_inside(rdf_values, r2 * rdf_scale)
    return 0.0


_visit_slab = traversal(_pair_visit)


@nb.njit(cache=True)
def wall_rates(T, element, distance, element_T, rates, p, k_pw, pfw, rdf, pw_contact_on, pfw_on, pw_radiation_on):
    """Add particle-wall heat rates (W, into the particle) to ``rates.q`` and conductances to ``rates.g``.

    ``element[s, i]``/``distance[s, i]`` are particle i's contact with wall surface s (the frame's
    :class:`dpht.thermal.integrate.Frame` arrays): the element at the surface's nearest point and
    the centre-to-wall distance (m) (-1: no contact, beyond the cutoff or adiabatic there; see
    :mod:`dpht.thermal.model`); ``element_T`` the element temperatures (K). ``rates`` is a
    :class:`dpht.thermal.integrate.Rates`, ``p`` a :class:`WallModes`, the tables those of
    :class:`WallTables`. ``rates.element_heat[e, column]`` gains the heat rate (W) through element e
    for each mode's column of PW_MODES; ``rates.clamped_walls[0]`` counts the PFW look-ups below the
    table's first distance.
    Serial on purpose: per-element sums would race in parallel, and the loop is O(N) and cheap.
    """
    literally(pw_contact_on)
    literally(pfw_on)
    literally(pw_radiation_on)
    q, g_sum, element_heat, clamped = rates.q, rates.g, rates.element_heat, rates.clamped_walls
    for i in range(element.shape[1]):
        Ti = T[i]
        for z in range(element.shape[0]):
            e = element[z, i]
            if e < 0:
                continue
            Tw = element_T[e]
            G_contact, G_gas, G_rad, below = wall_conductances(distance[z, i], Ti, Tw, p, k_pw, pfw, rdf, pw_contact_on, pfw_on, pw_radiation_on)
            clamped[0] += below
            G = G_contact + G_gas + G_rad
            q[i] += G * (Tw - Ti)
            g_sum[i] += G
            element_heat[e, _CONTACT] += G_contact * (Tw - Ti)
            element_heat[e, _PFW] += G_gas * (Tw - Ti)
            element_heat[e, _RADIATION] += G_rad * (Tw - Ti)


@nb.njit(cache=True, inline="always")
def wall_conductances(d, Ti, Tw, p, k_pw, pfw, rdf, pw_contact_on, pfw_on, pw_radiation_on):
    """Conductances (W/K) of one particle-wall contact at centre-wall distance ``d`` (m), particle
    and wall temperatures ``Ti``, ``Tw`` (K): ``(contact, gas gap, radiation)``, 0 where disabled,
    and 1 if the PFW look-up fell below the table's first distance (clamped there), else 0."""
    radius, softening = p.radius, p.softening
    below = 0
    G_contact = 0.0
    G_gas = 0.0
    G_rad = 0.0
    if pw_contact_on:
        if d < radius:
            G_contact = pw_contact(d, radius, table_1d(k_pw, 0.5 * (Ti + Tw)), softening)
    if pfw_on:
        if d < p.pfw_cutoff:
            d_real = pw_real_distance(d, radius, softening)
            G_gas = table_2d(pfw, d_real, 0.5 * (Ti + Tw))
            below = d_real < pfw.x0
    if pw_radiation_on:
        if d < p.radiation_cutoff:
            D = table_1d(rdf, d * d / (radius * radius))
            G_rad = radiative_conductance(p.radiation_coefficient * D, Ti, Tw)
    return G_contact, G_gas, G_rad, below


class Specialised:
    """A kernel compiled for fixed mode flags, called without numba re-dispatching each time.

    Resolving literal arguments costs ~20 ms per call through the dispatcher; after the first
    call (which compiles, or loads from the cache) the compiled entry point is called directly.
    """

    def __init__(self, kernel, flags):
        self.kernel, self.flags, self.entry = kernel, tuple(flags), None

    def __call__(self, *args):
        if self.entry is None:
            self.kernel(*args, *self.flags)
            wanted = tuple(types.literal(f) for f in self.flags)
            self.entry = next(
                result.entry_point
                for signature, result in self.kernel.overloads.items()
                if tuple(signature[-len(wanted) :]) == wanted
            )
            return
        self.entry(*args, *self.flags)


@functools.cache
def pair_kernel(flags: tuple) -> Specialised:
    """:func:`pair_rates` for flags in the order of PP_MODES."""
    return Specialised(pair_rates, flags)


@functools.cache
def wall_kernel(flags: tuple) -> Specialised:
    """:func:`wall_rates` for flags in the order of PW_MODES."""
    return Specialised(wall_rates, flags)
