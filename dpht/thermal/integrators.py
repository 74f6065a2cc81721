"""The registry of time integrators (``thermal.integrator``) and the automatic choice among them.

Every list of integrators derives from :data:`INTEGRATORS`: the config schema's enum of
``thermal.integrator`` (:data:`CHOICES`, checked by a test), the candidates of ``auto``, the log
lines and the thermal summary, the hard-case suite and ``benchmarks/integrators.py``.

Each integrator is a class with one interface, which the thermal stage calls once per frame::

    integrator = create(name, model, options)        # options: the thermal config section
    report = integrator.advance(frame, h, dt, frame_number, start=None)  # -> integrate.StepReport
    integrator.cost(stiffness)                      # estimated cost of a frame, in rate evaluations
    saved = integrator.checkpoint()                 # what it carries to the next frame (a flat dict)
    integrator.restore(saved)                       # on a fresh integrator: continue bitwise

``checkpoint`` returns a flat dict of numpy arrays and JSON values (the thermal stage stores it with
its State), so a run resumed from a checkpoint computes the same bits as an uninterrupted one:
what an integrator keeps from frame to frame that can change a result (the preconditioner of a
reused network, auto's view of which frames repeat a geometry) is in it, with its counts.

``advance`` advances the specific enthalpies ``h`` (J/kg, the positions file's order) in place over
``dt`` (s) on the frame's fixed geometry (:class:`dpht.thermal.integrate.Frame`, whose per-contact
wall element and distance arrays are the one wall input), conserving energy exactly; ``start``
optionally hands over the rates already evaluated at the frame's start temperatures. Explicit and
implicit (backward Euler) also take a resolved model's node enthalpies (``shells=``) and the
particle-gas convection; multirate takes neither (:data:`SHELLS`).

``auto`` (:class:`Auto`, the default) evaluates the rates at each frame's start, from them the
frame's stiffness spectrum (:class:`Stiffness`: the largest and typical ratio of a particle's
conductance sum to its heat capacity, times the step; for resolved particles the surface node's
effective capacity, :attr:`dpht.thermal.intraparticle.ShellGrid.outer`), and runs the registered
integrator (of :data:`SHELLS` for a resolved model or one with convection) with the lowest
estimated cost; it logs each change of choice with the numbers and counts the frames per
integrator for the summary. All registered integrators are stable at any step (explicit and
multirate by sub-stepping, implicit by construction), so the choice is one of cost.
"""

from __future__ import annotations

import importlib
import logging
from dataclasses import dataclass

import numpy as np

from dpht.defaults import setting

log = logging.getLogger("dpht")


@dataclass(frozen=True)
class Entry:
    name: str  # the value of thermal.integrator
    description: str
    order: int  # of accuracy in the step
    target: str  # "module:Class" implementing the interface above

    def load(self):
        module, cls = self.target.split(":")
        return getattr(importlib.import_module(module), cls)


INTEGRATORS: tuple[Entry, ...] = (
    Entry("explicit", "forward Euler with global sub-steps at the stiffest particle's limit (DPHT Eq. 1)", 1,
          "dpht.thermal.integrate:Explicit"),
    Entry("multirate", "forward Euler with power-of-two local sub-steps per particle, conservative pair by pair", 1,
          "dpht.thermal.multirate:Multirate"),
    Entry("implicit", "backward Euler or TR-BDF2 on the frame's conductance network (Picard then Newton, GMRES + AMG/Jacobi)", 1,
          "dpht.thermal.implicit:Implicit"),
)  # fmt: skip
BY_NAME = {e.name: e for e in INTEGRATORS}
NAMES = tuple(BY_NAME)
AUTO = "auto"
CHOICES = (AUTO, *NAMES)  # the schema's enum of thermal.integrator; "auto" is the default


