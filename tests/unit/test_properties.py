"""Property-based tests (hypothesis): random malformed inputs to the config validation and the
pre-flight check, the expression parser, the dump and HDF5 readers and the RDF command end in a
DPHTError (or the geometry's GeometryError) with a message, never in another exception, and write
nothing outside their output folder."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dpht import config
from dpht.__main__ import main
from dpht.dem.dumps import PositionsFile, read_dump, write_positions
from dpht.errors import USER_ERRORS
from dpht.figures import scene as figures
from dpht.plan import from_workflow
from dpht.util.expr import parse

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "config" / "config.yaml"
BASE = yaml.safe_load(DEFAULT.read_text())

# Deterministic (same examples on every run and machine) and no example database on disk.
settings.register_profile("dpht", derandomize=True, database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.load_profile("dpht")


def files_under(folder: Path) -> set[Path]:
    return {p for p in folder.rglob("*")}


# --- config validation and the pre-flight check ----------------------------------------------------

VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**30, 10**30), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12), st.sampled_from(["adiabatic", "air", "1/0", "9**9**9", "x +", "271.5 * T_C**0.1719", "..",
                                           "a b", "-1e-5", "5.0e6"]),
    st.lists(st.floats(-1e3, 1e3), max_size=3), st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


def leaf_paths(node, prefix=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield from leaf_paths(value, (*prefix, key))
    elif isinstance(node, list):
        for k, value in enumerate(node):
            yield from leaf_paths(value, (*prefix, k))
    yield prefix


PATHS = [p for p in leaf_paths(BASE) if p]


@st.composite
def mutated_configs(draw):
    """The default config with a few keys replaced by random values, deleted, or added."""
    cfg = copy.deepcopy(BASE)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PATHS))
        node = cfg
        try:
            for key in path[:-1]:
                node = node[key]
            action = draw(st.sampled_from(["replace", "delete", "add"]))
            if action == "replace":
                node[path[-1]] = draw(VALUES)
            elif action == "delete" and isinstance(node, dict):
                del node[path[-1]]
            elif isinstance(node, dict):
                node[draw(st.text(min_size=1, max_size=8))] = draw(VALUES)
        except (KeyError, IndexError, TypeError):  # an earlier mutation changed the shape here
            pass
    return cfg


@settings(max_examples=150)
@given(mutated_configs())
def test_config_validation_raises_only_config_errors(cfg):
    try:
        config.validate(cfg, "random.yaml")
    except USER_ERRORS as err:
        assert str(err)


NUMERIC_PATHS = [p for p in PATHS if isinstance(config._numbers(BASE).get(p[0]), dict) and p[0] != "variants"]
EXPRESSIONS_IN_CONFIG = ["1/0", "where(z > 0.03, 1/(z - 0.035), 900)", "1000 - 3e4 * z", "9**9**9", "sqrt(x)",
                         "600 + 0 * T", "T_C", "exp(z * 1e3)"]


@st.composite
def plausible_configs(draw):
    """The default config with one to three numbers scaled by up to 10^1.5 either way (or negated), or
    expressions swapped: mostly valid for the schema, so that the cross-field checks run."""
    cfg = config._numbers(copy.deepcopy(BASE))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(NUMERIC_PATHS))
        node = cfg
        for key in path[:-1]:
            node = node[key]
        value = node[path[-1]]
        if isinstance(value, bool):
            node[path[-1]] = not value
        elif isinstance(value, (int, float)):
            scaled = value * 10 ** draw(st.floats(-1.5, 1.5)) * draw(st.sampled_from([1, 1, 1, -1]))
            node[path[-1]] = round(scaled) if isinstance(value, int) else scaled
        elif isinstance(value, str):
            node[path[-1]] = draw(st.sampled_from(EXPRESSIONS_IN_CONFIG))
    return cfg


@settings(max_examples=60)
@given(st.one_of(plausible_configs(), plausible_configs(), plausible_configs(), mutated_configs()))
def test_the_workflows_plan_and_preflight_raise_only_user_errors(tmp_path_factory, cfg):
    folder = tmp_path_factory.mktemp("plan")
    override = folder / "override.yaml"
    try:
        override.write_text(yaml.safe_dump(cfg))
    except yaml.YAMLError:
        return
    before = files_under(folder)
    try:
        from_workflow(cfg, [override])
    except USER_ERRORS as err:
        assert str(err)
    assert files_under(folder) == before  # planning writes nothing


# --- expressions -------------------------------------------------------------------------------------

ATOMS = st.one_of(st.sampled_from(["x", "T", "T_C", "z", "pi", "q", "sqrt", "open"]),
                  st.floats(allow_nan=False, allow_infinity=False).map(repr), st.integers(-10**400, 10**400).map(str))
EXPRESSIONS = st.recursive(
    ATOMS,
    lambda inner: st.one_of(
        st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**", "//", "%", "<", ">=", "==", " and ", " if 1 else "]),
                  inner).map("".join),
        st.tuples(st.sampled_from(["sqrt", "exp", "log", "min", "max", "where", "abs", "tanh", "foo"]),
                  st.lists(inner, max_size=4)).map(lambda f: f"{f[0]}({', '.join(f[1])})"),
        inner.map(lambda e: f"-({e})"), inner.map(lambda e: f"[{e}]"),
    ),
    max_leaves=12,
)


@settings(max_examples=400)
@given(st.one_of(EXPRESSIONS, st.text(max_size=40), st.floats(), st.integers(-10**400, 10**400), st.none()))
def test_expressions_parse_or_raise_config_errors_and_evaluate_without_raising(text):
    try:
        expression = parse(text, ("x", "T", "T_C", "z"), "particles.specific_heat")
    except USER_ERRORS as err:
        assert "particles.specific_heat" in str(err)
        return
    values = np.array([-1.0, 0.0, 300.0, 1e300])
    result = expression(x=values, T=values, T_C=values, z=values)
    assert result.shape == values.shape and result.dtype == np.float64
    try:
        expression.checked("a positive number", minimum=0.0, x=values, T=values, T_C=values, z=values)
    except USER_ERRORS as err:
        assert "particles.specific_heat: expression" in str(err)


# --- LIGGGHTS dumps and the positions file ---------------------------------------------------------

HEADER = ["ITEM: TIMESTEP", "1000", "ITEM: NUMBER OF ATOMS", "3", "ITEM: BOX BOUNDS ff ff pp", "-0.005 0.005",
          "-0.005 0.005", "0 0.02", "ITEM: ATOMS id x y z ix iy iz"]
ATOMS_LINES = ["1 0.001 0.0 0.01 0 0 0", "2 0.0 0.002 0.012 0 0 -1", "3 -0.002 0.0 0.015 0 0 0"]
TOKENS = st.sampled_from(["nan", "inf", "-1", "1e999", "2.5", "x", "", "0", "3", "-0", "1e-400", "ITEM:", "pp"])


@st.composite
def damaged_dumps(draw):
    lines = [line.split() for line in HEADER + ATOMS_LINES]
    for _ in range(draw(st.integers(1, 4))):
        row = draw(st.integers(0, len(lines) - 1))
        action = draw(st.sampled_from(["token", "drop", "duplicate", "truncate"]))
        if action == "token" and lines[row]:
            lines[row][draw(st.integers(0, len(lines[row]) - 1))] = draw(TOKENS)
        elif action == "drop":
            del lines[row]
        elif action == "duplicate":
            lines.insert(row, list(lines[row]))
        else:
            lines = lines[:row]
        if not lines:
            break
    text = "\n".join(" ".join(line) for line in lines) + "\n"
    return draw(st.one_of(st.just(text.encode()), st.binary(max_size=64)))


@settings(max_examples=300)
@given(damaged_dumps())
def test_damaged_dumps_raise_dpht_errors(tmp_path_factory, content):
    path = tmp_path_factory.mktemp("dump") / "dump.1000.txt"
    path.write_bytes(content)
    try:
        frame = read_dump(path)
    except USER_ERRORS as err:
        assert str(path) in str(err)
        return
    assert np.all(np.isfinite(frame.positions)) and np.all(np.diff(frame.ids) > 0)
    write_positions(path.with_suffix(".h5"), [frame], radius=5e-4, density=3560.0, timestep=1e-5, dump_interval=1000)


def positions_file(path: Path) -> Path:
    from dpht.dem.dumps import DumpFrame

    lo, hi = np.array([-0.005, -0.005, 0.0]), np.array([0.005, 0.005, 0.02])
    ids = np.arange(1, 6)
    frames = [DumpFrame(500 * k, lo, hi, (False, False, True), ids, np.full((5, 3), 0.001 * k), np.zeros((5, 3), np.int32))
              for k in range(3)]  # fmt: skip
    write_positions(path, frames, radius=5e-4, density=3560.0, timestep=1e-5, dump_interval=500)
    return path


NAMES = ["ids", "step", "time", "positions", "image", "lost"]
ATTRS = ["format", "summary", "radius", "timestep", "box_lo", "box_hi", "periodic"]


@settings(max_examples=150)
@given(st.lists(st.tuples(st.sampled_from(["delete", "reshape", "retype", "attr", "truncate"]),
                          st.sampled_from(NAMES + ATTRS), st.integers(0, 10**6)), min_size=1, max_size=3))
def test_damaged_positions_files_raise_dpht_errors(tmp_path_factory, damage):
    path = positions_file(tmp_path_factory.mktemp("positions") / "positions.h5")
    for action, name, number in damage:
        if action == "truncate":
            data = path.read_bytes()
            path.write_bytes(data[: number % max(len(data), 1)])
            continue
        try:
            with h5py.File(path, "r+") as h5:
                if name in ATTRS and action in ("delete", "attr"):
                    if action == "delete" and name in h5.attrs:
                        del h5.attrs[name]
                    else:
                        h5.attrs[name] = ["dpht-positions-0", "{", "x", -1.0, number][number % 5]
                elif name in NAMES and name in h5:
                    data = h5[name][...]
                    del h5[name]
                    if action == "reshape":
                        h5[name] = data.reshape(-1)[: max(data.size - 1, 0)]
                    elif action == "retype":
                        h5[name] = data.astype("S8") if number % 2 else data.astype(np.float32)
        except OSError:  # already truncated: h5py cannot open it for the next damage
            pass
    try:
        with PositionsFile(path) as f:
            for frame in f.frames():
                assert frame.positions.shape == (f.n_particles, 3)
    except USER_ERRORS as err:
        assert str(path) in str(err)


@settings(max_examples=60)
@given(st.sampled_from(["ids", "time", "temperature", "wall_heat", "element_heat", "energy/wall", "dem_frame"]),
       st.sampled_from(["delete", "shrink", "modes", "wall_modes", "format"]))
def test_damaged_thermal_files_raise_dpht_errors(tmp_path_factory, name, action):
    folder = tmp_path_factory.mktemp("thermal")
    positions = positions_file(folder / "positions.h5")
    thermal = folder / "thermal.h5"
    with h5py.File(thermal, "w") as f:
        f.attrs.update(format="dpht-thermal-1", modes=json.dumps(["pw_contact"]), wall_modes=["pw_contact", "pfw",
                       "pw_radiation"], complete=True)  # fmt: skip
        f["ids"], f["dem_frame"], f["time"] = np.arange(1, 6), np.arange(3), np.arange(3) * 5e-3
        f["temperature"], f["wall_heat"] = np.full((3, 5), 300.0, np.float32), np.zeros((3, 3))
        f["element_heat"] = np.zeros((3, 4, 3), np.float32)
        for part in ("particles", "wall", "recycled"):
            f[f"energy/{part}"] = np.zeros(3)
    with h5py.File(thermal, "r+") as f:
        if action in ("delete", "shrink"):
            data = f[name][...]
            del f[name]
            if action == "shrink":
                f[name] = data[:-1]
        else:
            f.attrs[action] = {"modes": "not json", "wall_modes": 7, "format": "dpht-thermal-0"}[action]
    (folder / "out").mkdir()  # the stage runner makes its output folders
    before = files_under(folder)
    for draw in (lambda: figures.wall_heat_history(thermal, folder / "out" / "h.png"),
                 lambda: figures.temperature_profiles(positions, thermal, folder / "out" / "t.png")):
        try:
            draw()
        except USER_ERRORS as err:
            assert str(err)
    assert {p for p in files_under(folder) - before if p.parent.name != "out"} == set()


# --- python -m dpht rdf ------------------------------------------------------------------------------

NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32).map(repr),
                   st.sampled_from(["-5e-4", "0", "1e-3", "x", "", "-1", "1e999"]))


@settings(max_examples=80)
@given(lines=st.lists(st.lists(NUMBER, min_size=0, max_size=4).map(" ".join), max_size=6),
       radius=NUMBER, emissivity=NUMBER, rays=st.sampled_from(["1", "5", "0", "-3", "x"]),
       out=st.sampled_from(["rdf.csv", "missing/rdf.csv", ".", ""]),
       extra=st.lists(st.sampled_from([["--periodic", "xq"], ["--periodic", "x"], ["--box", "0", "0", "0", "1", "1", "1"],
                                       ["--wall-plane", "0", "0", "0", "0", "0", "0"], ["--max-overlap", "-1"],
                                       ["--wall-emissivity", "2"], ["--seed", "-1"]]), max_size=2))
def test_the_rdf_command_fails_with_a_message_and_writes_only_its_output(tmp_path_factory, lines, radius, emissivity,
                                                                        rays, out, extra):
    folder = tmp_path_factory.mktemp("rdf")
    bed = folder / "bed.txt"
    bed.write_text("\n".join(lines) + "\n")
    before = files_under(folder)
    argv = ["rdf", str(bed), "--radius", radius, "--emissivity", emissivity, "--rays", rays,
            "--out", str(folder / out), *(item for option in extra for item in option)]
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse: an unparsable number or option, with its usage message
        assert exit_.code == 2
        code = 2
    assert code in (0, 2)
    written = files_under(folder) - before
    assert written <= {folder / "rdf.csv"} and (code == 0) == bool(written)
    if code == 0:
        assert math.isfinite(float(radius)) and float(radius) > 0
