"""Verification harness: named cases that compare a model with an exact or reference solution.

Each physical model registers its cases with :func:`case`. A case function returns ``(error,
tolerance)`` in the case's ``unit``, or ``(error, tolerance, notes)`` with lines to print after the
summary; it passes when ``error <= tolerance``. A case that can write its numbers and figures takes
a keyword argument ``out`` (a folder, or None), which ``python -m dpht verify --out DIR`` sets. Cases
must be quick (seconds) so that ``python -m dpht verify`` checks an installation in about a
minute; the test suite runs every registered case too (tests/unit/test_verification.py). A case that
needs an external program (``requires``) is skipped, and says so, where the program is missing.
"""

from __future__ import annotations

import importlib
import inspect
import shutil
import time
from dataclasses import dataclass
from typing import Callable

# Modules whose import registers verification cases.
CASE_MODULES = ("dpht.verification.cases",)


@dataclass(frozen=True)
class Case:
    name: str
    description: str
    run: Callable[..., tuple]
    unit: str  # of the error and the tolerance, e.g. "relative", "K", "standard errors"
    requires: tuple[str, ...] = ()  # external programs, looked up on PATH

    @property
    def writes(self) -> bool:
        """The case writes files into an ``out`` folder when given one."""
        return "out" in inspect.signature(self.run).parameters

    def missing(self) -> list[str]:
        """The required programs that are not installed."""
        return [p for p in self.requires if shutil.which(p) is None]


_CASES: dict[str, Case] = {}


def case(name: str, description: str, unit: str = "relative", requires: tuple[str, ...] = ()):
    """Register ``func`` as the verification case ``name``; its error and tolerance are in ``unit``."""

    def register(func):
        if name in _CASES:
            raise ValueError(f"verification case {name!r} registered twice")
        _CASES[name] = Case(name, description, func, unit, tuple(requires))
        return func

    return register


def cases() -> dict[str, Case]:
    for module in CASE_MODULES:
        importlib.import_module(module)
    return dict(sorted(_CASES.items()))


@dataclass(frozen=True)
class Outcome:
    name: str
    error: float
    tolerance: float
    unit: str
    seconds: float
    skipped: str = ""  # why the case did not run (a missing program); empty when it ran
    notes: tuple[str, ...] = ()  # lines the case asks to print after the summary

    @property
    def passed(self) -> bool:
        return not self.skipped and bool(self.error <= self.tolerance)

    def line(self) -> str:
        if self.skipped:
            return f"SKIP  {self.name:<34s} {self.skipped}"
        return (
            f"{'PASS' if self.passed else 'FAIL'}  {self.name:<34s} error {self.error:10.3e}"
            f"  tolerance {self.tolerance:8.1e} {self.unit:<16s} ({self.seconds:5.1f} s)"
        )


def check(c: Case, out=None) -> Outcome:
    """Run one case (or skip it, naming the missing programs); ``out``: the folder for its files."""
    missing = c.missing()
    if missing:
        return Outcome(c.name, float("nan"), float("nan"), c.unit, 0.0, skipped=f"needs {', '.join(missing)} (not installed)")
    start = time.perf_counter()
    error, tolerance, *notes = c.run(out=out) if c.writes else c.run()
    return Outcome(c.name, float(error), float(tolerance), c.unit, time.perf_counter() - start,
                   notes=tuple(notes[0]) if notes else ())  # fmt: skip


def run(names: list[str] | None = None, echo=print, out=None) -> list[Outcome]:
    """Run the named cases (all when ``names`` is empty) and print one line each; cases that write
    files write them into ``out`` when given."""
    available = cases()
    unknown = [n for n in names or [] if n not in available]
    if unknown:
        raise KeyError(f"unknown verification case(s) {unknown}; available: {sorted(available)}")
    outcomes = []
    for name in names or list(available):
        outcome = check(available[name], out)
        echo(outcome.line())
        outcomes.append(outcome)
    return outcomes
