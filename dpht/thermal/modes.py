"""The registry of heat-transfer modes: every list of modes in the project derives from :data:`MODES`.

Each mode of the DPHT paper (Section 3) is a named sub-model, in the spirit of LAMMPS's named
granular sub-models: its config switch ``thermal.modes.<name>``, whether it couples two particles
(``pp``) or a particle and a wall (``pw``), the equations it implements, its label in figures, how its
cutoff is found, which table it reads, and its *styles*: the named alternative closures of its
conductance where the literature has several (like LAMMPS GRANULAR's ``heat radius|area``), the
first the default. A style names its :class:`dpht.closures.conductance.Law` (a numba function of
the pair's geometry, temperature and parameters, and how its parameters and table are set up).
The config chooses a mode's style with ``thermal.styles.<mode>`` (:class:`Styles`); the schema
lists the modes that have alternatives, each with its styles' names, the default first.

From this registry come the kernels, composed from the enabled modes' laws in registry order
(:mod:`dpht.thermal.kernels`: one pair conductance and one wall counterpart for the explicit
kernel, the integrators' network and the screening alike), the parameters and tables of
:class:`dpht.thermal.model.ThermalModel`, the cutoffs, the tables the workflow builds
(:func:`needing`), the wall-heat columns of ``thermal.h5`` (attribute ``wall_modes``,
:data:`PW_MODES` in order), the figure labels and the synthetic test scenes. A test checks the
config schema's ``thermal.modes`` (names; each ``true``, ``false`` or ``auto``, the default, which
:mod:`dpht.thermal.effects` decides) against it.

Every mode is a conductance G (W/K) between two temperatures (K); its heat rate is G (T_j - T_i).
How to add one: docs/manual/adding-a-mode.md.

Pure Python, no numba: :mod:`dpht.config` imports it (a style's law is imported when first used).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Literal

from dpht.errors import ConfigError


@dataclass(frozen=True)
class Style:
    """One closure of a mode's conductance: its name, its law (``"module:attribute"`` of a
    :class:`dpht.closures.conductance.Law`, or the law itself) and the equations it implements."""

    name: str
    law: object
    equations: str
    description: str

    def resolve(self):
        """The :class:`dpht.closures.conductance.Law` (imported on first use)."""
        if not isinstance(self.law, str):
            return self.law
        module, attribute = self.law.split(":")
        return getattr(importlib.import_module(module), attribute)


@dataclass(frozen=True)
class Mode:
    name: str  # the switch under thermal.modes, and the name in outputs and logs
    side: Literal["pp", "pw"]  # particle-particle or particle-wall
    equations: str  # DPHT paper equations implemented
    label: str  # for figures
    description: str
    cutoff: float | str  # fixed cutoff in particle radii (contact: 2 centre-centre, 1 centre-wall),
    #                      or the thermal.* key that gives it in radii
    table: tuple[str, str] | None = None  # ("htc", "pfp"|"pfw") or ("rdf", "pp"|"pw"): the table it reads
    styles: tuple[Style, ...] = ()  # the closures of its conductance, the first the default

    def style(self, name: str | None = None) -> Style:
        """The style ``name`` (None: the default, the first)."""
        if name is None:
            return self.styles[0]
        found = [s for s in self.styles if s.name == name]
        if not found:
            raise KeyError(f"mode {self.name!r} has no style {name!r} (styles: {[s.name for s in self.styles]})")
        return found[0]

    @property
    def region(self) -> str:
        """The ``thermal.solid_fraction`` region whose value this mode's tables are read at: the
        bulk for PP modes, near the wall for PW modes (DPHT paper, Section 3.6)."""
        return "bulk" if self.side == "pp" else "near_wall"

    @property
    def cutoff_key(self) -> str | None:
        """``thermal.<key>`` giving the cutoff in radii, or None for a fixed one."""
        return self.cutoff if isinstance(self.cutoff, str) else None

    def cutoff_radii(self, thermal: dict) -> float:
        """The cutoff in particle radii (centre-centre for PP, centre-wall for PW) from the
        ``thermal`` section of the config."""
        return float(thermal[self.cutoff]) if isinstance(self.cutoff, str) else self.cutoff


_LAWS = "dpht.closures.conductance"

MODES: tuple[Mode, ...] = (
    Mode("pp_contact", "pp", "Eqs. 2-4", "PP conduction", "particle-particle contact conduction", 2.0, None, (
        Style("corrected", f"{_LAWS}:PP_CONTACT", "Eqs. 2-4", "2 k_s a, the contact radius corrected for the DEM's softening (c_PP)"),
        Style("dem", f"{_LAWS}:PP_CONTACT_DEM", "Eqs. 2, 4 with c_PP = 1", "2 k_s a, the DEM's own contact radius (as LAMMPS heat radius)"),
    )),
    Mode("pw_contact", "pw", "Eqs. 5-7", "PW conduction", "particle-wall contact conduction", 1.0, None, (
        Style("corrected", f"{_LAWS}:PW_CONTACT", "Eqs. 5-7", "contact radius corrected for the DEM's softening (c_PW)"),
        Style("dem", f"{_LAWS}:PW_CONTACT_DEM", "Eqs. 5-6 with c_PW = 1", "the DEM's own contact radius"),
    )),
    Mode("pfp", "pp", "Eqs. 8-17", "PFP conduction", "particle-fluid-particle conduction", "pfp_cutoff", ("htc", "pfp"), (
        Style("table", f"{_LAWS}:PFP", "Eqs. 8-17", "the tabulated gas-gap conductance at the real centre distance (Eq. 17)"),
    )),
    Mode("pfw", "pw", "Eqs. 18-24", "PFW conduction", "particle-fluid-wall conduction", "pfw_cutoff", ("htc", "pfw"), (
        Style("table", f"{_LAWS}:PFW", "Eqs. 18-24", "the tabulated gas-gap conductance at the real centre-wall distance (Eq. 24)"),
    )),
    Mode("pp_radiation", "pp", "Eq. 25", "PP radiation", "particle-particle radiation", "radiation_cutoff", ("rdf", "pp"), (
        Style("secant", f"{_LAWS}:PP_RADIATION", "Eq. 25", "eps A sigma D (T_j^4 - T_i^4), exact as a secant conductance"),
    )),
    Mode("pw_radiation", "pw", "Eq. 26", "PW radiation", "particle-wall radiation", "radiation_cutoff", ("rdf", "pw"), (
        Style("secant", f"{_LAWS}:PW_RADIATION", "Eq. 26", "eps A sigma D (T_w^4 - T_i^4), exact as a secant conductance"),
    )),
)


@dataclass(frozen=True)
class Registry:
    """A set of modes in order (the kernels' order on each side; the wall-heat columns are the PW
    modes in this order). :data:`REGISTRY` is the project's; :meth:`with_mode` extends it."""

    modes: tuple[Mode, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.modes)

    def side(self, side: str) -> tuple[Mode, ...]:
        """The modes of one side ("pp" or "pw"), in order."""
        return tuple(m for m in self.modes if m.side == side)

    def __getitem__(self, name: str) -> Mode:
        return next(m for m in self.modes if m.name == name)

    def enabled(self, switches: dict) -> frozenset:
        """The modes switched on in ``thermal.modes`` (``True``; a missing switch, and one still at
        ``auto`` - decided by :mod:`dpht.thermal.effects` before a model is built - are off)."""
        return frozenset(name for name in self.names if switches.get(name) is True)

    def wall_column(self, name: str) -> int:
        """Column of a particle-wall mode in ``/wall_heat`` and ``/element_heat``."""
        return tuple(m.name for m in self.side("pw")).index(name)

    def with_mode(self, mode: Mode) -> Registry:
        """This registry and ``mode`` after its modes."""
        if mode.name in self.names:
            raise ValueError(f"mode {mode.name!r} is registered already")
        return Registry(self.modes + (mode,))


