"""The cooled sphere of ParScale (Section 3.1): resolved particles against the analytic series.

A sphere at T0 cooled by a fluid at T_env through a heat transfer coefficient (Robin condition),
ParScale's Table 1. The exact solution is the series of Crank, *The Mathematics of Diffusion*
(2nd ed., Eq. 6.40, surface evaporation from a sphere), with L = h a / lambda::

    (T - T_env) / (T0 - T_env) = (2 L a / r) sum_n exp(-beta_n^2 D t / a^2) sin(beta_n r / a)
                                               / ((beta_n^2 + L (L - 1)) sin beta_n),
    beta_n cot beta_n + L - 1 = 0,   D = lambda / (rho c_p).

:func:`simulate` runs the thermal stage's kernel (:mod:`dpht.thermal.intraparticle`) on one particle, with
the scene's default shell count (the schema's default of ``thermal.shells``), and compares the
profiles at r/a = 0, 0.25, 0.5, 0.75, 1 and t = 2, 5, 8, 10 s; the error is the mean over those 20
points of |T - T_exact| / T_exact (T in K, as ParScale's Fig. 2 plots T / T0). Points between nodes
(and the centre, which is no node) are read from the cubic through the four nearest nodes of the
profile extended evenly through the centre (fourth order, as the scheme). ParScale's own test
harness measures the root mean square error over the range of the reference values instead
(:func:`parscale_error`); both are reported.
"""

from __future__ import annotations

import csv
import functools
import math
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from dpht import config
from dpht.closures import heat_capacity
from dpht.thermal import intraparticle
from dpht.util.interp import Table1D

# ParScale Table 1 (its c_p unit "J m-3 K-1" is a typo for J/(kg K): with rho it gives the
# diffusivity that reproduces its Fig. 2).
TABLE_1 = {"specific_heat": 300.0, "density": 1000.0, "conductivity": 1.0, "htc": 100.0, "radius": 5e-3,
           "T0": 800.0, "T_env": 300.0}  # fmt: skip
TIMES = (2.0, 5.0, 8.0, 10.0)  # s
POINTS = (0.0, 0.25, 0.5, 0.75, 1.0)  # r / a
SHELLS = config.schema()["properties"]["thermal"]["properties"]["shells"]["default"]  # the scenes' default
STEP = 2e-5  # s; backward Euler is first order: at this step its error is below the spacing's
# The shell series runs each count at STEP and STEP / 2 and extrapolates in the step (2 T(dt/2) -
# T(dt), backward Euler's first-order error cancelled), so it measures the spacing alone.
CONVERGENCE_SHELLS = (3, 4, 6, 8, 12, 16)
CONVERGENCE_STEPS = (0.1, 0.05, 0.025, 0.0125, 0.00625)  # s


@functools.cache
def series_roots(L: float, terms: int = 200) -> np.ndarray:
    """The first ``terms`` positive roots of beta cos beta + (L - 1) sin beta = 0 (one per (n pi, (n+1) pi))."""
    f = lambda b: b * math.cos(b) + (L - 1.0) * math.sin(b)  # noqa: E731
    return np.array([brentq(f, max(n * math.pi, 1e-9), (n + 1) * math.pi, xtol=1e-15, rtol=1e-15) for n in range(terms)])


def exact(r_over_a, t: float, p: dict = TABLE_1) -> np.ndarray:
    """Crank's series (module docstring): T (K) at ``r_over_a`` and time ``t`` (s)."""
    a, L = p["radius"], p["htc"] * p["radius"] / p["conductivity"]
    D = p["conductivity"] / (p["density"] * p["specific_heat"])
    beta = series_roots(L)
    x = np.atleast_1d(np.asarray(r_over_a, dtype=float))[:, None]
    shape = np.where(x > 0, np.sin(beta * x) / np.where(x > 0, x, 1.0), beta)  # sin(beta x) / x -> beta at the centre
    terms = np.exp(-(beta**2) * D * t / a**2) / ((beta**2 + L * (L - 1.0)) * np.sin(beta))
    return p["T_env"] + (p["T0"] - p["T_env"]) * 2.0 * L * (shape * terms).sum(axis=1)


