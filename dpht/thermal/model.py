"""The thermal model of one scene: material constants, tables and wall boundary conditions as arrays.

Built once from the validated config (see :func:`build`), then passed unchanged to the kernels:
each mode of the registry (:mod:`dpht.thermal.modes`) has its law (the style's closure), its
parameters (:class:`dpht.closures.conductance.ModeParams`: its cutoff by the registry's rule, its
coefficient) and, when enabled, its table from the law's setup; :meth:`ThermalModel.state` hands
them to the kernels (:mod:`dpht.thermal.kernels`). SI units: m, K, W, J.

Wall contacts: one per wall *surface* (:mod:`dpht.geometry.walls`: the tube's cylinder, the orifice
plate, each mixer solid), at the nearest point of the whole surface, adiabatic elements included,
with the boundary condition of the element there. So a particle whose nearest point of a surface
is adiabatic gets no heat from a farther heated element of it; a particle near the edge between
two Dirichlet zones of one surface has one contact, not two; and a particle in the corner between
the tube and the orifice plate (two surfaces) keeps both. Distances are to the surface the DEM
collided particles with: the exact primitives of zones LIGGGHTS read as primitives (the DEM run's
record ``walls``, :attr:`dpht.dem.params.DemParams.wall_kinds`), the triangles of the others.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from dpht.closures import contact, heat_capacity, htc, rdf
from dpht.closures.conductance import ModeParams, Setting, Side
from dpht.errors import ConfigError, DPHTError
from dpht.thermal.slice import Slice
from dpht.thermal import intraparticle, modes as registry
from dpht.thermal.intraparticle import NO_CONVECTION, Surface
from dpht.thermal.wall_distance import SurfaceIndex, mesh_surface, primitive_surface
from dpht.util.expr import parse
from dpht.util.interp import Table1D, Table2D
from dpht.geometry.walls import FORMAT as WALLS_FORMAT, Walls

@dataclass(frozen=True)
class ThermalModel:
    modes: frozenset  # names of the enabled modes
    radius: float  # m
    mass: float  # kg
    cutoffs: dict  # m per mode name (centre-centre for PP modes, centre-wall for PW modes)
    pair: Side  # the particle-particle modes' shared parameters (reach: see state)
    wall: Side  # the particle-wall modes'
    styles: registry.Styles  # the style of each mode of the registry (thermal.styles)
    laws: dict  # the law (dpht.closures.conductance.Law) of each mode of the registry, its style's
    parameters: dict  # ModeParams of each mode of the registry (cutoff: m2 for PP modes, m for PW modes)
    tables: dict  # the table of each enabled mode (from its law's setup)
    conductivity: Table1D  # the particles' k_p (W/(m K)) over temperature (K)
    enthalpy: heat_capacity.EnthalpyTable
    initial_temperature: float  # K
    inlet_temperature: float  # K
    max_substeps: int
    surfaces: tuple = field(default=())  # SurfaceIndex per wall surface with a Dirichlet element (none without a PW mode)
    element_temperature: np.ndarray = field(default_factory=lambda: np.zeros(0))  # K per wall element, NaN if adiabatic
    n_elements: int = 0  # wall elements (the rows of the wall-heat outputs), 0 without walls
    # A slice travelling down a tube (thermal.slice): K per element at time t (s), which the stage
    # writes into element_temperature before each frame; None for walls fixed in time.
    wall_temperature_at: Callable[[float], np.ndarray] | None = None
    # Resolved intra-particle conduction (thermal.intraparticle): the shells of every particle, or
    # None for uniform particles; ``intraparticle`` is the config's switch (True, False, "auto"), and
    # an "auto" model has no shells until :func:`resolved` gives it the decision.
    shells: intraparticle.ShellGrid | None = None
    intraparticle: bool | str = False
    shell_count: int = 10  # thermal.shells
    convection: Surface = NO_CONVECTION  # thermal.convection (particle-gas)
    biot_threshold: float = 0.1  # thermal.biot_threshold, for "auto"
    # K, the scene's coldest and hottest temperatures: initial, inlet, walls (over a slice's path), gas
    temperature_range: tuple = (0.0, 0.0)
    # K, the coldest and hottest Dirichlet wall element over the run (a slice's over its path; the
    # element temperatures now are only those of the frame last stepped); None without one
    wall_range: tuple | None = None
    registry: registry.Registry = registry.REGISTRY  # the modes it was built from

    @property
    def pair_cutoff(self) -> float:
        """Largest centre-centre cutoff (m) of the enabled PP modes; 0 if none."""
        return _largest(self.cutoffs, self.modes, self.names("pp"))

    @property
    def wall_cutoff(self) -> float:
        """Largest centre-wall cutoff (m) of the enabled PW modes; 0 if none."""
        return _largest(self.cutoffs, self.modes, self.names("pw"))

    def names(self, side: str) -> tuple[str, ...]:
        """The registry's modes of ``side`` ("pp" or "pw"), in order (the PW modes: the wall-heat columns)."""
        return tuple(m.name for m in self.registry.side(side))

    def side_laws(self, side: str) -> tuple:
        """Each mode of ``side`` in registry order: its law, or None where disabled (the kernels'
        composition, :func:`dpht.thermal.kernels.pair_side`/``wall_side``)."""
        return tuple(self.laws[name] if name in self.modes else None for name in self.names(side))

    def state(self, side: str) -> tuple:
        """The flat tuple a kernel of ``side`` reads (see :mod:`dpht.thermal.kernels`): the side's
        :class:`Side` (its reach the largest enabled cutoff, squared between particles), then each
        enabled mode's parameters and table fields, in registry order."""
        shared = self.pair if side == "pp" else self.wall
        reach = self.pair_cutoff**2 if side == "pp" else self.wall_cutoff
        state = [shared.radius, shared.softening, reach]
        for name in self.names(side):
            if name in self.modes:
                state += [*self.parameters[name], *self.tables[name]]
        return tuple(state)

    def lookup_range(self) -> tuple[float, float]:
        """Temperatures (K) every temperature table covers: the enthalpy and conductivity tables, and
        the HTC tables of the enabled gas-gap modes. A particle outside is looked up clamped."""
        lo, hi = self.enthalpy.T0, self.enthalpy.T_max
        for mode in self.registry.modes:
            if mode.name in self.modes and mode.table is not None and mode.table[0] == "htc":
                table = self.tables[mode.name]
                lo, hi = max(lo, table.y0), min(hi, table.y0 + table.dy * (table.values.shape[1] - 1))
        return lo, hi