@dataclass(frozen=True)
class Stiffness:
    """The stiffness spectrum of a frame: r_i = dt g_i / (m c_p,min) per particle (g_i its sum of
    conductances, W/K), the sub-steps explicit needs for particle i."""

    dt: float  # s
    largest: float  # max r_i
    typical: float  # median r_i
    multirate_work: float  # mean over particles of 2^l_i, l_i the particle's multirate level
    stiffest: int  # frame-order index of the particle with the largest r_i (-1 if none)
    reused: bool = False  # the same frame geometry as the previous frame (a frozen bed): no new assembly

    @classmethod
    def of(cls, g: np.ndarray, capacity: float, dt: float, reused: bool = False) -> Stiffness:
        if g.size == 0:
            return cls(dt, 0.0, 0.0, 1.0, -1, reused)
        r = dt * g / capacity
        levels = np.where(r > 1.0, np.ceil(np.log2(np.maximum(r, 1.0) * (1 + 1e-12))), 0.0)
        return cls(dt, float(r.max()), float(np.median(r)), float(np.mean(2.0**levels)), int(np.argmax(r)), reused)


# The integrators that advance resolved particles' nodes and the particle-gas convection
# (thermal.intraparticle, thermal.convection; :mod:`dpht.thermal.intraparticle`); implicit with
# backward Euler only for resolved particles. Multirate's per-particle levels have neither.
SHELLS = ("explicit", "implicit")


def requested(thermal: dict) -> str:
    """The integrator the thermal config section asks for (``thermal.integrator``)."""
    return setting(thermal, "thermal.integrator")


def check_intraparticle(thermal: dict) -> None:
    """ConfigError, before any work, when the thermal config section may resolve the particles
    (``intraparticle`` true or auto) or has particle-gas ``convection`` and asks for an integrator
    other than those of :data:`SHELLS` (``auto`` then chooses among them), or may resolve them and
    asks the implicit integrator for another scheme than backward Euler."""
    name = requested(thermal)
    resolving = setting(thermal, "thermal.intraparticle")
    needs = [f"thermal.intraparticle: {resolving}"] if resolving else []
    needs += ["thermal.convection"] if thermal.get("convection") else []
    from dpht.errors import ConfigError

    if needs and name not in (AUTO, *SHELLS):
        raise ConfigError(
            f"thermal.integrator: {name!r} cannot advance resolved particles or the particle-gas convection "
            f"({', '.join(needs)}); expected one of {[AUTO, *SHELLS]} (auto then chooses among {list(SHELLS)}), or "
            "switch them off"
        )  # fmt: skip
    scheme = setting(thermal.get("implicit") or {}, "thermal.implicit.scheme")
    if resolving and name in (AUTO, "implicit") and scheme != "backward_euler":
        raise ConfigError(
            f"thermal.implicit.scheme: {scheme!r} cannot advance resolved particles (thermal.intraparticle: "
            f"{resolving}, thermal.integrator: {name}); expected backward_euler"
        )


def create(name: str, model, thermal: dict | None = None):
    """The integrator ``name`` (one of :data:`CHOICES`) for ``model``; ``thermal`` is the thermal
    config section (its ``implicit`` options are passed on). A model with shells or particle-gas
    convection rejects integrators outside :data:`SHELLS` (:func:`check_intraparticle`)."""
    thermal = thermal or {}
    if name not in CHOICES:
        from dpht.errors import ConfigError

        raise ConfigError(f"thermal.integrator: {name!r} is not one of {list(CHOICES)}")
    if model.shells is not None or model.convection.coefficient > 0.0:
        check_intraparticle({"integrator": name, "intraparticle": model.shells is not None,
                             "convection": model.convection.coefficient > 0.0, "implicit": thermal.get("implicit")})  # fmt: skip
    if name == AUTO:
        return Auto(model, thermal)
    return BY_NAME[name].load()(model, thermal.get(name))


