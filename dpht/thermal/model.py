"""The thermal model of one scene: material constants, tables and wall boundary conditions as arrays.

Built once from the validated config (see :func:`build`), then passed unchanged to the kernels:
the parameters and tables of the modes are the typed records of :mod:`dpht.thermal.kernels`
(``PairModes``/``PairTables``, ``WallModes``/``WallTables``), and each mode's cutoff follows its
rule in the registry :mod:`dpht.thermal.modes`. SI units: m, K, W, J.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from dpht.closures import contact, heat_capacity, htc, rdf
from dpht.errors import ConfigError
from dpht.thermal import intraparticle, modes as registry
from dpht.thermal.intraparticle import NO_CONVECTION, Surface
from dpht.thermal.kernels import PairModes, PairTables, WallModes, WallTables
from dpht.thermal.wall_distance import WallIndex, build_index
from dpht.util.expr import parse
from dpht.util.interp import Table1D, Table2D
from geometry.walls import Walls

# A 2x2 table standing in for a disabled mode (its kernel branch is compiled out).
_UNUSED_2D = Table2D(0.0, 1.0, 0.0, 1.0, np.zeros((2, 2)))
_UNUSED_1D = Table1D(0.0, 1.0, np.zeros(2))


@dataclass(frozen=True)
class ThermalModel:
    modes: frozenset  # names of the enabled modes
    radius: float  # m
    mass: float  # kg
    cutoffs: dict  # m per mode name (centre-centre for PP modes, centre-wall for PW modes)
    pair: PairModes  # the particle-particle modes' scalar parameters, as the pair kernel reads them
    pair_tables: PairTables  # and their tables (a 2x2 stand-in for a disabled mode)
    wall: WallModes  # the same for the particle-wall modes
    wall_tables: WallTables
    enthalpy: heat_capacity.EnthalpyTable
    initial_temperature: float  # K
    inlet_temperature: float  # K
    max_substeps: int
    zones: tuple = field(default=())  # WallIndex per Dirichlet zone (none without an enabled PW mode)
    element_temperature: np.ndarray = field(default_factory=lambda: np.zeros(0))  # K per wall element, NaN if adiabatic
    n_elements: int = 0  # wall elements (the rows of the wall-heat outputs), 0 without walls
    # Resolved intra-particle conduction (thermal.intraparticle): the shells of every particle, or
    # None for uniform particles; ``intraparticle`` is the config's switch (True, False, "auto"), and
    # an "auto" model has no shells until :func:`resolved` gives it the decision.
    shells: intraparticle.ShellGrid | None = None
    intraparticle: bool | str = False
    shell_count: int = 10  # thermal.shells
    convection: Surface = NO_CONVECTION  # thermal.convection (particle-gas)
    biot_threshold: float = 0.1  # thermal.biot_threshold, for "auto"

    @property
    def pair_cutoff(self) -> float:
        """Largest centre-centre cutoff (m) of the enabled PP modes; 0 if none."""
        return _largest(self.cutoffs, self.modes, registry.PP_MODES)

    @property
    def wall_cutoff(self) -> float:
        """Largest centre-wall cutoff (m) of the enabled PW modes; 0 if none."""
        return _largest(self.cutoffs, self.modes, registry.PW_MODES)

    def flags(self, names) -> tuple:
        return tuple(name in self.modes for name in names)


def resolved(model: ThermalModel) -> ThermalModel:
    """``model`` with its ``shell_count`` shells (resolved intra-particle conduction)."""
    return dataclasses.replace(model, shells=intraparticle.grid(model.radius, model.shell_count))


def _largest(cutoffs: dict, enabled: frozenset, names) -> float:
    return max((cutoffs[m] for m in names if m in enabled), default=0.0)


def build(spec: dict, walls: Walls | None, htc_tables: dict, rdf_tables: rdf.RDFTables | None = None) -> ThermalModel:
    """Assemble the model from ``spec`` (see :func:`dpht.config.thermal_spec`).

    ``htc_tables`` maps "pfp"/"pfw" to :class:`dpht.closures.htc.HTCTable`; ``rdf_tables`` is needed only
    when a radiation mode is enabled.
    """
    p, w, t = spec["particles"], spec["wall"], spec["thermal"]
    modes = registry.enabled(t["modes"])
    radius = p["diameter"] / 2
    mass = p["density"] * 4.0 / 3.0 * math.pi * radius**3
    cutoffs = {m.name: m.cutoff_radii(t) * radius for m in registry.MODES}

    element_T = _wall_temperatures(walls, t["walls"]) if walls is not None else np.zeros(0)
    wall_T = element_T[np.isfinite(element_T)]
    convection = t.get("convection")
    gas = [convection["gas_temperature"]] if convection else []
    temps = [t["initial_temperature"], t["inlet_temperature"], *wall_T.tolist(), *gas]
    T_low, T_high = min(temps), max(temps)
    enthalpy = heat_capacity.build(heat_capacity.specific_heat(p["specific_heat"]), T_low, T_high)

    def htc_table(name) -> Table2D:
        if name not in modes:
            return _UNUSED_2D
        kind = registry.BY_NAME[name].table[1]
        table = htc_tables[kind]
        lo, hi = table.temperature[0], table.temperature[-1]
        if T_low < lo or T_high > hi:
            raise ConfigError(
                f"thermal.htc_table.temperature_range: the scene reaches {T_low:.1f}-{T_high:.1f} K "
                f"but the {kind} table covers {lo:.1f}-{hi:.1f} K"
            )
        return table.uniform()

    radiation = modes & set(registry.needing("rdf"))
    if radiation and rdf_tables is None:
        raise ConfigError(f"thermal.rdf_table: needed for {sorted(radiation)} but not given")
    phi = registry.solid_fractions(t["solid_fraction"])
    rad_coefficient = p["emissivity"] * 4 * math.pi * radius**2 * contact.STEFAN_BOLTZMANN

    def rdf_table(name) -> Table1D:
        if name not in modes:
            return _UNUSED_1D
        mode = registry.BY_NAME[name]
        return _squared(getattr(rdf_tables, mode.table[1]), phi[mode.region], mode.cutoff_radii(t))

    T_grid = np.linspace(enthalpy.T0, enthalpy.T_max, 512)
    dT = T_grid[1] - T_grid[0]
    k_p = htc.solid_conductivity(p["conductivity"], T_grid)
    wall_cutoff = _largest(cutoffs, modes, registry.PW_MODES)
    zones = () if walls is None or wall_cutoff == 0.0 else tuple(
        _zone_index(walls, name, wall_cutoff)
        for name in walls.zone_names
        if np.any(np.isfinite(element_T[walls.zone_mask(name)]))
    )  # fmt: skip
    model = ThermalModel(
        modes=modes,
        radius=radius,
        mass=mass,
        cutoffs=cutoffs,
        pair=PairModes(
            radius=radius,
            cutoff2=_largest(cutoffs, modes, registry.PP_MODES) ** 2,
            softening=contact.c_pp(p["youngs_modulus_dem"], p["youngs_modulus_real"]),
            pfp_cutoff2=cutoffs["pfp"] ** 2,
            radiation_cutoff2=cutoffs["pp_radiation"] ** 2,
            radiation_coefficient=rad_coefficient,
        ),
        pair_tables=PairTables(
            pp_contact=Table1D(T_grid[0], dT, k_p),
            pfp=htc_table("pfp"),
            pp_radiation=rdf_table("pp_radiation"),
        ),
        wall=WallModes(
            radius=radius,
            softening=contact.c_pw(
                p["poisson_ratio"], p["youngs_modulus_real"], p["youngs_modulus_dem"],
                w["poisson_ratio"], w["youngs_modulus_real"], w["youngs_modulus_dem"],
            ),  # fmt: skip
            pfw_cutoff=cutoffs["pfw"],
            radiation_cutoff=cutoffs["pw_radiation"],
            radiation_coefficient=rad_coefficient,
        ),
        wall_tables=WallTables(
            pw_contact=Table1D(T_grid[0], dT, contact.pw_conductivity(k_p, w["conductivity"])),
            pfw=htc_table("pfw"),
            pw_radiation=rdf_table("pw_radiation"),
        ),
        enthalpy=enthalpy,
        initial_temperature=t["initial_temperature"],
        inlet_temperature=t["inlet_temperature"],
        max_substeps=t["max_substeps"],
        zones=zones,
        element_temperature=element_T,
        n_elements=0 if walls is None else len(walls.area),
        intraparticle=t.get("intraparticle", False),
        shell_count=int(t.get("shells", 10)),
        biot_threshold=float(t.get("biot_threshold", 0.1)),
        convection=Surface(float(convection["coefficient"]), float(convection["gas_temperature"])) if convection
        else NO_CONVECTION,
    )
    return resolved(model) if model.intraparticle is True else model


def _squared(table: rdf.RDFTable, solid_fraction: float, cutoff: float, n: int = 1024) -> Table1D:
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
    return Table1D(0.0, step, np.interp(np.sqrt(u), d, values))


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
