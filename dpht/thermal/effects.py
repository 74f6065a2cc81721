"""The registry of effects a scene may call for, and the decisions that switch them on or off.

``thermal.effects: auto`` (the default) simulates only the effects a scene calls for: every switch
left at ``auto`` is decided, and logged with its reason, in this order:

1. **By the config alone** (:func:`from_config`, here; the workflow's plan uses it to build no table
   and run no job that only a switched-off effect would need): a switch set to ``true`` or
   ``false`` is as set; an ``auto`` particle-wall mode is off where no wall zone has a temperature
   (no Dirichlet wall: particle-wall heat has nowhere to come from or go to), an ``auto`` gas-gap
   mode in a vacuum (``thermal.gas_pressure: 0``); with ``thermal.effects: all`` every other
   ``auto`` is on.
2. **By the scene's own data** (:mod:`dpht.thermal.screening`, the ``screening`` stage, on the first
   DEM frame, i.e. the settled bed): each remaining mode by its share of the conductance on its side
   (particle-particle or particle-wall) at the scene's coldest and hottest temperatures, off when the
   larger share is below ``thermal.screening_threshold`` (default 1%); resolved intra-particle
   conduction (``thermal.intraparticle: auto``) by the particles' Biot number
   (:func:`dpht.thermal.decisions.decide_intraparticle`).
3. **By the DEM run** (:func:`recycling`, in the thermal stage): recycling particles to the inlet
   temperature only where particles crossed a recycling boundary.

Every decision is a :class:`Decision` (on/off, the estimate behind it, the threshold, a reason),
written to the thermal summary (``effects``) and the variant's report table. No numba:
:mod:`dpht.config` and :mod:`dpht.plan` import it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from dpht.closures import htc
from dpht import defaults
from dpht.errors import ConfigError
from dpht.thermal import modes

AUTO = "auto"
ALL = "all"  # thermal.effects: every switch left at auto is on (the behaviour before screening existed)


@dataclass(frozen=True)
class Effect:
    name: str  # the switch (a mode name, "intraparticle") or the effect ("recycling")
    key: str | None  # the config key that sets it, None for one decided by the DEM run alone
    rule: str  # what decides an auto switch from data: "share", "biot" (screening stage), "crossings" (thermal stage)
    description: str


EFFECTS: tuple[Effect, ...] = (
    *(Effect(m.name, f"thermal.modes.{m.name}", "share", m.description) for m in modes.MODES),
    Effect("intraparticle", "thermal.intraparticle", "biot", "resolved intra-particle conduction (ParScale)"),
    Effect("recycling", None, "crossings", "particles re-entering at the inlet temperature across the recycled axis"),
)
BY_NAME = {e.name: e for e in EFFECTS}
SCREENED = tuple(e.name for e in EFFECTS if e.rule in ("share", "biot"))  # what the screening stage decides
RADIATION = modes.needing("rdf")


@dataclass(frozen=True)
class Decision:
    effect: str
    on: bool
    reason: str
    setting: object = AUTO  # the config's value of the switch (True, False, "auto"), or None
    by: str = "config"  # "config", "screening" (the scene's first frame) or "dem" (the DEM run)
    estimate: float | None = None  # the number decided on: a share of the conductance, a Biot number, crossings
    threshold: float | None = None

    def record(self) -> dict:
        return asdict(self)

    def line(self) -> str:
        """One log line, e.g. ``pp_radiation: off - 0.3% of the pair conductance at T_max = 420 K``."""
        return f"{self.effect}: {'on' if self.on else 'off'} - {self.reason}"


def switch(thermal: dict, name: str):
    """The config's value of effect ``name``'s switch: True, False or "auto"."""
    if name == "intraparticle":
        return defaults.setting(thermal, "thermal.intraparticle")
    return defaults.setting(defaults.setting(thermal, "thermal.modes"), f"thermal.modes.{name}")


def has_dirichlet_wall(thermal: dict, zones=None) -> bool:
    """Whether a wall zone (of ``zones``, the geometry's, where given) has a temperature."""
    return any(bc != "adiabatic" and (zones is None or zone in zones) for zone, bc in thermal["walls"].items())


def from_config(thermal: dict, zones=None) -> dict[str, Decision | None]:
    """Every screened effect's decision from the ``thermal`` config section alone, None where the
    scene's data must decide (the screening stage). ``zones``: the geometry's wall zones."""
    everything = defaults.setting(thermal, "thermal.effects") == ALL
    decisions: dict[str, Decision | None] = {}
    for name in SCREENED:
        setting = switch(thermal, name)
        side = modes.BY_NAME[name].side if name in modes.BY_NAME else None
        if setting is True or setting is False:
            decisions[name] = Decision(name, setting, "set in the config", setting)
        elif side == "pw" and not has_dirichlet_wall(thermal, zones):
            decisions[name] = Decision(name, False, "no wall zone has a temperature (thermal.walls): particle-wall "
                                                    "heat has nowhere to flow", setting)  # fmt: skip
        elif name in modes.needing("htc") and not htc.gas_conducts(thermal):
            decisions[name] = Decision(name, False, "no gas to conduct (thermal.gas_pressure = 0 Pa)", setting)
        elif everything:
            decisions[name] = Decision(name, True, "thermal.effects: all", setting)
        else:
            decisions[name] = None
    return decisions


def pending(decisions: dict) -> tuple[str, ...]:
    """The effects the config leaves to the scene's data."""
    return tuple(name for name, d in decisions.items() if d is None)


def possible_modes(decisions: dict) -> frozenset:
    """The modes that are on, or may be once the data has decided: their tables are needed, or may be."""
    return frozenset(m for m in modes.NAMES if decisions[m] is None or decisions[m].on)


def resolve(thermal: dict, decisions: dict) -> dict:
    """``thermal`` with every decided switch set to its decision (``modes`` complete, booleans;
    ``intraparticle`` a boolean where it was auto). Raises if any is still undecided."""
    undecided = pending(decisions)
    if undecided:
        raise ValueError(f"effects {list(undecided)} are not decided")
    out = {**thermal, "modes": {m: decisions[m].on for m in modes.NAMES}}
    if out.get("intraparticle") == AUTO:
        out["intraparticle"] = decisions["intraparticle"].on
    return out


def all_on(thermal: dict) -> dict:
    """Overrides of a config's ``thermal`` section switching every ``auto`` on (modes, intraparticle):
    every effect the screening may switch off, back on (the screening check's second run)."""
    overrides = {"modes": {m: True for m, v in thermal["modes"].items() if v == AUTO}}
    if thermal.get("intraparticle") == AUTO:
        overrides["intraparticle"] = True
    return overrides


def check_decided(thermal: dict) -> None:
    """Refuse a thermal section whose modes are not all decided (``true`` or ``false``): the thermal
    model would take an ``auto`` for off."""
    undecided = [m for m in modes.NAMES if thermal["modes"].get(m) not in (True, False)]
    if undecided:
        raise ConfigError(f"thermal.modes: {undecided} are not decided (auto): the screening stage "
                          "(dpht.thermal.screening) decides them before the thermal stage runs")


def recycling(recycled, crossings: int, travelling_slice: bool = False) -> Decision:
    """Recycling, decided by the DEM run: on where an axis is recycled and particles crossed it
    (``crossings``: particles whose image along it differs between the run's first and last frame),
    except in a travelling slice (thermal.slice), which carries the same particles all the way down."""
    if travelling_slice:
        return Decision("recycling", False, "a travelling slice (thermal.slice) carries the same particles all the "
                        "way down: nothing re-enters", None, "config")  # fmt: skip
    if not recycled or not any(recycled):
        return Decision("recycling", False, "no axis of the DEM run is recycled", None, "dem")
    if not crossings:
        return Decision("recycling", False, "no particle crossed the recycled axis in the DEM run", None, "dem", 0)
    return Decision("recycling", True, f"{crossings} particles crossed the recycled axis in the DEM run", None, "dem",
                    float(crossings))  # fmt: skip


def table(decisions) -> list[dict]:
    """Rows for the report's table (one per effect): effect, on/off, decided by, estimate, threshold, reason."""
    return [{"effect": d["effect"], "on": d["on"], "by": d["by"], "estimate": d["estimate"], "threshold": d["threshold"],
             "reason": d["reason"]} for d in decisions]  # fmt: skip