REGISTRY = Registry(MODES)


@dataclass(frozen=True)
class Styles:
    """The style of every mode of a registry, as ``thermal.styles`` chooses them (a mode not named
    there: its default, the first). The thermal model's laws come from it (:func:`dpht.thermal.model.build`)."""

    chosen: tuple[Style, ...]  # one per mode of the registry, in registry order
    registry: Registry = REGISTRY

    @classmethod
    def of(cls, thermal: dict, registry: Registry = REGISTRY) -> Styles:
        """The styles ``thermal`` (a config's or a stage spec's thermal section) names. The schema
        checks a config's names first, with its file and line; a spec built otherwise (or a mode
        added to the registry) is checked here, ConfigError naming the key and the allowed names."""
        given = thermal.get("styles") or {}
        for name, style in given.items():
            if name not in registry.names:
                raise ConfigError(f"thermal.styles.{name}: not a heat-transfer mode; expected one of {list(registry.names)}")
            allowed = [s.name for s in registry[name].styles]
            if style not in allowed:
                raise ConfigError(f"thermal.styles.{name}: {style!r} is not a style of {name}; expected one of {allowed}")
        return cls(tuple(m.style(given.get(m.name)) for m in registry.modes), registry)

    def __getitem__(self, mode: str) -> Style:
        return self.chosen[self.registry.names.index(mode)]

    def changed(self) -> dict:
        """``{mode: style}`` of the modes not at their default style: what a stage's key holds
        (a run at the default styles keeps the key it had before styles could be chosen)."""
        return {m.name: s.name for m, s in zip(self.registry.modes, self.chosen) if s is not m.styles[0]}


