"""Config checks shared by the tube and the mixers: every failure is a GeometryConfigError naming the key."""

from __future__ import annotations

import math
import numbers

from dpht.geometry.errors import GeometryConfigError


def keys(cfg, key: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> None:
    """``cfg`` must be a mapping holding all ``required`` keys and nothing outside ``optional``."""
    if not isinstance(cfg, dict):
        raise GeometryConfigError(f"{key} must be a mapping with keys {list(required)}, got {type(cfg).__name__}")
    missing = [k for k in required if k not in cfg]
    unknown = sorted(set(cfg) - set(required) - set(optional))
    if missing or unknown:
        raise GeometryConfigError(
            f"{key}: missing keys {missing}, unknown keys {unknown}; expected {list(required)}"
            + (f" and optionally {list(optional)}" if optional else "")
        )


def number(value, key: str, unit: str = "m") -> float:
    """``value`` as a float; it must be a finite real number (not a bool)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise GeometryConfigError(f"{key} must be a finite number ({unit}), got {value!r}")
    return float(value)


def positive(value, key: str, unit: str = "m") -> float:
    value = number(value, key, unit)
    if value <= 0:
        raise GeometryConfigError(f"{key} must be positive ({unit}), got {value}")
    return value


def between(value, key: str, low: float, high: float, unit: str) -> float:
    """A number strictly inside (low, high)."""
    value = number(value, key, unit)
    if not low < value < high:
        raise GeometryConfigError(f"{key} must lie strictly between {low} and {high} ({unit}), got {value}")
    return value


def count(value, key: str) -> int:
    """A non-negative integer."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        raise GeometryConfigError(f"{key} must be a non-negative integer, got {value!r}")
    return int(value)
