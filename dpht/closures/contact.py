"""Contact conduction and the softening corrections (DPHT paper, Sections 3.2-3.5).

DEM runs with a Young's modulus far below the real one, which inflates overlaps and contact areas.
The softening factors c_PP (Eq. 3) and c_PW (Eq. 7) scale the contact radius back, and Eqs. 17 and
24 give the real centre distances used for the gas-gap conduction. The per-pair functions are numba
``inline`` scalars composed into the thermal kernels; the factors are plain Python.
"""

from __future__ import annotations

import math

import numba as nb

STEFAN_BOLTZMANN = 5.670374419e-8  # W/(m2 K4)


def c_pp(youngs_dem: float, youngs_real: float) -> float:
    """Particle-particle softening factor, DPHT paper Eq. 3 (Zhou et al. 2010)."""
    return (youngs_dem / youngs_real) ** 0.2


def c_pw(nu_p: float, youngs_p_real: float, youngs_p_dem: float, nu_w: float, youngs_w_real: float, youngs_w_dem: float) -> float:
    """Particle-wall softening factor, DPHT paper Eq. 7 (the wall is 'particle j')."""
    real = (1 - nu_p**2) / youngs_p_real + (1 - nu_w**2) / youngs_w_real
    dem = (1 - nu_p**2) / youngs_p_dem + (1 - nu_w**2) / youngs_w_dem
    return (real / dem) ** 0.2


def pw_conductivity(k_particle, k_wall):
    """Effective particle-wall contact conductivity 4 / (1/k_p + 1/k_w), DPHT paper Eq. 6."""
    return 4.0 / (1.0 / k_particle + 1.0 / k_wall)


@nb.njit(cache=True)
def pp_contact(r2, radius, k_solid, softening):
    """Particle-particle contact conductance (W/K), Eqs. 2 and 4, from the squared centre
    distance ``r2`` (m2) and the particle conductivity (W/(m K)); zero when not overlapping."""
    overlap = radius * radius - 0.25 * r2
    if overlap <= 0.0:
        return 0.0
    return 2.0 * softening * k_solid * math.sqrt(overlap)


@nb.njit(cache=True)
def pw_contact(d, radius, k_pw, softening):
    """Particle-wall contact conductance (W/K), Eqs. 5-6 with ``k_pw`` from :func:`pw_conductivity`."""
    overlap = radius * radius - d * d
    if overlap <= 0.0:
        return 0.0
    return k_pw * softening * math.sqrt(overlap)


@nb.njit(cache=True)
def pp_real_distance(d, radius, softening):
    """Centre distance without DEM softening, Eq. 17; unchanged for particles not in contact."""
    overlap = radius * radius - 0.25 * d * d
    if overlap <= 0.0:
        return d
    return 2.0 * math.sqrt(radius * radius - softening * softening * overlap)


@nb.njit(cache=True)
def pw_real_distance(d, radius, softening):
    """Centre-to-wall distance without DEM softening, Eq. 24; unchanged without contact."""
    overlap = radius * radius - d * d
    if overlap <= 0.0:
        return d
    return math.sqrt(radius * radius - softening * softening * overlap)


@nb.njit(cache=True)
def radiative_conductance(coefficient, T_i, T_j):
    """``coefficient * (T_j^4 - T_i^4) / (T_j - T_i)``: Eqs. 25-26 written as a conductance.

    ``coefficient = eps_p A_p sigma D`` (W/K^4). The secant form keeps the explicit update a convex
    combination of temperatures (maximum principle) and is exact, not a linearisation.
    """
    return coefficient * (T_i * T_i + T_j * T_j) * (T_i + T_j)


@nb.njit(cache=True)
def radiative_slope(coefficient, T_i, T_j):
    """``d/dT_i`` of :func:`radiative_conductance` (W/K^2): ``coefficient (3 T_i^2 + 2 T_i T_j + T_j^2)``
    (Newton's Jacobian in the implicit integrator)."""
    return coefficient * (3.0 * T_i * T_i + 2.0 * T_i * T_j + T_j * T_j)