def resolved(model: ThermalModel) -> ThermalModel:
    """``model`` with its ``shell_count`` shells (resolved intra-particle conduction)."""
    return dataclasses.replace(model, shells=intraparticle.grid(model.radius, model.shell_count))


def _largest(cutoffs: dict, enabled: frozenset, names) -> float:
    return max((cutoffs[m] for m in names if m in enabled), default=0.0)


def build(spec: dict, walls: Walls | None, htc_tables: dict, rdf_tables: rdf.RDFTables | None = None,
          wall_kinds: dict | None = None, modes_registry: registry.Registry = registry.REGISTRY) -> ThermalModel:  # fmt: skip
    """Assemble the model from ``spec`` (see :func:`dpht.config.thermal_spec`).

    ``htc_tables`` maps "pfp"/"pfw" to :class:`dpht.closures.htc.HTCTable`; ``rdf_tables`` is needed only
    when a radiation mode is enabled. ``wall_kinds`` maps each wall zone to the surface the DEM
    collided particles with, "primitive" or "mesh" (the DEM summary's ``walls``); None: meshes.
    ``modes_registry`` is the set of modes (the project's unless extended,
    :meth:`dpht.thermal.modes.Registry.with_mode`); each mode's law is its style's in the spec's
    ``thermal.styles`` (a mode not named there: its default style).
    """
    p, w, t = spec["particles"], spec["wall"], spec["thermal"]
    modes = modes_registry.enabled(t["modes"])
    radius = p["diameter"] / 2
    mass = p["density"] * 4.0 / 3.0 * math.pi * radius**3
    cutoffs = {m.name: m.cutoff_radii(t) * radius for m in modes_registry.modes}
    styles = registry.Styles.of(t, modes_registry)
    laws = {m.name: styles[m.name].resolve() for m in modes_registry.modes}

    slice_ = Slice.of(t)
    element_T = wall_temperatures(walls, t["walls"]) if walls is not None else np.zeros(0)
    wall_temperature_at = None
    if slice_ is not None and walls is not None:
        def wall_temperature_at(time: float) -> np.ndarray:
            return wall_temperatures(walls, t["walls"], z=float(slice_.height(time)))

        element_T = wall_temperature_at(0.0)
        wall_T = np.concatenate([wall_temperatures(walls, t["walls"], z=float(z)) for z in slice_.heights()])
    else:
        wall_T = element_T
    wall_T = wall_T[np.isfinite(wall_T)]
    convection = t.get("convection")
    gas = [convection["gas_temperature"]] if convection else []
    temps = [t["initial_temperature"], t["inlet_temperature"], *wall_T.tolist(), *gas]
    T_low, T_high = min(temps), max(temps)
    enthalpy = heat_capacity.build(heat_capacity.specific_heat(p["specific_heat"]), T_low, T_high)

    def htc_table(mode) -> Table2D:
        kind = mode.table[1]
        table = htc_tables[kind]
        lo, hi = table.temperature[0], table.temperature[-1]
        if T_low < lo or T_high > hi:
            raise ConfigError(
                f"thermal.htc_table.temperature_range: the scene reaches {T_low:.1f}-{T_high:.1f} K "
                f"but the {kind} table covers {lo:.1f}-{hi:.1f} K"
            )
        return table.uniform()

    radiation = sorted(m.name for m in modes_registry.modes if m.name in modes and m.table and m.table[0] == "rdf")
    if radiation and rdf_tables is None:
        raise ConfigError(f"thermal.rdf_table: needed for {radiation} but not given")
    phi = registry.solid_fractions(t["solid_fraction"])
    unresolved = sorted(region for region, value in phi.items() if registry.is_measured(value))
    if unresolved:  # dpht.thermal.stage reads them from the DEM run's summary first
        raise ConfigError(f"thermal.solid_fraction: {unresolved} measured by the DEM run, but no value was read for them")
    rad_coefficient = p["emissivity"] * 4 * math.pi * radius**2 * contact.STEFAN_BOLTZMANN

    def rdf_table(mode) -> Table1D:
        return _squared(getattr(rdf_tables, mode.table[1]), phi[mode.region], mode.cutoff_radii(t))

    T_grid = np.linspace(enthalpy.T0, enthalpy.T_max, 512)
    dT = T_grid[1] - T_grid[0]
    k_p = htc.solid_conductivity(p["conductivity"], T_grid)
    wall_cutoff = _largest(cutoffs, modes, [m.name for m in modes_registry.side("pw")])
    conductivity = Table1D(T_grid[0], dT, k_p)
    setting = Setting(conductivity, w["conductivity"], rad_coefficient, htc_table, rdf_table)
    parameters, tables = {}, {}
    for mode in modes_registry.modes:
        coefficient, tables[mode.name] = laws[mode.name].setup(mode, setting) if mode.name in modes else (0.0, None)
        parameters[mode.name] = ModeParams(cutoffs[mode.name] ** 2 if mode.side == "pp" else cutoffs[mode.name], coefficient)
    tables = {name: table for name, table in tables.items() if table is not None}
    surfaces = () if walls is None or wall_cutoff == 0.0 else wall_surfaces(walls, element_T, wall_kinds, wall_cutoff)
    model = ThermalModel(
        modes=modes,
        radius=radius,
        mass=mass,
        cutoffs=cutoffs,
        pair=Side(radius, contact.c_pp(p["youngs_modulus_dem"], p["youngs_modulus_real"]),
                  _largest(cutoffs, modes, [m.name for m in modes_registry.side("pp")]) ** 2),  # fmt: skip
        wall=Side(radius, contact.c_pw(p["poisson_ratio"], p["youngs_modulus_real"], p["youngs_modulus_dem"],
                                       w["poisson_ratio"], w["youngs_modulus_real"], w["youngs_modulus_dem"]),
                  wall_cutoff),  # fmt: skip
        styles=styles,
        laws=laws,
        parameters=parameters,
        tables=tables,
        conductivity=conductivity,
        enthalpy=enthalpy,
        initial_temperature=t["initial_temperature"],
        inlet_temperature=t["inlet_temperature"],
        max_substeps=t["max_substeps"],
        surfaces=surfaces,
        element_temperature=element_T,
        n_elements=0 if walls is None else len(walls.area),
        wall_temperature_at=wall_temperature_at,
        intraparticle=t.get("intraparticle", False),
        shell_count=int(t.get("shells", 10)),
        biot_threshold=float(t.get("biot_threshold", 0.1)),
        convection=Surface(float(convection["coefficient"]), float(convection["gas_temperature"])) if convection
        else NO_CONVECTION,
        temperature_range=(T_low, T_high),
        wall_range=(float(wall_T.min()), float(wall_T.max())) if wall_T.size else None,
        registry=modes_registry,
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


def wall_surfaces(walls: Walls, element_T: np.ndarray, wall_kinds: dict | None, cutoff: float) -> tuple[SurfaceIndex, ...]:
    """The wall surfaces a particle can take heat from (those with a Dirichlet element), each measured
    as the DEM saw it (see the module docstring); ``cutoff`` in m."""
    kinds = _checked_kinds(walls, wall_kinds)
    dirichlet = np.isfinite(element_T)
    ids = np.where(dirichlet, np.arange(len(walls)), -1)
    found = []
    for s, name in enumerate(walls.surface_names):
        on = walls.surface == s
        if not dirichlet[on].any():
            continue  # every nearest point would be adiabatic
        zones = [walls.zone_names[z] for z in np.unique(walls.zone[on])]
        if {kinds[z] for z in zones} == {"mesh"}:
            found.append(mesh_surface(name, walls.vertices[on], ids[on], cutoff))
            continue
        if {kinds[z] for z in zones} != {"primitive"}:
            raise DPHTError(f"wall surface {name!r}: the DEM used primitives for some of its zones and meshes for others ({kinds})")
        pieces = [p for p in walls.primitives if walls.primitive_surface(p) == s]
        heated = [z for z in zones if dirichlet[on & walls.zone_mask(z)].any()]
        zone_triangles = [(walls.vertices[on & walls.zone_mask(z)], ids[on & walls.zone_mask(z)]) for z in heated]
        piece_zone = [heated.index(p.zone) if p.zone in heated else -1 for p in pieces]
        found.append(primitive_surface(name, [p.segment for p in pieces], piece_zone, zone_triangles, cutoff))
    return tuple(found)


def _checked_kinds(walls: Walls, wall_kinds: dict | None) -> dict:
    """``wall_kinds`` checked against the wall table: the same zones, primitives where the DEM used them."""
    if wall_kinds is None:
        return dict.fromkeys(walls.zone_names, "mesh")
    if set(wall_kinds) != set(walls.zone_names) or not set(wall_kinds.values()) <= {"mesh", "primitive"}:
        raise DPHTError(
            f"the DEM run's wall zones {dict(wall_kinds)} (primitive or mesh each) differ from the wall table's "
            f"{list(walls.zone_names)}: the DEM and the wall table come from different geometries"
        )
    missing = sorted(z for z, kind in wall_kinds.items() if kind == "primitive" and z not in {p.zone for p in walls.primitives})
    if missing:
        raise DPHTError(
            f"the DEM collided particles with the exact surface of the wall zones {missing}, but the wall table "
            f"has no primitives for them (a wall table older than format {WALLS_FORMAT!r}?): rebuild the geometry stage"
        )
    return dict(wall_kinds)


def wall_temperatures(walls: Walls, conditions: dict, z: float | None = None) -> np.ndarray:
    """Temperature (K) of every element from its zone's condition; NaN for adiabatic elements.

    The expressions are evaluated at the element centroids, or with ``z`` (m) instead of the
    centroids' z: the height a slice travelling down the tube has reached (:mod:`dpht.thermal.slice`).
    """
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
        x, y, zc = walls.centroid[mask].T
        where = "every element centroid" if z is None else f"every element of the slice at z = {z:.6g} m"
        expression = parse(condition["temperature"], ("x", "y", "z"), key)
        temperature[mask] = expression.checked(f"a finite temperature > 0 K at {where} (x, y, z in m)",
                                               minimum=0.0, x=x, y=y, z=zc if z is None else np.full_like(zc, z))
    return temperature
