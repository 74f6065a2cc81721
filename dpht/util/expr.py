"""Arithmetic expressions from config files, parsed safely (no ``eval``) and evaluated on arrays.

Config values such as a specific heat ``"271.5 * T_C**0.1719"`` or a wall temperature profile
``"-995.70*z**3 + 381.44*z**2 - 657.96*z + 1057.8"`` (DPHT paper, Eq. 30) are parsed with
:mod:`ast` and interpreted node by node; only numbers, the declared variables, ``pi``, arithmetic,
comparisons and a fixed set of numpy functions are accepted. Every operation is numpy's on float64,
so ``1/0`` or ``9**9**9`` give inf and ``sqrt(-1)`` NaN instead of raising: :meth:`Expression.checked`
then names the expression, the value and the point where it is not what the config needs.
"""

from __future__ import annotations

import ast
import math
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
# name -> (function, number of arguments)
FUNCTIONS = {
    "sqrt": (np.sqrt, 1),
    "exp": (np.exp, 1),
    "log": (np.log, 1),
    "log10": (np.log10, 1),
    "sin": (np.sin, 1),
    "cos": (np.cos, 1),
    "tanh": (np.tanh, 1),
    "abs": (np.abs, 1),
    "min": (np.minimum, 2),
    "max": (np.maximum, 2),
    "where": (np.where, 3),
}
CONSTANTS = {"pi": np.pi}
MAX_LENGTH = 2000  # characters: a config expression is a formula, not a program
MAX_DEPTH = 60  # nesting levels of the syntax tree (the evaluation recurses once per level)
_SHOWN = 100  # characters of an expression quoted in a message


@dataclass(frozen=True)
class Expression:
    """A parsed expression; call it with arrays for its variables, e.g. ``expr(T=T)``."""

    text: str
    variables: tuple[str, ...]
    key: str
    tree: ast.Expression

    def __call__(self, **values) -> np.ndarray:
        """The expression's float64 values, broadcast over the arrays given (inf or NaN where an
        operation overflows or is undefined)."""
        missing = set(self.variables) - set(values)
        if missing:
            raise TypeError(f"{self.key}: values missing for {sorted(missing)}")
        arrays = {k: np.asarray(v, dtype=np.float64) for k, v in values.items()}
        shape = np.broadcast_shapes(*(a.shape for a in arrays.values())) if arrays else ()
        with np.errstate(all="ignore"):
            result = _evaluate(self.tree.body, {**CONSTANTS, **arrays})
        return np.broadcast_to(np.asarray(result, dtype=np.float64), shape).copy()

    def checked(self, expected: str, *, minimum: float | None = None, **values) -> np.ndarray:
        """The values at the points ``values`` (arrays of the variables), which must be finite and,
        with ``minimum``, greater than it; otherwise a ConfigError names the key, the expression,
        how many points fail and the first of them with its value, and says what was ``expected``."""
        result = self(**values)
        good = np.isfinite(result) & (result > minimum if minimum is not None else True)
        if not good.all():
            bad = np.flatnonzero(~good.ravel())
            first = np.unravel_index(bad[0], result.shape)
            point = ", ".join(f"{name} = {np.broadcast_to(np.asarray(v, float), result.shape)[first]:.6g}"
                              for name, v in values.items())  # fmt: skip
            raise ConfigError(
                f"{self.key}: expression {_quoted(self.text)} gives {float(result[first])!r} at {bad.size} of "
                f"{result.size} points, the first at {point or 'every point'}; expected {expected}"
            )
        return result


