"""Heat transfer coefficients [W/K] for conduction through the gas gap (DPHT paper, Sections 3.4-3.5).

The double-cone model of Cheng et al. (1999): between two particles, or a particle and the wall,
heat flows parallel to the line of centres through solid (length l_s) and gas (length l_f), in
series, inside a cone of base radius R_ij (Eq. 13) with its apex at the particle centre. The heat
transfer coefficient (HTC) is the integral of Eq. 8 (particle-fluid-particle, PFP) or Eq. 18
(particle-fluid-wall, PFW); the heat rate is HTC * (T_j - T_i).

Geometry, with c = R + h the distance from a particle centre to the mid-plane (PFP) or to the
wall (PFW):

- PFP: h = (d_ij - 2R) / 2 (Eq. 11), so c = d_ij / 2; l_f = 2 [c - sqrt(R^2 - r^2)] (Eq. 10) and
  l_si = l_sj (Eq. 9), both particles the same size.
- PFW: c = d_iw, h = d_iw - R; l_f = c - sqrt(R^2 - r^2) (Eq. 20, half the PFP value) and no wall
  resistance (Eq. 18).
- l_s = sqrt(R^2 - r^2) - r c / R_ij (Eqs. 9, 19); the upper limit r_sf = R_ij R / sqrt(R_ij^2 + c^2)
  (Eq. 12) is where the cone surface leaves the sphere (l_s = 0); the lower limit is 0 without
  contact and the contact radius sqrt(R^2 - c^2) with overlap.

So the PFP integrand is exactly half the PFW integrand at the same c: the mid-plane between two
equal spheres is isothermal, and PFP is two sphere-plane gaps in series, HTC_PFP(d) =
HTC_PFW(d / 2) / 2. Both are computed by one sphere-plane integral, :func:`_sphere_plane`.

The model is defined while the contact circle lies inside the cone, r_c < r_sf, i.e.
c^2 > R^2 - R_ij^2 (d_ij > 1.52 R for alpha_s = 0.64). Closer, the range of integration is empty
while the HTC tends to a finite value as that limit is approached, so the functions raise there.
In the continuum the HTC falls monotonically with distance from about 1.8 R outwards (checked
over 1.99-3.5 R); with deeper overlap it falls again, as the contact circle eats the cone. With
the temperature jump it falls from contact outwards (within the overlap it may rise slightly).

Rarefied gas (Smoluchowski temperature jump). At a finite gas pressure the gas temperature jumps
at each solid surface by g dT/dn, g the jump distance of that surface
(:func:`dpht.closures.gas.jump_distance`, Kennard 1938): in the gas column of length l_f the heat
flux is k_f dT / (l_f + the jump distances at its ends). Each half-gap of the sphere-plane integral
touches one particle surface and the plane: for PFP the plane is the isothermal mid-plane in the
gas, so l_f -> l_f + g_p per half (l_f + 2 g_p for the whole gap of Eq. 10); for PFW it is the
wall, l_f -> l_f + g_p + g_w (Eq. 20), each with its own accommodation coefficient. With
p -> infinity (``pressure="continuum"``, the DPHT paper's model) the jump vanishes; at p = 0 it is
infinite and the gap carries no heat (HTC exactly 0). Where the gap closes the gas resistance
keeps at least (jump distances)/k_f, where in the continuum it vanishes with h.

Quadrature. When the gap closes (h -> 0+, or just after contact) the gas resistance dominates
and the integrand peaks in a boundary layer of width w ~ sqrt(2 R D0 k_f) at the lower limit,
where D0 = l_s/k_s + (l_f + g)/k_f there (g the jump distances, 0 in the continuum): w ~ 0.045 R
for touching spheres with k_s/k_f = 1e3, and w -> 0 with the gap in the rigid continuum limit
k_s -> infinity. Near the lower limit l_f grows as (r^2 - r_lo^2)/(c + sqrt(R^2 - r_lo^2)), the
jump distances stay constant, and the resistance is
D ~ D0 (1 + (r^2 - r_lo^2) / w^2) = D0 cosh^2 t, w^2 = D0 k_f (c + sqrt(R^2 - r_lo^2)), with the
substitution r^2 = r_lo^2 + w^2 sinh^2 t, which makes 2 pi r dr / D ~ 2 pi w^2 tanh(t) dt / D0 smooth on the
whole interval. Gauss-Legendre on t then converges exponentially: 16 nodes agree with adaptive
quadrature to 1e-12 from contact outwards and to 6e-9 just after contact (1.9999 R, where
r = sqrt(r_lo^2 + w^2 sinh^2 t) has branch points close to the real axis); the 32 used agree to
5e-12 everywhere (measured over 1.99-3 R, 250-1500 K, k_s 0.2-30, alpha_s 0.3-0.64; errors also in
tests/unit/test_htc.py and ``python -m dpht verify htc_pfp_quadrature``). A jump distance only widens the
layer (w grows with D0), so t_max = arcsinh(sqrt(r_sf^2 - r_lo^2)/w) shrinks: the same nodes agree
to 5e-12 from the continuum to 10 Pa. Leaving the jump out of D0 (and so w) would converge to the
same integral, more slowly at low pressure (6 nodes: 7e-5 instead of 3e-6 at 1e4 Pa).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from dpht.closures import gas as gas_properties
from dpht.defaults import setting
from dpht.errors import DPHTError
from dpht.util.h5 import check_values, open_checked
from dpht.util.interp import Table2D, table_2d_many

FORMAT = "dpht-htc-2"  # 2: gas pressure and accommodation coefficients (temperature jump)
KINDS = ("pfp", "pfw")
CONE_COEFFICIENT = 0.560  # DPHT paper, Eq. 13 (Zhou et al. 2009)
N_NODES = 32  # Gauss-Legendre nodes in the substituted variable t

_T_NODES, _T_WEIGHTS = np.polynomial.legendre.leggauss(N_NODES)


def cone_base_radius(radius: float, solid_fraction: float) -> float:
    """R_ij = 0.560 R alpha_s^(-1/3) [m] (DPHT paper, Eq. 13)."""
    return CONE_COEFFICIENT * radius * solid_fraction ** (-1.0 / 3.0)


CONTINUUM = "continuum"  # the gas pressure of the DPHT paper's model: no temperature jump (p -> infinity)
SURFACES = ("particle", "wall")  # surfaces with an accommodation coefficient
TOUCHES = {"pfp": ("particle",), "pfw": ("particle", "wall")}  # the solid surfaces one half-gap touches


def gas_conducts(thermal: Mapping) -> bool:
    """Whether the gas-gap modes (PFP, PFW) can carry any heat in a scene's ``thermal`` config
    section: not in a vacuum (``gas_pressure`` 0; the schema's default where the section gives none)."""
    return check_pressure(setting(thermal, "thermal.gas_pressure")) > 0.0


def rarefied(pressure) -> bool:
    """Whether the temperature jump applies at ``pressure``: finite and > 0 (neither the continuum
    nor a vacuum), so that the molecular data and accommodation coefficients matter."""
    return 0.0 < check_pressure(pressure) < np.inf


def check_pressure(pressure) -> float:
    """Gas pressure [Pa] >= 0 as a float, infinity for ``"continuum"``; raises on anything else."""
    if isinstance(pressure, str):
        if pressure == CONTINUUM:
            return np.inf
    elif not isinstance(pressure, bool):
        try:
            value = float(pressure)
        except (TypeError, ValueError):
            value = np.nan
        if value >= 0.0:
            return value
    raise DPHTError(f"pressure must be a number of Pa >= 0 or {CONTINUUM!r}, got {pressure!r}")


def accommodation_of(accommodation, gas: str | Mapping = "air") -> dict:
    """Thermal accommodation coefficients ``{"particle": a_p, "wall": a_w}``, each in (0, 1]:
    ``accommodation`` is None (the gas's typical value, :data:`dpht.closures.gas.MOLECULAR`), one
    number for both surfaces, or a mapping with any of the two keys (the others typical)."""
    if accommodation is None:
        given = {}
    elif isinstance(accommodation, Mapping):
        given = dict(accommodation)
        unknown = sorted(set(given) - set(SURFACES))
        if unknown:
            raise DPHTError(f"accommodation: unknown surface(s) {unknown}; expected {list(SURFACES)}")
    else:
        given = dict.fromkeys(SURFACES, accommodation)
    result = {}
    for surface in SURFACES:
        if given.get(surface) is None:
            typical = gas_properties.molecular(gas).accommodation
            if typical is None:
                raise DPHTError(f"accommodation of the {surface} surface: not given, and the gas table has no "
                                "typical 'accommodation'; give one in (0, 1]")  # fmt: skip
            result[surface] = typical
            continue
        value = given[surface]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not 0 < value <= 1:
            raise DPHTError(f"accommodation of the {surface} surface must be a number in (0, 1], got {value!r}")
        result[surface] = float(value)
    return result


def jump_length(kind: str, temperature, *, gas: str | Mapping = "air", pressure=gas_properties.ATMOSPHERE,
                accommodation=None):
    """Sum of the temperature-jump distances [m] of the solid surfaces one half-gap of ``kind``
    touches (module docstring): g_p for PFP, g_p + g_w for PFW, at ``temperature`` [K]; 0 in the
    continuum, infinite at ``pressure`` 0. Arguments as for :func:`pfp`."""
    _check_kind(kind)
    p = check_pressure(pressure)
    if p == np.inf:
        return np.zeros(np.shape(temperature))[()]
    if p == 0.0:
        return np.full(np.shape(temperature), np.inf)[()]
    a = accommodation_of(accommodation, gas)
    return sum(gas_properties.jump_distance(gas, temperature, p, a[s]) for s in TOUCHES[kind])


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise DPHTError(f"kind must be one of {KINDS}, got {kind!r}")


def _check_parameters(radius, k_solid, solid_fraction) -> tuple[float, float, float]:
    checked = []
    for name, value, low, high, unit in (
        ("radius", radius, 0.0, np.inf, "m"),
        ("k_solid", k_solid, 0.0, np.inf, "W/(m K)"),
        ("solid_fraction", solid_fraction, 0.0, 0.75, "-"),
    ):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise DPHTError(f"{name} must be a number [{unit}], got {value!r}") from None
        if not (low < value < high):
            raise DPHTError(f"{name} must lie in ({low:g}, {high:g}) [{unit}], got {value:g}")
        checked.append(value)
    return tuple(checked)


def min_distance(kind: str, *, radius: float, solid_fraction: float) -> float:
    """Distance [m] (centre-centre for "pfp", centre-wall for "pfw") above which the model is
    defined: at and below it the contact circle reaches the cone surface (r_c >= r_sf)."""
    _check_kind(kind)
    r_ij = cone_base_radius(radius, solid_fraction)
    c_min = np.sqrt(max(radius**2 - r_ij**2, 0.0))
    return 2.0 * c_min if kind == "pfp" else c_min


def _check_distance(kind: str, distance, radius: float, solid_fraction: float) -> np.ndarray:
    d = np.asarray(distance, dtype=float)
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise DPHTError(f"distance must be positive and finite [m], got min {np.min(d):g}")
    d_min = min_distance(kind, radius=radius, solid_fraction=solid_fraction)
    if np.any(d <= d_min):
        raise DPHTError(
            f"distance {np.min(d):g} m is at or below {d_min:g} m, where the {kind.upper()} "
            f"model is undefined (contact circle reaches the cone surface, DPHT paper Eqs. 12-13)"
        )
    return d


def _sphere_plane(c, k_f, jump, radius: float, k_solid: float, r_ij: float) -> np.ndarray:
    """Integral of Eq. 18, int 2 pi r dr / (l_s/k_s + (l_f + jump)/k_f) [W/K], with l_f of Eq. 20.

    ``c`` is the centre-to-plane distance [m], ``k_f`` the gas conductivity [W/(m K)] and ``jump``
    the temperature-jump distances of the half-gap [m] (:func:`jump_length`; infinite: 0 W/K); they
    broadcast together. Quadrature: see the module docstring.
    """
    c, k_f, jump = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (c, k_f, jump)))
    conducts = np.isfinite(jump)
    jump = np.where(conducts, jump, 0.0)
    R = radius
    h_plus = np.maximum(c - R, 0.0)  # gas gap at r = r_lo: h without contact, 0 with overlap
    contact = c < R
    # Lower limit r_lo (0, or the contact radius) and sqrt(R^2 - r_lo^2).
    r_lo = np.where(contact, np.sqrt(np.maximum(R * R - c * c, 0.0)), 0.0)
    s_lo = np.where(contact, c, R)
    # r_sf^2 - r_lo^2 (Eq. 12), written without cancellation for the overlap case.
    span2 = np.where(
        contact,
        c * c * (c * c + r_ij * r_ij - R * R) / (r_ij * r_ij + c * c),
        (r_ij * R) ** 2 / (r_ij * r_ij + c * c),
    )
    # Resistance per unit area at r_lo and the boundary-layer width w (module docstring).
    d0 = (s_lo - r_lo * c / r_ij) / k_solid + (h_plus + jump) / k_f
    w2 = d0 * k_f * (c + s_lo)
    t_max = np.arcsinh(np.sqrt(span2 / w2))

    t = 0.5 * t_max[..., None] * (_T_NODES + 1.0)
    v = w2[..., None] * np.sinh(t) ** 2  # r^2 - r_lo^2
    r = np.sqrt(r_lo[..., None] ** 2 + v)
    s = np.sqrt(s_lo[..., None] ** 2 - v)  # sqrt(R^2 - r^2)
    l_solid = s - r * (c / r_ij)[..., None]  # Eq. 19
    # Eq. 20, l_f = c - s = (c^2 - R^2 + r^2) / (c + s), free of cancellation as the gap closes.
    l_fluid = (h_plus * (2.0 * R + h_plus))[..., None] + v
    l_fluid = l_fluid / (c[..., None] + s) + jump[..., None]
    integrand = 2.0 * np.pi * w2[..., None] * np.sinh(t) * np.cosh(t)
    integrand = integrand / (l_solid / k_solid + l_fluid / k_f[..., None])
    return np.where(conducts, 0.5 * t_max * (integrand @ _T_WEIGHTS), 0.0)