def spec_styles(thermal: dict) -> dict:
    """The ``thermal.styles`` a stage's spec holds: the modes not at their default (see :meth:`Styles.changed`)."""
    return Styles.of(thermal).changed()
BY_NAME = {m.name: m for m in MODES}
NAMES = REGISTRY.names
PP_MODES = tuple(m.name for m in REGISTRY.side("pp"))  # the pair kernel's modes, in order
PW_MODES = tuple(m.name for m in REGISTRY.side("pw"))  # the wall kernel's; also the wall-heat columns
LABELS = {m.name: m.label for m in MODES}


def needing(table: str) -> tuple[str, ...]:
    """Names of the modes that read a ``table`` ("htc" or "rdf") table."""
    return tuple(m.name for m in MODES if m.table is not None and m.table[0] == table)


def reader(table: str, kind: str) -> Mode:
    """The mode that reads the ``kind`` part of a ``table`` table (e.g. "htc", "pfw"; "rdf", "pp")."""
    return next(m for m in MODES if m.table == (table, kind))


enabled = REGISTRY.enabled
wall_column = REGISTRY.wall_column


REGIONS = ("bulk", "near_wall")
MEASURED = "measured"  # a solid fraction the scene's DEM run measures (thermal.solid_fraction)


def solid_fractions(value) -> dict:
    """``thermal.solid_fraction`` as ``{"bulk": ..., "near_wall": ...}``: particle-particle modes
    use the bulk value, particle-wall modes the near-wall one (DPHT paper, Section 3.6). Each is a
    number or measured: :data:`MEASURED`, or in a stage's spec ``{"measured": <DEM key>, "region":
    <region>}`` (:func:`measured`)."""
    if isinstance(value, dict) and set(value) == set(REGIONS):
        return dict(value)
    return dict.fromkeys(REGIONS, value)


def is_measured(value) -> bool:
    """Whether a region's solid fraction is to be read from the DEM run (see :func:`solid_fractions`)."""
    return value == MEASURED or isinstance(value, dict) and MEASURED in value


def measured(value, region: str, dem: str | None):
    """A region's solid fraction as a stage's spec holds it: a number as it is; measured as
    ``{"measured": dem, "region": region}``, which puts the DEM run's key into the stage's key (the
    stage reads the value from that run's summary), or :data:`MEASURED` without a DEM run."""
    return {"measured": dem, "region": region} if is_measured(value) and dem is not None else value