def parse(value, variables, key: str) -> Expression:
    """Parse a config value (a number or an expression string) of the given variable names.

    ``key`` names the config entry in error messages, e.g. ``"particles.specific_heat"``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(f"{key}: expected a number or an expression string, got {value!r}")
    if not isinstance(value, str):
        try:
            number = float(value)
        except OverflowError:  # an integer beyond float range
            number = math.inf
        if not math.isfinite(number):
            raise ConfigError(f"{key}: expected a finite number, got {_quoted(repr(value))}")
        text = repr(number)
    else:
        text = value
    if len(text) > MAX_LENGTH:
        raise ConfigError(f"{key}: expression of {len(text)} characters; at most {MAX_LENGTH} are allowed")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as err:
        raise ConfigError(f"{key}: cannot parse expression {_quoted(text)}: {err.msg}") from None
    except (ValueError, RecursionError, MemoryError) as err:  # null bytes; nesting the parser cannot take
        raise ConfigError(f"{key}: cannot parse expression {_quoted(text)}: {type(err).__name__}: {err}") from None
    if _depth(tree) > MAX_DEPTH:
        raise ConfigError(f"{key}: expression {_quoted(text)} is nested more than {MAX_DEPTH} levels deep")
    allowed = set(variables) | set(CONSTANTS)
    called = {id(node.func) for node in ast.walk(tree) if isinstance(node, ast.Call)}
    for node in ast.walk(tree):
        _check(node, allowed, called, key, text)
    return Expression(text, tuple(variables), key, tree)


def shifted(value, variable: str, offset: float, variables, key: str):
    """A config value (number or expression, :func:`parse`) with ``variable`` replaced by
    ``(variable + offset)``: the same function seen from coordinates moved by -``offset`` (a resolved
    segment's wall temperature in its own z, its bottom at the scene's z = offset). A number stays
    the number; the expression is checked as :func:`parse` checks it."""
    expression = parse(value, variables, key)
    if not isinstance(value, str) or offset == 0.0:
        return value

    class Shift(ast.NodeTransformer):
        def visit_Name(self, node):
            if node.id != variable:
                return node
            return ast.BinOp(ast.Name(variable, ast.Load()), ast.Add(), ast.Constant(float(offset)))

    tree = ast.fix_missing_locations(Shift().visit(expression.tree))
    return ast.unparse(tree)


def _quoted(text: str) -> str:
    return repr(text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "...")


def _depth(tree: ast.AST) -> int:
    """Depth of the syntax tree, without recursion (a parsed tree can be deeper than Python's stack)."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return deepest


def _check(node, allowed, called, key, text):
    """Refuse ``node`` unless it is allowed; ``called``: ids of the nodes that are called functions."""
    where = f"{key}: expression {_quoted(text)}"
    if isinstance(node, ast.Name):
        if node.id in FUNCTIONS and id(node) not in called:
            raise ConfigError(f"{where}: function {node.id!r} used without calling it")
        if node.id not in allowed and node.id not in FUNCTIONS:
            raise ConfigError(f"{where}: unknown name {node.id!r} (allowed: {', '.join(sorted(allowed))})")
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS or node.keywords:
            name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise ConfigError(f"{where}: function {name!r} not allowed (allowed: {', '.join(sorted(FUNCTIONS))})")
        arity = FUNCTIONS[node.func.id][1]
        if len(node.args) != arity:
            raise ConfigError(f"{where}: {node.func.id}() takes {arity} argument{'s' * (arity > 1)}, "
                              f"got {len(node.args)}")  # fmt: skip
    elif isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ConfigError(f"{where}: only numbers are allowed as constants, got {node.value!r}")
        if isinstance(node.value, int) and abs(node.value) > 2**1023:
            digits = int(node.value.bit_length() * math.log10(2))
            raise ConfigError(f"{where}: a number of about 10^{digits} is too large (at most about 1.8e308)")
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
        return np.float64(node.value)
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_evaluate(node.left, env), _evaluate(node.right, env))
    if isinstance(node, ast.UnaryOp):
        return _UNARY[type(node.op)](_evaluate(node.operand, env))
    if isinstance(node, ast.Compare):  # 1.0 or 0.0, so that the result takes part in arithmetic
        result = _COMPARE[type(node.ops[0])](_evaluate(node.left, env), _evaluate(node.comparators[0], env))
        return np.asarray(result, dtype=np.float64)
    if isinstance(node, ast.Call):
        return FUNCTIONS[node.func.id][0](*(_evaluate(arg, env) for arg in node.args))
    raise AssertionError(f"unchecked node {type(node).__name__}")