def _htc(kind, distance, temperature, radius, k_solid, solid_fraction, gas, pressure, accommodation) -> np.ndarray:
    radius, k_solid, solid_fraction = _check_parameters(radius, k_solid, solid_fraction)
    d = _check_distance(kind, distance, radius, solid_fraction)
    if check_pressure(pressure) == 0.0:  # a vacuum: no gas, no conductance (nor gas data needed)
        return np.zeros(np.broadcast_shapes(d.shape, np.shape(temperature)))[()]
    k_f = gas_properties.conductivity(gas, temperature)
    jump = jump_length(kind, temperature, gas=gas, pressure=pressure, accommodation=accommodation)
    r_ij = cone_base_radius(radius, solid_fraction)
    if kind == "pfp":  # c = R + h = d_ij / 2 (Eq. 11); Eq. 8 is half the Eq. 18 integrand
        return 0.5 * _sphere_plane(0.5 * d, k_f, jump, radius, k_solid, r_ij)
    return _sphere_plane(d, k_f, jump, radius, k_solid, r_ij)  # c = R + h = d_iw


def pfp(distance, temperature, *, radius: float, k_solid: float, solid_fraction: float,
        gas: str | Mapping = "air", pressure=gas_properties.ATMOSPHERE, accommodation=None):
    """Particle-fluid-particle HTC [W/K], the integral in DPHT paper Eq. 8 (Eqs. 9-13), with the
    temperature jump of a rarefied gas at each particle surface (module docstring).

    ``distance`` is the real centre-centre distance d_ij [m] (after the softening correction,
    Eq. 17) and ``temperature`` the mean of the two particles [K]; they broadcast. ``radius`` [m],
    ``k_solid`` [W/(m K)], ``solid_fraction`` alpha_s for Eq. 13, ``gas`` a name from
    :data:`dpht.closures.gas.GASES` or a conductivity table mapping (with the molecular data
    :data:`dpht.closures.gas.MOLECULAR_KEYS` at a finite pressure). ``pressure`` is the gas pressure
    [Pa] >= 0 (default 1 atm) or ``"continuum"`` (no temperature jump, the DPHT paper's model);
    ``accommodation`` the thermal accommodation coefficients (:func:`accommodation_of`: None for the
    gas's typical value, a number, or ``{"particle": a_p, "wall": a_w}``; PFP uses a_p).
    """
    return _htc("pfp", distance, temperature, radius, k_solid, solid_fraction, gas, pressure, accommodation)


