"""Arithmetic expressions from config files, parsed safely (no ``eval``) and evaluated on arrays.

Config values such as a specific heat ``"271.5 * T_C**0.1719"`` or a wall temperature profile
``"-995.70*z**3 + 381.44*z**2 - 657.96*z + 1057.8"`` (DPHT paper, Eq. 30) are parsed with
:mod:`ast` and interpreted node by node; only numbers, the declared variables, ``pi``, arithmetic,
comparisons and a fixed set of numpy functions are accepted.
"""

from __future__ import annotations

import ast
import operator
from dataclasses import dataclass

import numpy as np

from dpht.errors import ConfigError

_BINARY = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
_COMPARE = {ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal}
FUNCTIONS = {
    "sqrt": np.sqrt,
    "exp": np.exp,
    "log": np.log,
    "log10": np.log10,
    "sin": np.sin,
    "cos": np.cos,
    "tanh": np.tanh,
    "abs": np.abs,
    "min": np.minimum,
    "max": np.maximum,
    "where": np.where,
}
CONSTANTS = {"pi": np.pi}


@dataclass(frozen=True)
class Expression:
    """A parsed expression; call it with arrays for its variables, e.g. ``expr(T=T)``."""

    text: str
    variables: tuple[str, ...]
    key: str
    tree: ast.Expression

    def __call__(self, **values) -> np.ndarray:
        missing = set(self.variables) - set(values)
        if missing:
            raise TypeError(f"{self.key}: values missing for {sorted(missing)}")
        arrays = {k: np.asarray(v, dtype=np.float64) for k, v in values.items()}
        shape = np.broadcast_shapes(*(a.shape for a in arrays.values())) if arrays else ()
        with np.errstate(all="ignore"):
            result = _evaluate(self.tree.body, {**CONSTANTS, **arrays})
        return np.broadcast_to(np.asarray(result, dtype=np.float64), shape).copy()


def parse(value, variables, key: str) -> Expression:
    """Parse a config value (a number or an expression string) of the given variable names.

    ``key`` names the config entry in error messages, e.g. ``"particles.specific_heat"``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(f"{key}: expected a number or an expression string, got {value!r}")
    text = repr(float(value)) if not isinstance(value, str) else value
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as err:
        raise ConfigError(f"{key}: cannot parse expression {text!r}: {err.msg}") from None
    allowed = set(variables) | set(CONSTANTS)
    for node in ast.walk(tree):
        _check(node, allowed, key, text)
    return Expression(text, tuple(variables), key, tree)


def _check(node, allowed, key, text):
    where = f"{key}: expression {text!r}"
    if isinstance(node, ast.Name):
        if node.id not in allowed and node.id not in FUNCTIONS:
            raise ConfigError(f"{where}: unknown name {node.id!r} (allowed: {', '.join(sorted(allowed))})")
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS or node.keywords:
            name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise ConfigError(f"{where}: function {name!r} not allowed (allowed: {', '.join(sorted(FUNCTIONS))})")
    elif isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ConfigError(f"{where}: only numbers are allowed as constants, got {node.value!r}")
    elif isinstance(node, ast.Compare):
        if len(node.ops) != 1 or type(node.ops[0]) not in _COMPARE:
            raise ConfigError(f"{where}: only single comparisons <, <=, >, >= are allowed")
    elif isinstance(node, ast.BinOp):
        if type(node.op) not in _BINARY:
            raise ConfigError(f"{where}: operator {type(node.op).__name__} not allowed")
    elif isinstance(node, ast.UnaryOp):
        if type(node.op) not in _UNARY:
            raise ConfigError(f"{where}: operator {type(node.op).__name__} not allowed")
    elif not isinstance(node, (ast.Expression, ast.Load, *_BINARY, *_UNARY, *_COMPARE)):
        raise ConfigError(f"{where}: {type(node).__name__} is not allowed in expressions")


def _evaluate(node, env):
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_evaluate(node.left, env), _evaluate(node.right, env))
    if isinstance(node, ast.UnaryOp):
        return _UNARY[type(node.op)](_evaluate(node.operand, env))
    if isinstance(node, ast.Compare):
        return _COMPARE[type(node.ops[0])](_evaluate(node.left, env), _evaluate(node.comparators[0], env))
    if isinstance(node, ast.Call):
        return FUNCTIONS[node.func.id](*(_evaluate(arg, env) for arg in node.args))
    raise AssertionError(f"unchecked node {type(node).__name__}")
