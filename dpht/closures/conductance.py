"""The conductance of each heat-transfer mode: one small pure numba function per mode and style.

The registry :mod:`dpht.thermal.modes` names, for each mode and style, a :class:`Law` of this
module; the kernels (:mod:`dpht.thermal.kernels`) compose the enabled modes' laws into the one pair
conductance and its wall counterpart. A law's ``conductance`` is a function of the geometry ``x``
(squared centre distance r2 in m2 between two particles, centre-wall distance d in m for a wall
contact), the mean temperature ``T_mean`` (K) of the two ends, the side's shared parameters
(:class:`Side`), the mode's own (:class:`ModeParams`) and its table; it returns its value and 1
where a look-up fell below its table's first distance (clamped there), else 0. The kernels call
it only inside the mode's cutoff (``x < own.cutoff``).

A law's ``temperature`` says how its conductance depends on the two temperatures: ``MEAN``, a
conductance (W/K) of the mean temperature; ``RADIATIVE``, a coefficient c (W/K^4) of the geometry
whose conductance is the exact secant ``c (T_i^2 + T_j^2)(T_i + T_j)`` of c (T_j^4 - T_i^4)
(:func:`dpht.closures.contact.radiative_conductance`, Eqs. 25-26). The implicit integrator's
Jacobian takes the first by a forward difference in the mean temperature, the second exactly.

A law's ``setup`` gives its coefficient and table from a :class:`Setting` (Python, when the model
is built; only for an enabled mode). Equations are those of the DPHT paper.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numba as nb

from dpht.closures.contact import pp_contact, pp_real_distance, pw_conductivity, pw_contact, pw_real_distance
from dpht.util.interp import Table1D, Table2D, table_1d, table_1d_inside, table_2d

MEAN = "mean"
RADIATIVE = "radiative"

# The options of every function the kernels compose: inlined (numba IR) into the loop that calls
# them, so they take its options (fast-math, error model, reference counting) and cost no call.
PIECE = {"cache": True, "inline": "always"}


class Side(NamedTuple):
    """Parameters shared by the modes of one side (particle-particle or particle-wall)."""

    radius: float  # m
    softening: float  # c_PP (Eq. 3) or c_PW (Eq. 7)
    reach: float  # the largest enabled cutoff: m2 (squared centre distance) between particles, m to a wall


class ModeParams(NamedTuple):
    """One mode's own scalars."""

    cutoff: float  # m2 (squared centre distance) between particles, m (centre-wall) to a wall
    coefficient: float  # the law's own constant (radiation: eps_p A_p sigma, W/K^4), 0 if none


class Setting(NamedTuple):
    """What a law's setup reads (built by :func:`dpht.thermal.model.build`)."""

    conductivity: Table1D  # k_p, W/(m K), over temperature (K)
    wall_conductivity: float  # k_w, W/(m K)
    radiation_coefficient: float  # eps_p A_p sigma, W/K^4
    htc: Callable  # mode -> its HTC table (Table2D, W/K over real distance (m) and temperature (K))
    rdf: Callable  # mode -> its RDF over squared distance in radii^2 (Table1D)


class Law(NamedTuple):
    temperature: str  # MEAN or RADIATIVE
    conductance: object  # numba: (x, T_mean, side, own, table) -> (value, clamped)
    setup: Callable  # (mode, setting) -> (coefficient, table)
    table: type  # Table1D or Table2D


def _contact(conductance, corrected: bool):
    """Contact conduction: ``conductance`` (:func:`dpht.closures.contact.pp_contact`, 2 k_s a, Eqs.
    2 and 4, or ``pw_contact``, Eqs. 5-6) with k at the mean temperature and the contact radius
    corrected for the DEM's softening (c_PP, Eq. 3; c_PW, Eq. 7) or, not ``corrected``, the DEM's
    own (c = 1)."""

    @nb.njit(**PIECE)
    def contact(x, T_mean, side, own, k):
        return conductance(x, side.radius, table_1d(k, T_mean), side.softening if corrected else 1.0), 0

    return contact


pp_contact_corrected = _contact(pp_contact, True)  # Eqs. 2-4
pp_contact_dem = _contact(pp_contact, False)  # Eqs. 2, 4 with c_PP = 1
pw_contact_corrected = _contact(pw_contact, True)  # Eqs. 5-7, k = 4 / (1/k_p + 1/k_w) (Eq. 6)
pw_contact_dem = _contact(pw_contact, False)  # Eqs. 5-6 with c_PW = 1


@nb.njit(**PIECE)
def pfp(r2, T_mean, side, own, table):
    """The gas gap's conductance (Eqs. 8-16, tabulated) at the real centre distance (Eq. 17)."""
    d_real = pp_real_distance(math.sqrt(r2), side.radius, side.softening)
    return table_2d(table, d_real, T_mean), d_real < table.x0


@nb.njit(**PIECE)
def pfw(d, T_mean, side, own, table):
    """The gas gap's conductance to a wall (Eqs. 18-23, tabulated) at the real centre-wall distance (Eq. 24)."""
    d_real = pw_real_distance(d, side.radius, side.softening)
    return table_2d(table, d_real, T_mean), d_real < table.x0


@nb.njit(**PIECE)
def pp_radiation(r2, T_mean, side, own, rdf):
    """Eq. 25's coefficient eps_p A_p sigma D (W/K^4). The RDF D is tabulated over squared centre
    distance in radii^2 from 0, one step past the cutoff (:func:`dpht.thermal.model.build`), so it
    needs no square root and no clamping."""
    return own.coefficient * table_1d_inside(rdf.values, r2 * (1.0 / (side.radius * side.radius * rdf.dx))), 0


@nb.njit(**PIECE)
def pw_radiation(d, T_mean, side, own, rdf):
    """Eq. 26's coefficient eps_p A_p sigma D (W/K^4), D over squared centre-wall distance in radii^2."""
    return own.coefficient * table_1d(rdf, d * d / (side.radius * side.radius)), 0


def _particle(mode, setting: Setting):
    return 0.0, setting.conductivity


def _particle_wall(mode, setting: Setting):
    k = setting.conductivity
    return 0.0, Table1D(k.x0, k.dx, pw_conductivity(k.values, setting.wall_conductivity))  # Eq. 6


def _htc(mode, setting: Setting):
    return 0.0, setting.htc(mode)


def _rdf(mode, setting: Setting):
    return setting.radiation_coefficient, setting.rdf(mode)


PP_CONTACT = Law(MEAN, pp_contact_corrected, _particle, Table1D)
PP_CONTACT_DEM = Law(MEAN, pp_contact_dem, _particle, Table1D)
PW_CONTACT = Law(MEAN, pw_contact_corrected, _particle_wall, Table1D)
PW_CONTACT_DEM = Law(MEAN, pw_contact_dem, _particle_wall, Table1D)
PFP = Law(MEAN, pfp, _htc, Table2D)
PFW = Law(MEAN, pfw, _htc, Table2D)
PP_RADIATION = Law(RADIATIVE, pp_radiation, _rdf, Table1D)
PW_RADIATION = Law(RADIATIVE, pw_radiation, _rdf, Table1D)