def pfw(distance, temperature, *, radius: float, k_solid: float, solid_fraction: float,
        gas: str | Mapping = "air", pressure=gas_properties.ATMOSPHERE, accommodation=None):
    """Particle-fluid-wall HTC [W/K], the integral in DPHT paper Eq. 18 (Eqs. 11-13, 19-20), with
    the temperature jumps at the particle and the wall surface (module docstring).

    ``distance`` is the real centre-to-wall distance d_iw [m] (Eq. 24) and ``temperature`` the
    mean of the particle and the wall [K]; other arguments as for :func:`pfp`.
    """
    return _htc("pfw", distance, temperature, radius, k_solid, solid_fraction, gas, pressure, accommodation)


@dataclass(frozen=True, eq=False)
class HTCTable:
    """HTC [W/K] on a uniform grid of distance [m] x temperature [K], for the thermal kernel.

    ``gas`` is the gas name, or for a user conductivity table the mapping
    ``{"temperature": [...], "conductivity": [...], ...}``; ``pressure`` [Pa] and ``accommodation``
    as for :func:`pfp` (:func:`build_table` records the coefficients it used, None where the jump
    does not apply: in the continuum and in a vacuum).
    """

    kind: str
    distance: np.ndarray
    temperature: np.ndarray
    values: np.ndarray
    radius: float
    k_solid: float | Mapping
    solid_fraction: float
    gas: str | Mapping = field(default="air")
    pressure: float | str = gas_properties.ATMOSPHERE
    accommodation: Mapping | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise DPHTError(f"HTC table kind must be one of {KINDS}, got {self.kind!r}")
        for name in ("distance", "temperature"):
            axis = np.asarray(getattr(self, name), dtype=float)
            if axis.ndim != 1 or axis.size < 2:
                raise DPHTError(f"HTC table {name} must be 1-D with at least 2 nodes, got {axis.shape}")
            step = np.diff(axis)
            if np.any(step <= 0) or np.ptp(step) > 1e-9 * abs(axis).max():
                raise DPHTError(f"HTC table {name} must be uniform and increasing")
        shape = (np.size(self.distance), np.size(self.temperature))
        if np.shape(self.values) != shape:
            raise DPHTError(f"HTC table values have shape {np.shape(self.values)}, expected {shape}")

    def uniform(self) -> Table2D:
        """``(d0, dd, T0, dT, values)`` for the kernels: first node and spacing of each axis."""
        d, t = self.distance, self.temperature
        return Table2D(
            float(d[0]), float((d[-1] - d[0]) / (d.size - 1)),
            float(t[0]), float((t[-1] - t[0]) / (t.size - 1)),
            np.ascontiguousarray(self.values, dtype=np.float64),
        )

    def exact(self, distance, temperature) -> np.ndarray:
        """The HTC [W/K] the table tabulates (:func:`pfp` or :func:`pfw` with its parameters), at
        ``distance`` [m] and ``temperature`` [K] (broadcast)."""
        return _evaluate(self.kind, distance, temperature, self.radius, self.k_solid, self.solid_fraction, self.gas,
                         self.pressure, self.accommodation)  # fmt: skip


