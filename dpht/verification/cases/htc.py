"""Verification of the gas-gap heat transfer coefficients (dpht.closures.htc, DPHT paper Eqs. 8-13, 18-20).

The references are the test oracles too (tests/unit/test_htc.py): Eqs. 8 and 18 transcribed literally,
with the gas path lengthened by the temperature-jump distances of a rarefied gas (Kennard's jump
distance, transcribed here from its formula: :func:`jump_distance`), and integrated in r by
adaptive quadrature (scipy.integrate.quad), where dpht.closures.htc uses Gauss-Legendre in another
variable, so the two share no numerics; and the closed form of Eq. 8 for a rigid solid, with and
without the jump. Only the gas's tabulated data (conductivity, molecular constants) are shared.
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
PRESSURES = ("continuum", 101325.0, 1000.0, 10.0)  # Pa
ACCOMMODATION = {"particle": 0.9, "wall": 0.6}  # unequal, so that a swapped coefficient shows


def jump_distance(temperature, pressure, accommodation, gas_name="air"):
    """Kennard's temperature-jump distance (m) at a surface of thermal accommodation coefficient
    ``accommodation``: (2 - a)/a 2 gamma/(gamma + 1) Lambda/Pr, with the hard-sphere mean free path
    Lambda = k_B T/(sqrt(2) pi sigma^2 p); 0 for ``pressure`` "continuum" (T in K, p in Pa)."""
    if pressure == "continuum":
        return 0.0
    m = gas.MOLECULAR[gas_name]
    mean_free_path = 1.380649e-23 * temperature / (np.sqrt(2.0) * np.pi * m.collision_diameter**2 * pressure)
    gamma = m.heat_capacity_ratio
    return (2 - accommodation) / accommodation * 2 * gamma / (gamma + 1) * mean_free_path / m.prandtl


def quadrature(distance, temperature, k_solid, solid_fraction, wall, radius=RADIUS, pressure="continuum",
               accommodation=ACCOMMODATION):
    """Eq. 8 (PFP, ``distance`` centre-centre) or Eq. 18 (PFW, ``wall``: centre-wall), W/K, in air
    at ``pressure`` (Pa, or "continuum": the paper's equations), transcribed literally and
    integrated in r by quad on sub-intervals crowding geometrically towards the lower limit, where
    the integrand peaks. Each particle surface adds its jump distance to the gas path, the wall its
    own (``accommodation``: {"particle": a_p, "wall": a_w}). Lengths in m, k_solid in W/(m K)."""
    R = radius
    k_f = gas.conductivity("air", temperature)
    g_p = jump_distance(temperature, pressure, accommodation["particle"])
    g_w = jump_distance(temperature, pressure, accommodation["wall"])
    R_ij = 0.560 * R * solid_fraction ** (-1 / 3)  # Eq. 13
    h = distance - R if wall else (distance - 2 * R) / 2  # Eq. 11
    r_sf = R_ij * R / np.sqrt(R_ij**2 + (R + h) ** 2)  # Eq. 12
    r_lo = np.sqrt(R**2 - (R + h) ** 2) if h < 0 else 0.0  # contact radius with overlap

    def integrand(r):
        l_s = np.sqrt(R**2 - r**2) - r * (R + h) / R_ij  # Eqs. 9, 19
        if wall:
            l_f = (R + h) - np.sqrt(R**2 - r**2) + g_p + g_w  # Eq. 20, a jump at the particle and the wall
            return 2 * np.pi * r / (l_s / k_solid + l_f / k_f)  # Eq. 18
        l_f = 2 * ((R + h) - np.sqrt(R**2 - r**2)) + 2 * g_p  # Eq. 10, a jump at each particle
        return 2 * np.pi * r / (l_s / k_solid + l_f / k_f + l_s / k_solid)  # Eq. 8

    edges = [r_lo] + [r_lo + (r_sf - r_lo) * 10.0**-k for k in range(10, 0, -1)] + [r_sf]
    return sum(quad(integrand, a, b, epsabs=0, epsrel=1e-10, limit=200)[0] for a, b in zip(edges[:-1], edges[1:]))


def _max_quadrature_error(kind: str) -> float:
    distances = PFP_DISTANCES if kind == "pfp" else PFW_DISTANCES
    function = htc.pfp if kind == "pfp" else htc.pfw
    error = 0.0
    for x, t, k_s, phi, p in itertools.product(distances, TEMPERATURES, K_SOLIDS, SOLID_FRACTIONS, PRESSURES):
        ref = quadrature(x * RADIUS, t, k_s, phi, wall=kind == "pfw", pressure=p)
        value = function(x * RADIUS, t, radius=RADIUS, k_solid=k_s, solid_fraction=phi, pressure=p,
                         accommodation=ACCOMMODATION)  # fmt: skip
        error = max(error, abs(value - ref) / ref)
    return error


@case("htc_pfp_quadrature", "PFP HTC (Eq. 8) vs adaptive quadrature, 1.6-3.5 R, 250-1500 K, k_s 0.2-30, continuum-10 Pa")
def pfp_quadrature():
    return _max_quadrature_error("pfp"), 1e-10


@case("htc_pfw_quadrature", "PFW HTC (Eq. 18) vs adaptive quadrature, 0.8-2 R, 250-1500 K, k_s 0.2-30, continuum-10 Pa")
def pfw_quadrature():
    return _max_quadrature_error("pfw"), 1e-10


def rigid_pfp(h, temperature, solid_fraction, radius=RADIUS, jump=0.0):
    """Eq. 8 with k_s -> infinity and gap h (m), in air, W/K: the integral of k_f 2 pi r / l_f,
    l_f = 2 (c - s + g), s = sqrt(R^2 - r^2), c = R + h, g the jump distance at each particle
    (``jump``, m; h > 0 without one, h >= 0 with). With r dr = -s ds, c' = c + g and
    s/(c' - s) = -1 + c'/(c' - s): pi k_f [c' ln((c' - s_f)/(h + g)) - (R - s_f)], where
    s_f = R c / sqrt(R_ij^2 + c^2) (Eq. 12)."""
    k_f = gas.conductivity("air", temperature)
    c = radius + h
    s_f = radius * c / np.sqrt((0.560 * radius * solid_fraction ** (-1 / 3)) ** 2 + c**2)  # Eq. 13
    return np.pi * k_f * ((c + jump) * np.log((c + jump - s_f) / (h + jump)) - (radius - s_f))


@case("htc_pfp_rigid_limit", "PFP HTC at k_s = 1e10 vs the closed-form gas-only integral, h 1e-3-1 R")
def pfp_rigid_limit():
    h = RADIUS * np.logspace(-3, 0, 13)
    t = np.array([250.0, 700.0, 1500.0])[:, None]
    error = 0.0
    for phi in SOLID_FRACTIONS:
        value = htc.pfp(2 * RADIUS + 2 * h, t, radius=RADIUS, k_solid=1e10, solid_fraction=phi, pressure="continuum")
        error = max(error, np.max(np.abs(value / rigid_pfp(h, t, phi) - 1.0)))
    return error, 1e-6


@case("htc_pfp_rigid_jump", "PFP HTC at k_s = 1e10 in air at 1 atm-10 Pa vs the closed form with the jump, h 0-1 R")
def pfp_rigid_jump():
    h = RADIUS * np.concatenate([[0.0], np.logspace(-3, 0, 13)])
    t = np.array([250.0, 700.0, 1500.0])[:, None]
    error = 0.0
    for phi, p in itertools.product(SOLID_FRACTIONS, PRESSURES[1:]):
        value = htc.pfp(2 * RADIUS + 2 * h, t, radius=RADIUS, k_solid=1e10, solid_fraction=phi, pressure=p,
                        accommodation=ACCOMMODATION)  # fmt: skip
        exact = rigid_pfp(h, t, phi, jump=jump_distance(t, p, ACCOMMODATION["particle"]))
        error = max(error, np.max(np.abs(value / exact - 1.0)))
    return error, 1e-6


def bilinear_midpoint_error(table: htc.HTCTable):
    """Relative error of the table's bilinear interpolation at its cell midpoints (the worst place),
    against the integral (Eq. 8 or 18) itself; returns the midpoint distances (m, column) and the errors."""
    d = 0.5 * (table.distance[1:] + table.distance[:-1])[:, None]
    t = 0.5 * (table.temperature[1:] + table.temperature[:-1])[None, :]
    return d, np.abs(htc.interpolate(table, d, t) / table.exact(d, t) - 1.0)


@case("htc_table_bilinear", "bilinear error of the default PFP table (200x64, 1.99-3R, 250-1400 K)")
def table_bilinear():
    table = htc.build_table("pfp", radius=RADIUS, k_solid=2.0, solid_fraction=0.6,
                            temperature_range=(250.0, 1400.0))
    return bilinear_midpoint_error(table)[1].max(), 3e-3
