"""Compiled heat-rate kernels: particle-particle pairs and particle-wall contacts.

Each kernel is specialised on the enabled heat-transfer modes (numba literal booleans), so a
disabled mode is compiled out of the pair loop rather than tested per pair. Every mode is written
as a conductance G (W/K) between two temperatures, so one pair contributes ``G (T_j - T_i)`` to
particle i and exactly the negative to particle j, and the sum of conductances per particle bounds
the explicit time step (see :mod:`dpht.thermal.integrate`).

Mode names (config ``thermal.modes``) and equations of the DPHT paper:
``pp_contact`` Eqs. 2-4, ``pw_contact`` Eqs. 5-7, ``pfp`` Eqs. 8-17, ``pfw`` Eqs. 18-24,
``pp_radiation`` Eq. 25, ``pw_radiation`` Eq. 26.
"""

from __future__ import annotations

import functools
import math

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
from dpht.util.interp import table_1d, table_1d_inside, table_2d
from dpht.thermal.neighbors import buffers, candidates, prepare_row

PP_MODES = ("pp_contact", "pfp", "pp_radiation")
PW_MODES = ("pw_contact", "pfw", "pw_radiation")
MODES = PP_MODES + PW_MODES


@nb.njit(cache=True, parallel=True)
def pair_rates(
    cell_start, shape, lo, size, lengths, reach, colour_start, colour_slabs, coords, T, q, g_sum,
    radius, k_T0, k_dT, k_values, c_pp, pfp_cut2, pfp_d0, pfp_dd, pfp_T0, pfp_dT, pfp_values,
    rad_cut2, rad_coefficient, rdf_u0, rdf_du, rdf_values, cut2,
    pp_contact_on, pfp_on, pp_radiation_on,
):  # fmt: skip
    """Add particle-particle heat rates (W) to ``q`` and conductance sums (W/K) to ``g_sum``.

    Arrays are in cell-sorted order (see :mod:`dpht.thermal.neighbors`). ``k_values`` tabulates the particle
    conductivity (W/(m K)) from ``k_T0`` in steps ``k_dT`` (K). ``pfp_values[d, T]`` is the PFP
    HTC table over real centre distance (m) and mean pair temperature (K); ``rdf_values`` the PP RDF
    over squared centre distance in radii squared from 0 in steps ``rdf_du``, one step past the
    radiation cutoff (so radiation needs no square root and no clamping; ``rdf_u0`` must be 0);
    ``rad_coefficient = eps_p A_p sigma``. Cutoffs are squared (m2).
    The three flags are compile-time constants: each combination is its own compiled kernel.
    Slabs of one colour never write the same particles, so they run in parallel without races.
    """
    literally(pp_contact_on)
    literally(pfp_on)
    literally(pp_radiation_on)
    for colour in range(colour_start.size - 1):
        first = colour_start[colour]
        for t in nb.prange(colour_start[colour + 1] - first):
            _slab_rates(
                colour_slabs[first + t], cell_start, shape, lo, size, lengths, reach, coords, T, q, g_sum,
                radius, k_T0, k_dT, k_values, c_pp, pfp_cut2, pfp_d0, pfp_dd, pfp_T0, pfp_dT, pfp_values,
                rad_cut2, rad_coefficient, rdf_u0, rdf_du, rdf_values, cut2,
                pp_contact_on, pfp_on, pp_radiation_on,
            )  # fmt: skip


