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
The HTC falls monotonically with distance from about 1.8 R outwards (checked over 1.99-3.5 R);
with deeper overlap it falls again, as the contact circle eats the cone.

Quadrature. When the gap closes (h -> 0+, or just after contact) the gas resistance dominates
and the integrand peaks in a boundary layer of width w ~ sqrt(2 R D0 k_f) at the lower limit,
where D0 = l_s/k_s + l_f/k_f there: w ~ 0.045 R for touching spheres with k_s/k_f = 1e3, and
w -> 0 with the gap in the rigid limit k_s -> infinity. Near the lower limit
the resistance is D ~ D0 (1 + (r^2 - r_lo^2) / w^2) = D0 cosh^2 t with the substitution
r^2 = r_lo^2 + w^2 sinh^2 t, which makes 2 pi r dr / D ~ 2 pi w^2 tanh(t) dt / D0 smooth on the
whole interval. Gauss-Legendre on t then converges exponentially: 16 nodes already agree with
adaptive quadrature to 1e-12 over the useful range; 32 are used (errors measured in
tests/test_htc.py and by ``python -m dpht verify htc_pfp_quadrature``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from dpht.closures import gas as gas_properties
from dpht.errors import DPHTError
from dpht.util.h5 import open_checked
from dpht.util.interp import Table2D, table_2d_many

FORMAT = "dpht-htc-1"
KINDS = ("pfp", "pfw")
CONE_COEFFICIENT = 0.560  # DPHT paper, Eq. 13 (Zhou et al. 2009)
N_NODES = 32  # Gauss-Legendre nodes in the substituted variable t

_T_NODES, _T_WEIGHTS = np.polynomial.legendre.leggauss(N_NODES)


def cone_base_radius(radius: float, solid_fraction: float) -> float:
    """R_ij = 0.560 R alpha_s^(-1/3) [m] (DPHT paper, Eq. 13)."""
    return CONE_COEFFICIENT * radius * solid_fraction ** (-1.0 / 3.0)


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


def _sphere_plane(c, k_f, radius: float, k_solid: float, r_ij: float) -> np.ndarray:
    """Integral of Eq. 18, int 2 pi r dr / (l_s/k_s + l_f/k_f) [W/K], with l_f of Eq. 20.

    ``c`` is the centre-to-plane distance [m] and ``k_f`` the gas conductivity [W/(m K)]; they
    broadcast together. Quadrature: see the module docstring.
    """
    c, k_f = np.broadcast_arrays(np.asarray(c, dtype=float), np.asarray(k_f, dtype=float))
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
    d0 = (s_lo - r_lo * c / r_ij) / k_solid + h_plus / k_f
    w2 = d0 * k_f * (c + s_lo)
    t_max = np.arcsinh(np.sqrt(span2 / w2))

    t = 0.5 * t_max[..., None] * (_T_NODES + 1.0)
    v = w2[..., None] * np.sinh(t) ** 2  # r^2 - r_lo^2
    r = np.sqrt(r_lo[..., None] ** 2 + v)
    s = np.sqrt(s_lo[..., None] ** 2 - v)  # sqrt(R^2 - r^2)
    l_solid = s - r * (c / r_ij)[..., None]  # Eq. 19
    # Eq. 20, l_f = c - s = (c^2 - R^2 + r^2) / (c + s), free of cancellation as the gap closes.
    l_fluid = (h_plus * (2.0 * R + h_plus))[..., None] + v
    l_fluid = l_fluid / (c[..., None] + s)
    integrand = 2.0 * np.pi * w2[..., None] * np.sinh(t) * np.cosh(t)
    integrand = integrand / (l_solid / k_solid + l_fluid / k_f[..., None])
    return 0.5 * t_max * (integrand @ _T_WEIGHTS)


def _htc(kind, distance, temperature, radius, k_solid, solid_fraction, gas) -> np.ndarray:
    radius, k_solid, solid_fraction = _check_parameters(radius, k_solid, solid_fraction)
    d = _check_distance(kind, distance, radius, solid_fraction)
    k_f = gas_properties.conductivity(gas, temperature)
    r_ij = cone_base_radius(radius, solid_fraction)
    if kind == "pfp":  # c = R + h = d_ij / 2 (Eq. 11); Eq. 8 is half the Eq. 18 integrand
        return 0.5 * _sphere_plane(0.5 * d, k_f, radius, k_solid, r_ij)
    return _sphere_plane(d, k_f, radius, k_solid, r_ij)  # c = R + h = d_iw


def pfp(distance, temperature, *, radius: float, k_solid: float, solid_fraction: float,
        gas: str | Mapping = "air"):
    """Particle-fluid-particle HTC [W/K], the integral in DPHT paper Eq. 8 (Eqs. 9-13).

    ``distance`` is the real centre-centre distance d_ij [m] (after the softening correction,
    Eq. 17) and ``temperature`` the mean of the two particles [K]; they broadcast. ``radius`` [m],
    ``k_solid`` [W/(m K)], ``solid_fraction`` alpha_s for Eq. 13, ``gas`` a name from
    :data:`dpht.closures.gas.GASES` or a conductivity table mapping.
    """
    return _htc("pfp", distance, temperature, radius, k_solid, solid_fraction, gas)


def pfw(distance, temperature, *, radius: float, k_solid: float, solid_fraction: float,
        gas: str | Mapping = "air"):
    """Particle-fluid-wall HTC [W/K], the integral in DPHT paper Eq. 18 (Eqs. 11-13, 19-20).

    ``distance`` is the real centre-to-wall distance d_iw [m] (Eq. 24) and ``temperature`` the
    mean of the particle and the wall [K]; other arguments as for :func:`pfp`.
    """
    return _htc("pfw", distance, temperature, radius, k_solid, solid_fraction, gas)


@dataclass(frozen=True, eq=False)
class HTCTable:
    """HTC [W/K] on a uniform grid of distance [m] x temperature [K], for the thermal kernel.

    ``gas`` is the gas name, or for a user conductivity table the mapping
    ``{"temperature": [...], "conductivity": [...]}``.
    """

    kind: str
    distance: np.ndarray
    temperature: np.ndarray
    values: np.ndarray
    radius: float
    k_solid: float | Mapping
    solid_fraction: float
    gas: str | Mapping = field(default="air")

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


def default_distance_range(kind: str, radius: float) -> tuple[float, float]:
    """Distances [m] tabulated by default: PFP 1.99R-3R (the paper's 3R cutoff), PFW the same gap
    range, 0.995R-1.5R."""
    _check_kind(kind)
    return (1.99 * radius, 3.0 * radius) if kind == "pfp" else (0.995 * radius, 1.5 * radius)


def build_table(kind: str, *, radius: float, k_solid: float | Mapping, solid_fraction: float,
                gas: str | Mapping = "air", distance_range: tuple[float, float] | None = None,
                n_distance: int = 200, temperature_range: tuple[float, float] | None = None,
                n_temperature: int = 64) -> HTCTable:
    """Tabulate :func:`pfp` or :func:`pfw` on a uniform grid (DPHT paper, Section 3.4).

    ``distance_range`` [m] defaults to :func:`default_distance_range`, ``temperature_range`` [K]
    to the whole conductivity table of ``gas``. ``k_solid`` [W/(m K)] is a number, or a table
    ``{"temperature": [...], "conductivity": [...]}``: then each temperature column uses the
    particle conductivity at that temperature.
    """
    _check_kind(kind)
    tabulated = isinstance(k_solid, Mapping)
    radius, k_check, solid_fraction = _check_parameters(radius, 1.0 if tabulated else k_solid, solid_fraction)
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
    if ranges["temperature_range"][0] < t_low or ranges["temperature_range"][1] > t_high:
        raise DPHTError(
            f"temperature_range {tuple(ranges['temperature_range'])} K exceeds the conductivity "
            f"table of the gas ({t_low:g}-{t_high:g} K)"
        )
    distance = np.linspace(*ranges["distance_range"], n_distance)
    temperature = np.linspace(*ranges["temperature_range"], n_temperature)
    if not tabulated:
        values = _htc(kind, distance[:, None], temperature[None, :], radius, k_check, solid_fraction, gas)
        return HTCTable(kind, distance, temperature, values, radius, k_check, solid_fraction, gas)
    k_nodes = solid_conductivity(k_solid, temperature, "k_solid")
    values = np.column_stack([_htc(kind, distance, t, radius, k, solid_fraction, gas) for t, k in zip(temperature, k_nodes)])
    return HTCTable(kind, distance, temperature, values, radius, dict(k_solid), solid_fraction, gas)


def table_from_spec(spec: Mapping) -> HTCTable:
    """Build the table a workflow spec describes (see :func:`dpht.config.htc_spec`).

    Distances run from the default lower end (slight overlap) to ``cutoff`` radii.
    """
    radius, kind = spec["radius"], spec["kind"]
    return build_table(
        kind,
        radius=radius,
        k_solid=spec["k_solid"],
        solid_fraction=spec["solid_fraction"],
        gas=spec["gas"],
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
    first node's HTC (HTC falls with distance, so this under-estimates slightly overlapping pairs
    closer than the table start), one beyond the last node the last node's HTC (the kernel
    applies its cutoff before looking up), and likewise in temperature.
    """
    d, t = np.broadcast_arrays(np.asarray(distance, dtype=float), np.asarray(temperature, dtype=float))
    out = np.empty(d.size)
    table_2d_many(table.uniform(), np.ascontiguousarray(d).ravel(), np.ascontiguousarray(t).ravel(), out)
    return out.reshape(d.shape)


def save_table(path: str | Path, table: HTCTable) -> None:
    """Write ``table`` to HDF5: datasets distance, temperature, values; parameters as attributes."""
    with h5py.File(path, "w") as f:
        f.attrs.update(format=FORMAT, kind=table.kind, radius=table.radius,
                       solid_fraction=table.solid_fraction, units="distance m, temperature K, values W/K")
        for name, value in (("gas", table.gas), ("k_solid", table.k_solid)):
            if isinstance(value, Mapping):
                f.attrs[name] = "user table"
                for axis in ("temperature", "conductivity"):
                    f.attrs[f"{name}_{axis}"] = np.asarray(value[axis], dtype=float)
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
        gas, k_solid = (_table_attr(f.attrs, name) for name in ("gas", "k_solid"))
        return HTCTable(
            str(f.attrs["kind"]),
            f["distance"][...], f["temperature"][...], f["values"][...],
            float(f.attrs["radius"]), k_solid if isinstance(k_solid, Mapping) else float(k_solid),
            float(f.attrs["solid_fraction"]), gas,
        )


def _table_attr(attrs, name):
    """A name/number attribute, or the table stored as ``<name>_temperature``/``<name>_conductivity``."""
    value = attrs[name]
    if isinstance(value, str) and value == "user table":
        return {axis: attrs[f"{name}_{axis}"].tolist() for axis in ("temperature", "conductivity")}
    return value.item() if hasattr(value, "item") else value
