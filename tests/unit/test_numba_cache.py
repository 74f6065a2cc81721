"""The numba cache helper: a composed function's key follows the code it is composed of, it is
compiled once and loaded in a later process, and the cold-cache heuristic sees the module's index."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numba as nb

from dpht.util.numba_cache import composition

MODULE = '''
import numba as nb
from dpht.util.numba_cache import composed, holds

@nb.njit(cache=True, inline="always")
def piece(x):
    return 2.0 * x

def compose(c):
    @composed()
    def whole(x):
        return piece(x) + c
    return whole

def make():
    """Defined in this module, for holds()."""
'''

RUN = '''
import json, sys
import composed_module as m
before = m.holds(m.make)
whole = m.compose(3.0)
value = whole(1.0)
print(json.dumps({"before": before, "after": m.holds(m.make), "value": value,
                  "hits": sum(whole.stats.cache_hits.values()), "misses": sum(whole.stats.cache_misses.values())}))
'''


def _closure(c, scale):
    @nb.njit
    def piece(x):
        return scale * x

    def whole(x):
        return piece(x) + c

    return whole


def _other_piece(c):
    @nb.njit
    def piece(x):
        return 3.0 * x

    def whole(x):
        return piece(x) + c

    return whole


def test_the_key_follows_the_closure_values_and_the_code_of_its_pieces():
    assert composition(_closure(1.0, 2.0)) == composition(_closure(1.0, 2.0))
    assert composition(_closure(1.0, 2.0)) != composition(_closure(1.5, 2.0))  # a value in the closure
    assert composition(_closure(1.0, 2.0)) != composition(_closure(1.0, 2.5))  # a value in a piece's closure
    assert "3.0" in composition(_other_piece(1.0))  # a piece's constants, not only its bytecode


def test_a_composed_function_compiles_once_and_loads_in_the_next_process(tmp_path):
    (tmp_path / "composed_module.py").write_text(textwrap.dedent(MODULE))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}  # fmt: skip

    def run():
        done = subprocess.run([sys.executable, "-c", RUN], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
        return json.loads(done.stdout.strip().splitlines()[-1])

    first, second = run(), run()
    assert first == {"before": False, "after": True, "value": 5.0, "hits": 0, "misses": 1}
    assert second == {"before": True, "after": True, "value": 5.0, "hits": 1, "misses": 0}
    os.utime(tmp_path / "composed_module.py")  # an edited module: its index is older than its source
    assert run()["before"] is False
