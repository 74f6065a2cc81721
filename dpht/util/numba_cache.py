"""numba's on-disk cache: the one module that uses its internals (``numba.core.caching``, 0.68).

Two uses: functions composed at run time (closures over other numba functions, as
:mod:`dpht.thermal.kernels` composes the heat-transfer modes) cached by the code they are composed
of (:func:`composed`), and whether the cache holds a module's kernels compiled from its present
source (:func:`holds`, for :mod:`dpht.cost`'s notice of a cold cache).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numba as nb
from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher


class CompositionCache(FunctionCache):
    """numba's cache of a composed function, keyed by the code it is composed of: numba's own key
    pickles the functions in the closure, with an id drawn afresh in every process, so a composed
    function would never be found and would compile in every process."""

    def _index_key(self, sig, codegen):
        return sig, codegen.magic_tuple(), hashlib.sha256(composition(self._py_func).encode()).hexdigest()


def composition(fn) -> str:
    """The code of ``fn`` and, recursively, of the numba functions and the values in its closure."""
    code = fn.__code__  # its constants and names too: an edited coefficient leaves the bytecode as it was
    parts = [fn.__module__, fn.__qualname__, code.co_code.hex(), repr(code.co_consts), repr(code.co_names)]
    for cell in fn.__closure__ or ():
        value = cell.cell_contents
        parts.append(composition(value.py_func) if isinstance(value, Dispatcher) else repr(value))
    return "(" + " ".join(parts) + ")"


def composed(**options):
    """``numba.njit(**options)`` for a composed function, cached (see :class:`CompositionCache`)."""

    def compile(fn):
        dispatcher = nb.njit(**options)(fn)
        dispatcher._cache = CompositionCache(fn)
        return dispatcher

    return compile


def holds(fn) -> bool:
    """Whether numba's cache folder of ``fn``'s module (a Python function defined in it) holds an
    index of a function of that module no older than the module's source: a heuristic for a cold
    cache (a fresh checkout, an edited module)."""
    source = Path(fn.__code__.co_filename)
    folder = Path(FunctionCache(fn)._cache_path)
    written = source.stat().st_mtime
    return any(index.stat().st_mtime >= written for index in folder.glob(f"{source.stem}.*.nbi"))
