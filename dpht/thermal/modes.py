"""The registry of heat-transfer modes: every list of modes in the project derives from :data:`MODES`.

Each mode of the DPHT paper (Section 3) is a named sub-model, in the spirit of LAMMPS's named
granular sub-models: its config switch ``thermal.modes.<name>``, whether it couples two particles
(``pp``) or a particle and a wall (``pw``), the equations it implements, its label in figures, how its
cutoff is found and which table it reads. From this registry come the kernels'
flag order (:data:`PP_MODES`, :data:`PW_MODES`) and parameter records
(:mod:`dpht.thermal.kernels`), the cutoffs of :class:`dpht.thermal.model.ThermalModel`, the tables
the workflow builds (:func:`needing`), the wall-heat columns of ``thermal.h5`` (attribute
``wall_modes``, :data:`PW_MODES` in order), the figure labels and the synthetic test scenes. A test
checks the config schema's ``thermal.modes`` (names; each ``true``, ``false`` or ``auto``, the
default, which :mod:`dpht.thermal.effects` decides) against it.

Every mode is a conductance G (W/K) between two temperatures (K); its heat rate is G (T_j - T_i).

Adding a mode means:

1. one :class:`Mode` entry below (its schema switch in ``workflow/schemas/config.schema.yaml`` and
   its line in ``config/config.yaml`` follow; the schema test names what is missing);
2. one pure numba scalar function of the conductance, in the style of :mod:`dpht.closures.contact`;
3. one kernel branch in :mod:`dpht.thermal.kernels` (``pair_conduction``, ``pair_radiation`` or ``wall_conductances``,
   which the rate kernels and the integrators' network share): a literal flag argument and a table
   argument, in registry order (through ``pair_rates``/``wall_rates`` and
   :mod:`dpht.thermal.network`'s kernels); a field named
   after the mode in that side's table record (``PairTables``/``WallTables``, which the kernels
   check against this registry at import) and its scalars in ``PairModes``/``WallModes``, filled in
   :func:`dpht.thermal.model.build`; and the branch calling the function of step 2 (a PW mode
   also gets its column of ``element_heat``);
4. its brute-force twin in :mod:`dpht.verification.reference`, which the kernel tests compare.

Pure Python, no numba: :mod:`dpht.config` imports it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


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


MODES: tuple[Mode, ...] = (
    Mode("pp_contact", "pp", "Eqs. 2-4", "PP conduction", "particle-particle contact conduction", 2.0),
    Mode("pw_contact", "pw", "Eqs. 5-7", "PW conduction", "particle-wall contact conduction", 1.0),
    Mode("pfp", "pp", "Eqs. 8-17", "PFP conduction", "particle-fluid-particle conduction", "pfp_cutoff", ("htc", "pfp")),
    Mode("pfw", "pw", "Eqs. 18-24", "PFW conduction", "particle-fluid-wall conduction", "pfw_cutoff", ("htc", "pfw")),
    Mode("pp_radiation", "pp", "Eq. 25", "PP radiation", "particle-particle radiation", "radiation_cutoff", ("rdf", "pp")),
    Mode("pw_radiation", "pw", "Eq. 26", "PW radiation", "particle-wall radiation", "radiation_cutoff", ("rdf", "pw")),
)

BY_NAME = {m.name: m for m in MODES}
NAMES = tuple(BY_NAME)
PP_MODES = tuple(m.name for m in MODES if m.side == "pp")  # the pair kernel's flags and record fields, in order
PW_MODES = tuple(m.name for m in MODES if m.side == "pw")  # the wall kernel's; also the wall-heat columns
LABELS = {m.name: m.label for m in MODES}


def needing(table: str) -> tuple[str, ...]:
    """Names of the modes that read a ``table`` ("htc" or "rdf") table."""
    return tuple(m.name for m in MODES if m.table is not None and m.table[0] == table)


def reader(table: str, kind: str) -> Mode:
    """The mode that reads the ``kind`` part of a ``table`` table (e.g. "htc", "pfw"; "rdf", "pp")."""
    return next(m for m in MODES if m.table == (table, kind))


def enabled(switches: dict) -> frozenset:
    """The modes switched on in ``thermal.modes`` (``True``; a missing switch, and one still at
    ``auto`` - decided by :mod:`dpht.thermal.effects` before a model is built - are off)."""
    return frozenset(name for name in NAMES if switches.get(name) is True)


def wall_column(name: str) -> int:
    """Column of a particle-wall mode in ``/wall_heat`` and ``/element_heat``."""
    return PW_MODES.index(name)


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
