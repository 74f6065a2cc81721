"""Verification of the gas-gap heat transfer coefficients (dpht.closures.htc, DPHT paper Eqs. 8-13, 18-20).

The references integrate Eqs. 8 and 18 adaptively (scipy.integrate.quad) in the variable
s = sqrt(R^2 - r^2), where r dr = -s ds, with breakpoints crowding towards the narrowest gap;
dpht.closures.htc uses Gauss-Legendre in another variable, so the two share no numerics.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.integrate import quad

from dpht.closures import gas, htc
from dpht.verification.harness import case

RADIUS = 5e-4  # m, the paper's Figure 4 particles
K_SOLIDS = (0.2, 30.0)  # W/(m K)
SOLID_FRACTIONS = (0.3, 0.64)
TEMPERATURES = (250.0, 1500.0)  # K, the whole air table
PFP_DISTANCES = (1.6, 1.99, 2.0, 2.001, 2.05, 2.5, 3.5)  # centre-centre / R
PFW_DISTANCES = (0.8, 0.995, 1.0, 1.0005, 1.025, 1.25, 2.0)  # centre-wall / R


def _reference(c, temperature, k_solid, solid_fraction, solid_layers):
    """Eq. 8 (``solid_layers`` 2, c = d_ij/2) or Eq. 18 (1, c = d_iw) by adaptive quadrature in s."""
    R = RADIUS
    k_f = gas.conductivity("air", temperature)
    r_ij = htc.cone_base_radius(R, solid_fraction)
    s_sf = R * c / np.hypot(r_ij, c)  # s at r_sf, Eq. 12
    s_lo = min(c, R)  # s at the lower limit: R without contact, c = sqrt(R^2 - r_c^2) with it

    def integrand(s):
        l_solid = s - np.sqrt(R * R - s * s) * c / r_ij  # Eqs. 9, 19
        l_fluid = solid_layers * (c - s)  # Eq. 10 (PFP) or Eq. 20 (PFW)
        return 2.0 * np.pi * s / (solid_layers * l_solid / k_solid + l_fluid / k_f)

    edges = [s_sf] + [s_lo - (s_lo - s_sf) * 10.0**-k for k in range(1, 11)] + [s_lo]
    return sum(quad(integrand, a, b, epsabs=0.0, epsrel=1e-10, limit=200)[0]
               for a, b in zip(edges[:-1], edges[1:]))


def _max_quadrature_error(kind: str) -> float:
    distances = PFP_DISTANCES if kind == "pfp" else PFW_DISTANCES
    function = htc.pfp if kind == "pfp" else htc.pfw
    error = 0.0
    for x, t, k_s, phi in itertools.product(distances, TEMPERATURES, K_SOLIDS, SOLID_FRACTIONS):
        d = x * RADIUS
        c, layers = (d / 2, 2) if kind == "pfp" else (d, 1)
        ref = _reference(c, t, k_s, phi, layers)
        value = function(d, t, radius=RADIUS, k_solid=k_s, solid_fraction=phi)
        error = max(error, abs(value - ref) / ref)
    return error


@case("htc_pfp_quadrature", "PFP HTC (Eq. 8) vs adaptive quadrature, 1.6-3.5 R, 250-1500 K, k_s 0.2-30")
def pfp_quadrature():
    return _max_quadrature_error("pfp"), 1e-6


@case("htc_pfw_quadrature", "PFW HTC (Eq. 18) vs adaptive quadrature, 0.8-2 R, 250-1500 K, k_s 0.2-30")
def pfw_quadrature():
    return _max_quadrature_error("pfw"), 1e-6


def rigid_limit_pfp(distance, temperature, solid_fraction, radius=RADIUS):
    """Eq. 8 for k_s -> infinity without contact, in closed form [W/K]:
    pi k_f [c ln((c - s_f) / h) - (R - s_f)], c = d/2, h = c - R, s_f = R c / sqrt(R_ij^2 + c^2)."""
    k_f = gas.conductivity("air", temperature)
    c = distance / 2
    s_f = radius * c / np.hypot(htc.cone_base_radius(radius, solid_fraction), c)
    return np.pi * k_f * (c * np.log((c - s_f) / (c - radius)) - (radius - s_f))


@case("htc_pfp_rigid_limit", "PFP HTC at k_s = 1e10 vs the closed-form gas-only integral, h 1e-3-1 R")
def pfp_rigid_limit():
    d = RADIUS * (2.0 + 2.0 * np.logspace(-3, 0, 13))
    t = np.array([250.0, 700.0, 1500.0])[:, None]
    error = 0.0
    for phi in SOLID_FRACTIONS:
        value = htc.pfp(d, t, radius=RADIUS, k_solid=1e10, solid_fraction=phi)
        error = max(error, np.max(np.abs(value / rigid_limit_pfp(d, t, phi) - 1.0)))
    return error, 1e-6


@case("htc_table_bilinear", "bilinear error of the default PFP table (200x64, 1.99-3R, 250-1400 K)")
def table_bilinear():
    table = htc.build_table("pfp", radius=RADIUS, k_solid=2.0, solid_fraction=0.6,
                            temperature_range=(250.0, 1400.0))
    d = 0.5 * (table.distance[1:] + table.distance[:-1])
    t = 0.5 * (table.temperature[1:] + table.temperature[:-1])
    exact = htc.pfp(d[:, None], t[None, :], radius=RADIUS, k_solid=2.0, solid_fraction=0.6)
    return np.max(np.abs(htc.interpolate(table, d[:, None], t[None, :]) / exact - 1.0)), 3e-3