def simulate(shells: int, step: float, p: dict = TABLE_1, times=TIMES) -> list[np.ndarray]:
    """Node temperatures (K) of the resolved sphere at each of ``times``, ``shells`` nodes, steps of ``step`` s."""
    a = p["radius"]
    grid = intraparticle.grid(a, shells)
    mass = p["density"] * 4.0 / 3.0 * math.pi * a**3
    enthalpy = heat_capacity.build(lambda T: np.full(np.shape(T), p["specific_heat"]), p["T_env"], p["T0"])
    k_table = Table1D(0.0, 1e4, np.full(2, p["conductivity"]))
    H = np.full((1, shells), enthalpy.enthalpy(p["T0"])[()])
    rows, q, convected = np.zeros(1, np.int64), np.zeros(1), np.zeros(1)
    surface = intraparticle.Surface(p["htc"], p["T_env"])
    profiles, t = [], 0.0
    for t_next in times:
        steps = round((t_next - t) / step)
        intraparticle.advance(H, rows, q, (t_next - t) / steps, steps, mass, grid, surface, *enthalpy.arrays, k_table, 1,
                              convected)  # fmt: skip
        profiles.append(enthalpy.temperature(H[0]))
        t = t_next
    return profiles


def nodes(shells: int) -> np.ndarray:
    """r / a of the nodes (:func:`dpht.thermal.intraparticle.grid`)."""
    return np.arange(1, shells + 1) / shells


def at_points(T: np.ndarray, points=POINTS) -> np.ndarray:
    """The profile of node temperatures ``T`` at ``points`` (r / a): the cubic through the four
    nearest nodes of the profile extended evenly through the centre (T(-r) = T(r))."""
    x = nodes(T.size)
    xs, Ts = np.concatenate([-x[::-1], x]), np.concatenate([T[::-1], T])
    out = []
    for point in points:
        k = int(np.searchsorted(xs, point))
        lo = min(max(k - 2, 0), xs.size - 4)
        out.append(np.polyval(np.polyfit(xs[lo : lo + 4], Ts[lo : lo + 4], 3), point))
    return np.array(out)


def errors(shells: int, step: float, profiles: list | None = None) -> np.ndarray:
    """|T - T_exact| / T_exact at (TIMES x POINTS) of :func:`simulate` (or its ``profiles``)."""
    profiles = profiles or simulate(shells, step)
    return np.array([np.abs(at_points(T) - exact(POINTS, t)) / exact(POINTS, t) for t, T in zip(TIMES, profiles)])


def parscale_error(profiles: list) -> float:
    """ParScale's measure (its verification scripts): root mean square of T - T_exact over the
    points and times, divided by the range of T_exact over them."""
    reference = np.array([exact(POINTS, t) for t in TIMES])
    difference = np.array([at_points(T) for T in profiles]) - reference
    return float(math.sqrt(np.mean(difference**2)) / np.ptp(reference))


def convergence() -> list[dict]:
    """Mean and max relative error against the shell count (extrapolated in the step, see
    :data:`CONVERGENCE_SHELLS`) and the step (at :data:`SHELLS`), with the observed order between
    neighbours (against the spacing a / n, or the step)."""
    rows = []

    def in_space(n):
        coarse, fine = simulate(n, STEP), simulate(n, STEP / 2)
        return errors(n, STEP, [2.0 * b - a for a, b in zip(coarse, fine)])

    for parameter, values, run in (("shells", CONVERGENCE_SHELLS, in_space),
                                   ("step", CONVERGENCE_STEPS, lambda dt: errors(SHELLS, dt))):  # fmt: skip
        previous = None
        for value in values:
            e = run(value)
            mean = float(e.mean())
            order = ""
            if previous is not None:
                ratio = previous[0] / value if parameter == "shells" else value / previous[0]  # of the spacing a / n, or the step
                order = math.log(previous[1] / mean) / math.log(1.0 / ratio)
            rows.append({"parameter": parameter, "value": value, "mean_relative_error": mean,
                         "max_relative_error": float(e.max()), "observed_order": order})  # fmt: skip
            previous = (value, mean)
    return rows


def write(out, profiles=None) -> np.ndarray:
    """Into the folder ``out``: ``cooled_sphere.csv`` (t, r_over_a, T at the five radii and four
    times, :data:`SHELLS` shells, step :data:`STEP`), ``cooled_sphere_convergence.csv`` and the
    figures ``cooled_sphere.png`` and ``cooled_sphere_convergence.png``. Returns the errors of
    :func:`errors` at the default resolution."""
    from dpht.figures import intraparticle as figures

    out = Path(out)
    profiles = profiles or simulate(SHELLS, STEP)
    with open(out / "cooled_sphere.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "r_over_a", "T"])
        for t, T in zip(TIMES, profiles):
            for x, value in zip(POINTS, at_points(T)):
                w.writerow([f"{t:g}", f"{x:g}", repr(float(value))])
    rows = convergence()
    with open(out / "cooled_sphere_convergence.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    figures.cooled_sphere(out / "cooled_sphere.png", TIMES, nodes(SHELLS), profiles, lambda x, t: exact(x, t), TABLE_1["T0"])
    figures.convergence(out / "cooled_sphere_convergence.png", rows, SHELLS, STEP)
    return errors(SHELLS, STEP, profiles)