def _evaluate(kind, distance, temperature, radius, k_solid, solid_fraction, gas, pressure, accommodation) -> np.ndarray:
    """:func:`_htc` with ``k_solid`` a number or a table (then each point uses k_s at its temperature)."""
    if not isinstance(k_solid, Mapping):
        return _htc(kind, distance, temperature, radius, k_solid, solid_fraction, gas, pressure, accommodation)
    d, t = np.broadcast_arrays(np.asarray(distance, dtype=float), np.asarray(temperature, dtype=float))
    out = np.empty(d.shape)
    for value in np.unique(t):
        at = t == value
        k = float(solid_conductivity(k_solid, value, "k_solid"))
        out[at] = _htc(kind, d[at], value, radius, k, solid_fraction, gas, pressure, accommodation)
    return out


def default_distance_range(kind: str, radius: float) -> tuple[float, float]:
    """Distances [m] tabulated by default: PFP 1.99R-3R (the paper's 3R cutoff), PFW the same gap
    range, 0.995R-1.5R."""
    _check_kind(kind)
    return (1.99 * radius, 3.0 * radius) if kind == "pfp" else (0.995 * radius, 1.5 * radius)


def build_table(kind: str, *, radius: float, k_solid: float | Mapping, solid_fraction: float,
                gas: str | Mapping = "air", pressure=gas_properties.ATMOSPHERE, accommodation=None,
                distance_range: tuple[float, float] | None = None, n_distance: int = 200,
                temperature_range: tuple[float, float] | None = None, n_temperature: int = 64) -> HTCTable:
    """Tabulate :func:`pfp` or :func:`pfw` on a uniform grid (DPHT paper, Section 3.4).

    ``distance_range`` [m] defaults to :func:`default_distance_range`, ``temperature_range`` [K]
    to the whole conductivity table of ``gas``. ``k_solid`` [W/(m K)] is a number, or a table
    ``{"temperature": [...], "conductivity": [...]}``: then each temperature column uses the
    particle conductivity at that temperature. ``pressure`` and ``accommodation`` as for
    :func:`pfp`; at pressure 0 (a vacuum) every value is 0.
    """
    _check_kind(kind)
    tabulated = isinstance(k_solid, Mapping)
    radius, k_check, solid_fraction = _check_parameters(radius, 1.0 if tabulated else k_solid, solid_fraction)
    p = check_pressure(pressure)
    pressure = CONTINUUM if p == np.inf else p
    accommodation = accommodation_of(accommodation, gas) if rarefied(p) else None
    for name, n in (("n_distance", n_distance), ("n_temperature", n_temperature)):
        if not isinstance(n, (int, np.integer)) or n < 2:
            raise DPHTError(f"{name} must be an integer >= 2, got {n!r}")
    ranges = {
        "distance_range": distance_range or default_distance_range(kind, radius),
        "temperature_range": temperature_range or gas_properties.valid_range(gas),
    }
    for name, value in ranges.items():
        bounds = np.asarray(value, dtype=float).ravel()
        if bounds.size != 2 or not (np.all(np.isfinite(bounds)) and 0 < bounds[0] < bounds[1]):
            raise DPHTError(f"{name} must be (low, high) with 0 < low < high, got {value!r}")
    d_min = min_distance(kind, radius=radius, solid_fraction=solid_fraction)
    if ranges["distance_range"][0] <= d_min:
        raise DPHTError(
            f"distance_range starts at {ranges['distance_range'][0]:g} m, at or below {d_min:g} m "
            f"where the {kind.upper()} model is undefined"
        )
    t_low, t_high = gas_properties.valid_range(gas)
    if p > 0.0 and (ranges["temperature_range"][0] < t_low or ranges["temperature_range"][1] > t_high):
        raise DPHTError(
            f"temperature_range {tuple(ranges['temperature_range'])} K exceeds the conductivity "
            f"table of the gas ({t_low:g}-{t_high:g} K)"
        )
    distance = np.linspace(*ranges["distance_range"], n_distance)
    temperature = np.linspace(*ranges["temperature_range"], n_temperature)
    k_solid = dict(k_solid) if tabulated else k_check
    values = _evaluate(kind, distance[:, None], temperature[None, :], radius, k_solid, solid_fraction, gas, pressure,
                       accommodation)  # fmt: skip
    return HTCTable(kind, distance, temperature, values, radius, k_solid, solid_fraction, gas, pressure, accommodation)


