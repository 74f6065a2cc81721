"""Thermal conductivity k_f(T) of the interstitial gas [W/(m K)] versus temperature T [K], at 1 atm.

The gas fills the gaps between particles and between particles and the wall; its conductivity sets
the particle-fluid-particle and particle-fluid-wall heat transfer coefficients (DPHT paper,
Sections 3.4-3.5, "k_f" in Eqs. 8 and 18).

Tables (k in 1e-3 W/(m K)) and their sources:

- ``air``: Incropera, DeWitt, Bergman & Lavine, *Fundamentals of Heat and Mass Transfer*,
  Table A.4, 250-1500 K.
- ``nitrogen``: the same Table A.4, 100-1300 K.
- ``co2``: the same Table A.4, 280-800 K.
- ``helium``: NIST Standard Reference Database 134, "Index of Semiconductor Process Gases -
  Helium-4", 100-1000 K.

Cross-checks made when the tables were entered: the CRC Handbook of Chemistry and Physics table
"Thermal conductivity of gases" (100-600 K) agrees with all four within 3.2 %, and the reference
correlations in CoolProp 8.0 (Lemmon & Jacobsen 2004 for air and N2, Huber et al. 2016 for CO2)
within 2.8 % over each table's range, except Incropera's air above 1200 K, which rises faster
(+9 % at 1500 K); it is kept as published.

Interpolation is monotone piecewise cubic (PCHIP, Fritsch-Carlson): it passes through every node,
has a continuous first derivative (so the heat transfer coefficient tables built from it have no
kinks in T, which keeps their bilinear interpolation error small), and, unlike a cubic spline,
cannot overshoot between nodes or turn the 3-digit rounding of the tables into wiggles. Outside
the tabulated range ``conductivity`` raises: a silent extrapolation of a transport property is
the kind of error nobody notices.

Rarefied gas. Near a solid surface the gas temperature jumps by g dT/dn (Smoluchowski's temperature
jump), with the jump distance of Kennard (1938, *Kinetic Theory of Gases*, McGraw-Hill, the chapter
on the temperature jump; the form used for gap conductances by Yovanovich and by Bahrami, Yovanovich & Culham 2006,
Int. J. Heat Mass Transfer 49:3691, and, as a modified mean free path, in the Zehner-Bauer-Schluender
model, VDI Heat Atlas D6.3):

    g = (2 - a)/a * 2 gamma/(gamma + 1) * Lambda/Pr,      Lambda = k_B T / (sqrt(2) pi sigma^2 p)

with a the thermal accommodation coefficient of the surface, gamma = c_p/c_v, Pr the Prandtl number
and Lambda the hard-sphere mean free path at temperature T [K] and pressure p [Pa] (sigma the
collision diameter [m]). Molecular data of the named gases (:data:`MOLECULAR`), constants:

- ``collision_diameter``: the hard-sphere diameter that reproduces the gas's viscosity at 300 K,
  mu = (5/16) sqrt(pi m k_B T) / (pi sigma^2) (Chapman-Enskog, first approximation; Bird, Stewart &
  Lightfoot, *Transport Phenomena*, 2nd ed., Section 1.4, with Omega_mu = 1), mu and the molar mass from
  Incropera Table A.4 (air 184.6, N2 178.2, CO2 149, He 199 x 1e-7 Pa s). So Lambda is the
  mean free path of the viscosity: air at 296 K and 1 atm 67.4 nm, against 66.5 nm (Jennings 1988,
  J. Aerosol Sci. 19:159). The Lennard-Jones sigma of Bird, Stewart & Lightfoot's Table E.1 (air
  3.617, N2 3.667, CO2 3.996, He 2.576 Angstrom) would make helium's Lambda 30 % too short. With a
  constant sigma Lambda grows as T; the viscosity's mean free path grows as about T^1.2 (air at
  1000 K: 228 nm here, 286 nm from Incropera's viscosity, 26 % more; 33 % at 1400 K), so the jump
  is underestimated in hot scenes (at 1 atm by a fraction of a percent of the HTC).
- ``heat_capacity_ratio``: c_p/(c_p - R_u/M) with c_p at 300 K from Incropera Table A.4 (helium 5/3).
- ``prandtl``: Incropera Table A.4 at 300 K (air varies 0.68-0.73 over 250-1500 K).
- ``accommodation``: the typical thermal accommodation coefficient on engineering (metal or
  ceramic, not atomically clean) surfaces, from the correlation of Song & Yovanovich (1987,
  "Correlation of thermal accommodation coefficient for engineering surfaces", ASME HTD-69:107),
  a = exp(-0.57 (T_s - T_0)/T_0) M*/(6.8 + M*) + 2.4 mu/(1 + mu)^2 [1 - exp(-0.57 (T_s - T_0)/T_0)],
  T_0 = 273 K, M* = M (monatomic) or 1.4 M [g/mol], mu = M / M_solid, at T_s = 300 K on iron
  (M_solid = 55.85; on alumina the values differ by < 0.003). The correlation falls with the
  surface temperature (air on iron: 0.61 at 1000 K); ``thermal.accommodation`` overrides it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.interpolate import PchipInterpolator

from dpht.errors import DPHTError

# Temperature [K] -> k [1e-3 W/(m K)], sources in the module docstring.
_TABLES: dict[str, dict[float, float]] = {
    "air": {
        250: 22.3, 300: 26.3, 350: 30.0, 400: 33.8, 450: 37.3, 500: 40.7, 550: 43.9, 600: 46.9,
        650: 49.7, 700: 52.4, 750: 54.9, 800: 57.3, 850: 59.6, 900: 62.0, 950: 64.3, 1000: 66.7,
        1100: 71.5, 1200: 76.3, 1300: 82.0, 1400: 91.0, 1500: 100.0,
    },
    "nitrogen": {
        100: 9.58, 150: 13.9, 200: 18.3, 250: 22.2, 300: 25.9, 350: 29.3, 400: 32.7, 450: 35.8,
        500: 38.9, 550: 41.7, 600: 44.6, 700: 49.9, 800: 54.8, 900: 59.7, 1000: 64.7, 1100: 70.0,
        1200: 75.8, 1300: 81.0,
    },
    "co2": {
        280: 15.20, 300: 16.55, 350: 20.4, 400: 24.3, 450: 28.0, 500: 32.5, 550: 36.6, 600: 40.7,
        650: 44.5, 700: 48.1, 750: 51.7, 800: 55.1,
    },
    "helium": {
        100: 74.8, 120: 84.4, 140: 93.4, 160: 102.1, 180: 110.4, 200: 118.5, 225: 128.2,
        250: 137.7, 275: 146.9, 300: 155.9, 325: 164.6, 350: 173.2, 375: 181.6, 400: 189.9,
        450: 206.0, 500: 221.7, 600: 251.9, 700: 280.9, 800: 308.9, 900: 336.1, 1000: 362.6,
    },
}

GASES: tuple[str, ...] = tuple(_TABLES)

BOLTZMANN = 1.380649e-23  # J/K, exact (SI 2019)
ATMOSPHERE = 101325.0  # Pa, one standard atmosphere (the closures' pressure where none is given)


@dataclass(frozen=True)
class Molecular:
    """What the temperature jump of a gas needs (module docstring): collision diameter sigma [m],
    heat-capacity ratio gamma, Prandtl number, and a typical thermal accommodation coefficient (None
    for a user table that gives none)."""

    collision_diameter: float
    heat_capacity_ratio: float
    prandtl: float
    accommodation: float | None


# Sources and derivations in the module docstring.
MOLECULAR: dict[str, Molecular] = {
    "air": Molecular(3.67e-10, 1.40, 0.707, 0.84),
    "nitrogen": Molecular(3.71e-10, 1.40, 0.716, 0.83),
    "co2": Molecular(4.54e-10, 1.29, 0.766, 0.88),
    "helium": Molecular(2.16e-10, 5.0 / 3.0, 0.680, 0.36),
}
# The keys a user gas table gives for the temperature jump; "accommodation" is optional.
MOLECULAR_KEYS = ("collision_diameter", "heat_capacity_ratio", "prandtl")


def table(gas: str) -> tuple[np.ndarray, np.ndarray]:
    """The published table of ``gas``: (temperature [K], conductivity [W/(m K)]), copies."""
    if gas not in _TABLES:
        raise DPHTError(f"gas {gas!r} is unknown; expected one of {list(GASES)} or a table mapping")
    temperature, k = zip(*_TABLES[gas].items())
    return np.array(temperature, dtype=float), np.array(k, dtype=float) * 1e-3


def _user_table(gas: Mapping, table: str = "gas table") -> tuple[np.ndarray, np.ndarray]:
    """A user's conductivity table checked; ``table`` says which table in errors."""
    try:
        temperature = np.asarray(gas["temperature"], dtype=float)
        k = np.asarray(gas["conductivity"], dtype=float)
    except (KeyError, TypeError, ValueError) as err:
        raise DPHTError(
            f"{table} must be a mapping with numeric lists 'temperature' [K] and 'conductivity' "
            f"[W/(m K)] ({err})"
        ) from None
    if temperature.ndim != 1 or temperature.shape != k.shape or temperature.size < 2:
        raise DPHTError(
            f"{table}: 'temperature' and 'conductivity' must be 1-D lists of the same length >= 2, "
            f"got shapes {temperature.shape} and {k.shape}"
        )
    if not np.all(np.isfinite(temperature)) or np.any(np.diff(temperature) <= 0) or temperature[0] <= 0:
        raise DPHTError(f"{table}: 'temperature' must be positive, finite and strictly increasing [K]")
    if not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise DPHTError(f"{table}: 'conductivity' must be positive and finite [W/(m K)]")
    return temperature, k