class Auto:
    """Per frame, the registered integrator with the lowest estimated cost for the frame's stiffness."""

    name = AUTO

    def __init__(self, model, thermal: dict | None = None):
        self.model = model
        general = model.shells is None and model.convection.coefficient == 0.0
        self.candidates = {e.name: create(e.name, model, thermal) for e in INTEGRATORS if general or e.name in SHELLS}
        self.explicit = self.candidates["explicit"]
        self.decisions: list[dict] = []  # each change of choice, with its numbers
        self._last = None
        self._frame = None
        self._key = None  # Frame.key of the last geometry (a frozen bed's is the same all along)

    def choose(self, stiffness: Stiffness) -> tuple[str, dict]:
        costs = {name: float(c.cost(stiffness)) for name, c in self.candidates.items()}
        return min(costs, key=lambda n: (costs[n], NAMES.index(n))), costs

    def advance(self, frame, h, dt, frame_number: int = 0, start=None, *, shells=None):
        from dpht.thermal import integrate

        rates = self.explicit.work(frame)
        T, mean = integrate.temperatures(self.model, h, frame.particles, shells)
        integrate.evaluate(self.model, frame, T, rates)
        start = integrate.Start(T, rates, mean)
        given = {} if shells is None else {"shells": shells}
        if dt == 0.0:
            return self.explicit.advance(frame, h, dt, frame_number, start, **given)
        grid = self.model.shells  # a resolved particle's surface node takes the surface heat first
        capacity = self.model.mass * self.model.enthalpy.cp_min * (grid.outer if grid is not None else 1.0)
        g = rates.g  # (explicit takes the particle-gas convection implicitly: it does not bound its step)
        # The same geometry as the last frame: the same object, or after a resume the same key (a
        # frozen bed's; a DEM frame a travelling slice comes back to is a new geometry, as it is here).
        reused = frame is self._frame or (self._frame is None and frame.key is not None and frame.key == self._key)
        self._frame, self._key = frame, frame.key
        # A frame explicit takes in one step is explicit's: nothing costs less than one evaluation,
        # so the spectrum is only computed when the choice changes (for the log).
        mild = g.size == 0 or dt * float(g.max()) <= capacity
        stiffness = None if mild and self._last == "explicit" else Stiffness.of(g, capacity, dt, reused)
        name, costs = ("explicit", None) if mild else self.choose(stiffness)
        if name != self._last:
            costs = costs or self.choose(stiffness)[1]
            decision = {"frame": frame_number, "integrator": name, "largest_ratio": stiffness.largest,
                        "typical_ratio": stiffness.typical, "multirate_work": stiffness.multirate_work,
                        "estimated_cost": costs}  # fmt: skip
            self.decisions.append(decision)
            log.info(
                "thermal.integrator auto: %s from frame %d (dt %.3g s; dt*g/(m c_p) largest %.3g, median %.3g; "
                "estimated cost in rate evaluations: %s)", name, frame_number, dt, stiffness.largest, stiffness.typical,
                ", ".join(f"{k} {v:.3g}" for k, v in costs.items()),
            )  # fmt: skip
            self._last = name
        return self.candidates[name].advance(frame, h, dt, frame_number, start, **given)

    def checkpoint(self) -> dict:
        saved = {"auto/last": self._last, "auto/key": self._key, "auto/decisions": self.decisions}
        for c in self.candidates.values():
            saved.update(c.checkpoint())
        return saved

    def restore(self, saved: dict) -> None:
        self._last, self._key = saved["auto/last"], saved.get("auto/key")
        self.decisions = list(saved["auto/decisions"])
        for c in self.candidates.values():
            c.restore(saved)

    @property
    def stats(self) -> dict:
        """Counts of every candidate that ran (iterations, micro-steps, ...)."""
        return {f"{name}.{k}": v for name, c in self.candidates.items() for k, v in getattr(c, "stats", {}).items()}


def summary(integrator, frames: dict) -> dict:
    """What the thermal summary records of the integrator: the one requested, the frames each
    registered integrator ran (``frames``), auto's decisions with their numbers, and the counts."""
    return {
        "requested": integrator.name,
        "frames": {name: int(frames.get(name, 0)) for name in NAMES},
        "decisions": list(getattr(integrator, "decisions", [])),
        "stats": {k: int(v) for k, v in getattr(integrator, "stats", {}).items()},
    }
