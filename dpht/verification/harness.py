"""Verification harness: named cases that compare a model with an exact or reference solution.

Each physical model registers its cases with :func:`case`. A case function takes no arguments and
returns ``(error, tolerance)``; the case passes when ``error <= tolerance``. Cases must be quick
(seconds) so that ``python -m dpht verify`` checks an installation in about a minute.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass
from typing import Callable

# Modules whose import registers verification cases.
CASE_MODULES = ("dpht.verification.cases",)


@dataclass(frozen=True)
class Case:
    name: str
    description: str
    run: Callable[[], tuple[float, float]]


_CASES: dict[str, Case] = {}


def case(name: str, description: str):
    """Register ``func`` as the verification case ``name``."""

    def register(func):
        if name in _CASES:
            raise ValueError(f"verification case {name!r} registered twice")
        _CASES[name] = Case(name, description, func)
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
    seconds: float

    @property
    def passed(self) -> bool:
        return bool(self.error <= self.tolerance)


def run(names: list[str] | None = None, echo=print) -> list[Outcome]:
    """Run the named cases (all when ``names`` is empty) and print one line each."""
    available = cases()
    unknown = [n for n in names or [] if n not in available]
    if unknown:
        raise KeyError(f"unknown verification case(s) {unknown}; available: {sorted(available)}")
    outcomes = []
    for name in names or list(available):
        start = time.perf_counter()
        error, tolerance = available[name].run()
        outcome = Outcome(name, float(error), float(tolerance), time.perf_counter() - start)
        echo(
            f"{'PASS' if outcome.passed else 'FAIL'}  {name:<34s} error {outcome.error:10.3e}"
            f"  tolerance {outcome.tolerance:8.1e}  ({outcome.seconds:5.1f} s)"
        )
        outcomes.append(outcome)
    return outcomes