@lru_cache(maxsize=None)
def _named_interpolant(gas: str) -> PchipInterpolator:
    return PchipInterpolator(*table(gas), extrapolate=False)


def _interpolant(gas: str | Mapping, table: str = "gas table") -> tuple[PchipInterpolator, str]:
    """The interpolant of ``gas`` and a name for error messages (``table`` names a user's table)."""
    if isinstance(gas, str):
        return _named_interpolant(gas), f"the conductivity table of gas {gas!r}"
    if isinstance(gas, Mapping):
        return PchipInterpolator(*_user_table(gas, table), extrapolate=False), f"the {table}"
    raise DPHTError(f"gas must be a name {list(GASES)} or a table mapping, got {type(gas).__name__}")


def valid_range(gas: str | Mapping) -> tuple[float, float]:
    """(Tmin, Tmax) [K] of the table of ``gas``."""
    interpolant, _ = _interpolant(gas)
    return float(interpolant.x[0]), float(interpolant.x[-1])


def conductivity(gas: str | Mapping, temperature, table: str = "gas table") -> np.ndarray | float:
    """Thermal conductivity [W/(m K)] of ``gas`` at ``temperature`` [K] (any array shape).

    ``gas`` is a name from :data:`GASES` or a mapping ``{"temperature": [...], "conductivity": [...]}``
    in K and W/(m K) (``table`` names it in errors). Raises :class:`DPHTError` when a temperature is
    outside the table.
    """
    interpolant, name = _interpolant(gas, table)
    t = np.asarray(temperature, dtype=float)
    t_min, t_max = interpolant.x[0], interpolant.x[-1]
    if not np.all((t >= t_min) & (t <= t_max)):
        bad = t[~((t >= t_min) & (t <= t_max))]
        raise DPHTError(
            f"temperature {bad.flat[0]:g} K is outside {name} "
            f"(valid {t_min:g}-{t_max:g} K)"
        )
    k = interpolant(t)
    return float(k) if k.ndim == 0 else k