def table_from_spec(spec: Mapping) -> HTCTable:
    """Build the table a workflow spec describes (see :func:`dpht.config.htc_spec`).

    Distances run from the default lower end (slight overlap) to ``cutoff`` radii; ``accommodation``
    (the coefficients the config gives) is left out where the jump does not apply or all are typical.
    """
    radius, kind = spec["radius"], spec["kind"]
    return build_table(
        kind,
        radius=radius,
        k_solid=spec["k_solid"],
        solid_fraction=spec["solid_fraction"],
        gas=spec["gas"],
        pressure=spec["gas_pressure"],
        accommodation=spec.get("accommodation"),
        distance_range=(default_distance_range(kind, radius)[0], spec["cutoff"] * radius),
        n_distance=spec["distances"],
        temperature_range=tuple(spec["temperature_range"]),
        n_temperature=spec["temperatures"],
    )


def solid_conductivity(value: float | Mapping, temperature, key: str = "particles.conductivity") -> np.ndarray:
    """Particle conductivity [W/(m K)] at ``temperature`` [K] from a number or a table mapping.

    Tables are interpolated like gas tables (monotone cubic, no extrapolation); ``key`` names the
    config entry in errors.
    """
    t = np.asarray(temperature, dtype=float)
    if not isinstance(value, Mapping):
        return np.full(t.shape, float(value))
    try:
        k = np.asarray(gas_properties.conductivity(value, t, table="particle conductivity table"), dtype=float)
    except DPHTError as err:
        raise DPHTError(f"{key}: {err}") from None
    if np.any(k <= 0):
        raise DPHTError(f"{key}: conductivity must be > 0 W/(m K) over {t.min():g}-{t.max():g} K")
    return k