@nb.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _slab_rates(
    slab, cell_start, shape, lo, size, lengths, reach, coords, T, q, g_sum,
    radius, k_T0, k_dT, k_values, c_pp, pfp_cut2, pfp_d0, pfp_dd, pfp_T0, pfp_dT, pfp_values,
    rad_cut2, rad_coefficient, rdf_u0, rdf_du, rdf_values, cut2,
    pp_contact_on, pfp_on, pp_radiation_on,
):  # fmt: skip
    """Pairs owned by the cells of one slab, in a fixed order (see :func:`pair_rates`)."""
    run_i, run_f, hit_j, hit_r2 = buffers()
    rdf_scale = 1.0 / (radius * radius * rdf_du)  # r2 (m2) to RDF grid steps
    # Mid axis outermost: the slab's layers then share their neighbour rows while they are in cache.
    for b in range(shape[1]):
        for a in range(slab * reach, min((slab + 1) * reach, shape[0])):
            n_run, hit_j, hit_r2 = prepare_row(cell_start, shape, lo, size, lengths, reach, a, b, run_i, run_f, hit_j, hit_r2)
            row = (a * shape[1] + b) * shape[2]
            for i in range(cell_start[row], cell_start[row + shape[2]]):
                n_hit = candidates(i, coords, cell_start, lo, size, run_i, run_f, n_run, cut2, hit_j, hit_r2)
                Ti = T[i]
                q_i = 0.0
                g_i = 0.0
                for k in range(np.uint64(n_hit)):
                    j = hit_j[k]
                    r2 = hit_r2[k]
                    Tj = T[j]
                    G = 0.0
                    if pp_contact_on:
                        if r2 < 4.0 * radius * radius:  # touching: k_s at the mean temperature
                            G += pp_contact(r2, radius, table_1d(k_T0, k_dT, k_values, 0.5 * (Ti + Tj)), c_pp)
                    if pfp_on:
                        if r2 < pfp_cut2:
                            d_real = pp_real_distance(math.sqrt(r2), radius, c_pp)
                            G += table_2d(pfp_d0, pfp_dd, pfp_T0, pfp_dT, pfp_values, d_real, 0.5 * (Ti + Tj))
                    if pp_radiation_on:
                        if r2 < rad_cut2:
                            D = table_1d_inside(rdf_values, r2 * rdf_scale)
                            G += radiative_conductance(rad_coefficient * D, Ti, Tj)
                    flux = G * (Tj - Ti)
                    q_i += flux
                    g_i += G
                    q[j] -= flux
                    g_sum[j] += G
                q[i] += q_i
                g_sum[i] += g_i


@nb.njit(cache=True)
def wall_rates(
    T, element, distance, element_T, q, g_sum, element_heat, weight,
    radius, k_T0, k_dT, k_pw_values, c_pw, pfw_cut, pfw_d0, pfw_dd, pfw_T0, pfw_dT, pfw_values,
    rad_cut, rad_coefficient, rdf_u0, rdf_du, rdf_values,
    pw_contact_on, pfw_on, pw_radiation_on,
):  # fmt: skip
    """Add particle-wall heat rates (W, into the particle) to ``q`` and conductances to ``g_sum``.

    ``element[z, i]``/``distance[z, i]`` are particle i's nearest element and centre-to-wall
    distance (m) in Dirichlet zone z (-1: none within the cutoff). ``k_pw_values`` tabulates the
    contact conductivity of Eq. 6 like ``k_values`` in :func:`pair_rates`. ``element_heat[e, mode]`` gains
    ``weight`` times the heat rate through element e for modes (pw_contact, pfw, pw_radiation).
    Serial on purpose: per-element sums would race in parallel, and the loop is O(N) and cheap.
    """
    literally(pw_contact_on)
    literally(pfw_on)
    literally(pw_radiation_on)
    for i in range(element.shape[1]):
        Ti = T[i]
        for z in range(element.shape[0]):
            e = element[z, i]
            if e < 0:
                continue
            d = distance[z, i]
            Tw = element_T[e]
            G_contact = 0.0
            G_gas = 0.0
            G_rad = 0.0
            if pw_contact_on:
                if d < radius:
                    G_contact = pw_contact(d, radius, table_1d(k_T0, k_dT, k_pw_values, 0.5 * (Ti + Tw)), c_pw)
            if pfw_on:
                if d < pfw_cut:
                    d_real = pw_real_distance(d, radius, c_pw)
                    G_gas = table_2d(pfw_d0, pfw_dd, pfw_T0, pfw_dT, pfw_values, d_real, 0.5 * (Ti + Tw))
            if pw_radiation_on:
                if d < rad_cut:
                    D = table_1d(rdf_u0, rdf_du, rdf_values, d * d / (radius * radius))
                    G_rad = radiative_conductance(rad_coefficient * D, Ti, Tw)
            G = G_contact + G_gas + G_rad
            q[i] += G * (Tw - Ti)
            g_sum[i] += G
            element_heat[e, 0] += weight * G_contact * (Tw - Ti)
            element_heat[e, 1] += weight * G_gas * (Tw - Ti)
            element_heat[e, 2] += weight * G_rad * (Tw - Ti)


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
    """:func:`pair_rates` for flags ``(pp_contact, pfp, pp_radiation)``."""
    return Specialised(pair_rates, flags)


@functools.cache
def wall_kernel(flags: tuple) -> Specialised:
    """:func:`wall_rates` for flags ``(pw_contact, pfw, pw_radiation)``."""
    return Specialised(wall_rates, flags)


def colour_arrays(slab_colours) -> tuple[np.ndarray, np.ndarray]:
    """Flatten a cell list's slab colours into CSR arrays for the kernel."""
    start = np.concatenate([[0], np.cumsum([len(c) for c in slab_colours])]).astype(np.int64)
    return start, np.concatenate(slab_colours).astype(np.int64)