def molecular(gas: str | Mapping, table: str = "gas table") -> Molecular:
    """The molecular data of ``gas`` (a name or a user table with the keys :data:`MOLECULAR_KEYS`
    and optionally ``accommodation``); raises naming the missing or bad keys."""
    if isinstance(gas, str):
        if gas not in MOLECULAR:
            raise DPHTError(f"gas {gas!r} is unknown; expected one of {list(GASES)} or a table mapping")
        return MOLECULAR[gas]
    if not isinstance(gas, Mapping):
        raise DPHTError(f"gas must be a name {list(GASES)} or a table mapping, got {type(gas).__name__}")
    missing = [key for key in MOLECULAR_KEYS if key not in gas]
    if missing:
        raise DPHTError(
            f"the {table} has no {', '.join(map(repr, missing))}: the temperature jump at a finite gas pressure "
            f"needs {', '.join(map(repr, MOLECULAR_KEYS))} (collision diameter m, c_p/c_v, Prandtl number)"
        )
    values = {}
    for key, low, high in (("collision_diameter", 0.0, 1e-8), ("heat_capacity_ratio", 1.0, 5.0 / 3.0 + 1e-9),
                           ("prandtl", 0.0, 10.0), ("accommodation", 0.0, 1.0)):  # fmt: skip
        if key not in gas:
            continue
        try:
            values[key] = float(gas[key])
        except (TypeError, ValueError):
            raise DPHTError(f"the {table}: {key!r} must be a number, got {gas[key]!r}") from None
        if not low < values[key] <= high:
            raise DPHTError(f"the {table}: {key!r} = {values[key]:g} must lie in ({low:g}, {high:.4g}]")
    return Molecular(values["collision_diameter"], values["heat_capacity_ratio"], values["prandtl"],
                     values.get("accommodation"))  # fmt: skip


def mean_free_path(gas: str | Mapping, temperature, pressure: float):
    """Hard-sphere mean free path Lambda = k_B T / (sqrt(2) pi sigma^2 p) [m] of ``gas`` at
    ``temperature`` [K] and ``pressure`` [Pa] > 0 (module docstring); infinite where it overflows
    (a pressure below ~1e-300 Pa: a vacuum)."""
    sigma = molecular(gas).collision_diameter
    with np.errstate(divide="ignore", over="ignore"):
        return BOLTZMANN * np.asarray(temperature, dtype=float) / (np.sqrt(2.0) * np.pi * sigma**2) / pressure


def jump_distance(gas: str | Mapping, temperature, pressure: float, accommodation: float):
    """Temperature-jump distance g = (2 - a)/a * 2 gamma/(gamma + 1) * Lambda/Pr [m] of ``gas`` at a
    surface of thermal accommodation coefficient ``accommodation`` (Kennard 1938; module docstring),
    at ``temperature`` [K] and ``pressure`` [Pa] > 0."""
    m = molecular(gas)
    gamma = m.heat_capacity_ratio
    factor = (2.0 - accommodation) / accommodation * 2.0 * gamma / (gamma + 1.0) / m.prandtl
    return factor * mean_free_path(gas, temperature, pressure)