def interpolate(table: HTCTable, distance, temperature) -> np.ndarray:
    """Bilinear interpolation of ``table`` [W/K], as the thermal kernel does (:mod:`dpht.util.interp`).

    Points outside the grid are clamped to its edges: a distance below the first node gets the
    first node's HTC (in the continuum HTC falls with distance, so this under-estimates slightly
    overlapping pairs closer than the table start; with the temperature jump it may rise within
    the overlap, by < 0.1 % at 1 atm), one beyond the last node the last node's HTC (the kernel
    applies its cutoff before looking up), and likewise in temperature.
    """
    d, t = np.broadcast_arrays(np.asarray(distance, dtype=float), np.asarray(temperature, dtype=float))
    out = np.empty(d.size)
    table_2d_many(table.uniform(), np.ascontiguousarray(d).ravel(), np.ascontiguousarray(t).ravel(), out)
    return out.reshape(d.shape)


def save_table(path: str | Path, table: HTCTable) -> None:
    """Write ``table`` to HDF5: datasets distance, temperature, values; parameters as attributes
    (the gas pressure as ``gas_pressure``, Pa or "continuum", and the accommodation coefficients,
    where given, as ``accommodation_particle`` and ``accommodation_wall``)."""
    with h5py.File(path, "w") as f:
        f.attrs.update(format=FORMAT, kind=table.kind, radius=table.radius, gas_pressure=table.pressure,
                       solid_fraction=table.solid_fraction,
                       units="distance m, temperature K, values W/K, gas_pressure Pa")
        if table.accommodation is not None:
            f.attrs.update({f"accommodation_{s}": float(table.accommodation[s]) for s in SURFACES})
        for name, value in (("gas", table.gas), ("k_solid", table.k_solid)):
            if isinstance(value, Mapping):  # its keys (a gas table's molecular data too) in <name>_keys
                f.attrs[name] = "user table"
                f.attrs[f"{name}_keys"] = ",".join(value)
                for key, entry in value.items():
                    f.attrs[f"{name}_{key}"] = np.asarray(entry, dtype=float)
            else:
                f.attrs[name] = value
        for name in ("distance", "temperature", "values"):
            f.create_dataset(name, data=np.asarray(getattr(table, name), dtype=np.float64))


