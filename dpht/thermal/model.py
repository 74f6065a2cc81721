"""The thermal model of one scene: material constants, tables and wall boundary conditions as arrays.

Built once from the validated config (see :func:`build`), then passed unchanged to the kernels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dpht.closures import contact, heat_capacity, htc, rdf
from dpht.config import solid_fractions
from dpht.errors import ConfigError
from dpht.util.expr import parse
from dpht.thermal.kernels import MODES
from dpht.thermal.wall_distance import WallIndex, build_index
from geometry.walls import Walls

# A 2x2 table standing in for a disabled mode (its kernel branch is compiled out).
_UNUSED_2D = (0.0, 1.0, 0.0, 1.0, np.zeros((2, 2)))
_UNUSED_1D = (0.0, 1.0, np.zeros(2))


@dataclass(frozen=True)
class ThermalModel:
    modes: frozenset
    radius: float  # m
    mass: float  # kg
    k_particle: tuple  # (T0, dT, values): particle conductivity W/(m K) on a uniform temperature grid (K)
    k_pw: tuple  # the same for 4 / (1/k_p + 1/k_w), Eq. 6
    c_pp: float  # Eq. 3
    c_pw: float  # Eq. 7
    rad_coefficient: float  # eps_p A_p sigma, W/K^4
    pfp: tuple  # (d0, dd, T0, dT, values[d, T]) real centre distance (m), mean T (K), W/K
    pfw: tuple
    rdf_pp: tuple  # (0, du, values) over u = (centre distance / radius)^2 up to the cutoff, see _squared
    rdf_pw: tuple  # the same over (centre-to-wall distance / radius)^2
    pfp_cutoff: float  # m, centre-centre
    pfw_cutoff: float  # m, centre-wall
    radiation_cutoff: float  # m
    enthalpy: heat_capacity.EnthalpyTable
    initial_temperature: float  # K
    inlet_temperature: float  # K
    max_substeps: int
    zones: tuple = field(default=())  # WallIndex per Dirichlet zone
    element_temperature: np.ndarray = field(default_factory=lambda: np.zeros(0))  # K, NaN if adiabatic
    n_elements: int = 0

    @property
    def pair_cutoff(self) -> float:
        cut = 0.0
        if "pp_contact" in self.modes:
            cut = 2 * self.radius
        if "pfp" in self.modes:
            cut = max(cut, self.pfp_cutoff)
        if "pp_radiation" in self.modes:
            cut = max(cut, self.radiation_cutoff)
        return cut

    @property
    def wall_cutoff(self) -> float:
        cut = 0.0
        if "pw_contact" in self.modes:
            cut = self.radius
        if "pfw" in self.modes:
            cut = max(cut, self.pfw_cutoff)
        if "pw_radiation" in self.modes:
            cut = max(cut, self.radiation_cutoff)
        return cut

    def flags(self, names) -> tuple:
        return tuple(name in self.modes for name in names)


def build(spec: dict, walls: Walls | None, htc_tables: dict, rdf_tables: rdf.RDFTables | None = None) -> ThermalModel:
    """Assemble the model from ``spec`` (see :func:`dpht.config.thermal_spec`).

    ``htc_tables`` maps "pfp"/"pfw" to :class:`dpht.closures.htc.HTCTable`; ``rdf_tables`` is needed only
    when a radiation mode is enabled.
    """
    p, w, t = spec["particles"], spec["wall"], spec["thermal"]
    modes = frozenset(m for m in MODES if t["modes"].get(m, False))
    radius = p["diameter"] / 2
    mass = p["density"] * 4.0 / 3.0 * math.pi * radius**3

    element_T = _wall_temperatures(walls, t["walls"]) if walls is not None else np.zeros(0)
    wall_T = element_T[np.isfinite(element_T)]
    temps = [t["initial_temperature"], t["inlet_temperature"], *wall_T.tolist()]
    T_low, T_high = min(temps), max(temps)
    enthalpy = heat_capacity.build(heat_capacity.specific_heat(p["specific_heat"]), T_low, T_high)

    def htc_table(kind):
        if kind not in modes:
            return _UNUSED_2D
        table = htc_tables[kind]
        lo, hi = table.temperature[0], table.temperature[-1]
        if T_low < lo or T_high > hi:
            raise ConfigError(
                f"thermal.htc_table.temperature_range: the scene reaches {T_low:.1f}-{T_high:.1f} K "
                f"but the {kind} table covers {lo:.1f}-{hi:.1f} K"
            )
        return table.uniform()

    radiation = modes & {"pp_radiation", "pw_radiation"}
    if radiation and rdf_tables is None:
        raise ConfigError(f"thermal.rdf_table: needed for {sorted(radiation)} but not given")

    phi = solid_fractions(t["solid_fraction"])
    T_grid = np.linspace(enthalpy.T0, enthalpy.T_max, 512)
    k_p = htc.solid_conductivity(p["conductivity"], T_grid)
    model = ThermalModel(
        modes=modes,
        radius=radius,
        mass=mass,
        k_particle=(T_grid[0], T_grid[1] - T_grid[0], k_p),
        k_pw=(T_grid[0], T_grid[1] - T_grid[0], contact.pw_conductivity(k_p, w["conductivity"])),
        c_pp=contact.c_pp(p["youngs_modulus_dem"], p["youngs_modulus_real"]),
        c_pw=contact.c_pw(
            p["poisson_ratio"], p["youngs_modulus_real"], p["youngs_modulus_dem"],
            w["poisson_ratio"], w["youngs_modulus_real"], w["youngs_modulus_dem"],
        ),  # fmt: skip
        rad_coefficient=p["emissivity"] * 4 * math.pi * radius**2 * contact.STEFAN_BOLTZMANN,
        pfp=htc_table("pfp"),
        pfw=htc_table("pfw"),
        rdf_pp=_squared(rdf_tables.pp, phi["bulk"], t["radiation_cutoff"]) if "pp_radiation" in modes else _UNUSED_1D,
        rdf_pw=_squared(rdf_tables.pw, phi["near_wall"], t["radiation_cutoff"]) if "pw_radiation" in modes else _UNUSED_1D,
        pfp_cutoff=t["pfp_cutoff"] * radius,
        pfw_cutoff=t["pfw_cutoff"] * radius,
        radiation_cutoff=t["radiation_cutoff"] * radius,
        enthalpy=enthalpy,
        initial_temperature=t["initial_temperature"],
        inlet_temperature=t["inlet_temperature"],
        max_substeps=t["max_substeps"],
    )
    if walls is None or model.wall_cutoff == 0.0:
        return model
    zones = tuple(
        _zone_index(walls, name, model.wall_cutoff)
        for name in walls.zone_names
        if np.any(np.isfinite(element_T[walls.zone_mask(name)]))
    )
    return replace(model, zones=zones, element_temperature=element_T, n_elements=len(walls.area))


def _squared(table: rdf.RDFTable, solid_fraction: float, cutoff: float, n: int = 1024):
    """The RDF at ``solid_fraction`` on a uniform grid in squared distance (radii^2).

    The pair kernel looks radiation up by squared distance, so the ~90% of pairs that only
    radiate need no square root. The grid starts at 0 and runs one step past the squared
    ``cutoff`` (radii), so every pair inside the cutoff is looked up without clamping; outside the
    traced distances the table's end values hold. 1024 points keep the resampling error far below
    the tables' statistical error.
    """
    d0, dd, values = table.at_solid_fraction(solid_fraction)
    d = d0 + dd * np.arange(values.size)
    step = cutoff**2 / n
    u = step * np.arange(n + 2)
    return 0.0, step, np.interp(np.sqrt(u), d, values)


def _zone_index(walls: Walls, name: str, cutoff: float) -> WallIndex:
    mask = walls.zone_mask(name)
    return build_index(walls.vertices[mask], cutoff, elements=np.flatnonzero(mask))


def _wall_temperatures(walls: Walls, conditions: dict) -> np.ndarray:
    """Temperature (K) of every element from its zone's condition; NaN for adiabatic elements."""
    # An adiabatic entry for a zone this geometry lacks (e.g. `mixer` in a variant without one) is
    # harmless; a temperature for a missing zone is most likely a misspelt name.
    unknown = sorted(z for z, c in conditions.items() if z not in walls.zone_names and c != "adiabatic")
    if unknown:
        raise ConfigError(f"thermal.walls: zones {unknown} are not in the geometry (zones: {list(walls.zone_names)})")
    missing = sorted(set(walls.zone_names) - set(conditions))
    if missing:
        raise ConfigError(f"thermal.walls: no boundary condition for zones {missing} (use 'adiabatic' or {{temperature: ...}})")
    temperature = np.full(len(walls.area), np.nan)
    for name, condition in conditions.items():
        if condition == "adiabatic" or name not in walls.zone_names:
            continue
        key = f"thermal.walls.{name}.temperature"
        mask = walls.zone_mask(name)
        x, y, z = walls.centroid[mask].T
        expression = parse(condition["temperature"], ("x", "y", "z"), key)
        temperature[mask] = expression.checked("a finite temperature > 0 K at every element centroid (x, y, z in m)",
                                               minimum=0.0, x=x, y=y, z=z)
    return temperature