def load_table(path: str | Path) -> HTCTable:
    """Read a table written by :func:`save_table`."""
    path = Path(path)
    with open_checked(path, FORMAT, "an HTC table") as f:
        missing = [n for n in ("distance", "temperature", "values") if n not in f]
        if missing:
            raise DPHTError(f"{path}: missing dataset(s) {missing}")
        check_values(path, "distance", f["distance"][...], low=0.0, increasing=True, what="distances in m")
        check_values(path, "temperature", f["temperature"][...], low=0.0, increasing=True, what="temperatures in K")
        check_values(path, "values", f["values"][...], low=0.0, what="heat transfer coefficients in W/K")
        gas, k_solid, pressure = (_table_attr(f.attrs, name) for name in ("gas", "k_solid", "gas_pressure"))
        accommodation = {s: float(f.attrs[f"accommodation_{s}"]) for s in SURFACES if f"accommodation_{s}" in f.attrs}
        return HTCTable(
            str(f.attrs["kind"]),
            f["distance"][...], f["temperature"][...], f["values"][...],
            float(f.attrs["radius"]), k_solid if isinstance(k_solid, Mapping) else float(k_solid),
            float(f.attrs["solid_fraction"]), gas, pressure if isinstance(pressure, str) else float(pressure),
            accommodation or None,
        )


def _table_attr(attrs, name):
    """A name/number attribute, or the table stored as ``<name>_<key>`` for the keys in ``<name>_keys``."""
    value = attrs[name]
    if isinstance(value, str) and value == "user table":
        return {key: attrs[f"{name}_{key}"].tolist() for key in attrs[f"{name}_keys"].split(",")}
    return value.item() if hasattr(value, "item") else value
