"""Messages for bad input: each is refused (or warned about) before any work, with no traceback, naming
where the value was set (file and line, or the command line's ``--config``, or the option), the key,
the value and what was expected.

One parametrised test over every case: generated from the config schema, every numeric key given NaN,
infinity and a value beyond each of its bounds, in a file merged over config/config.yaml as
``snakemake --configfile`` merges it (pure config validation); then the cases found by trying the
tiny scene (.test/config/config.yaml) as an adversary would, through ``dpht check``, ``snakemake -n``
and the other commands' options.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pytest
import trimesh
import yaml

from dpht import config
from dpht.__main__ import main
from dpht.errors import USER_ERRORS
from dpht.plan import from_workflow
from test_workflow import SNAKEMAKE, TEST_CONFIG

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "config" / "config.yaml"
SCHEMA = config.schema()
BASE = config.load(DEFAULT)  # the values of the lists a case changes one item of


@dataclass(frozen=True)
class Case:
    """``run(folder)`` returns what the user sees (the message, or the warnings of a run that goes on);
    each of ``expect`` (regular expressions) must be found in it, ``absent`` must not."""

    name: str
    run: Callable[[Path], str]
    expect: tuple[str, ...]
    absent: tuple[str, ...] = ()


def refused(call) -> str:
    """``call()``'s error (and anything printed on stderr), as the command line shows it."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            call()
    except USER_ERRORS as error:
        return err.getvalue() + f"dpht: error: {error}"
    return err.getvalue()


# --- every numeric key of the schema -----------------------------------------------------------


def resolve(node: dict) -> dict:
    while "$ref" in node:
        node = {**SCHEMA["$defs"][node["$ref"].rsplit("/", 1)[1]], **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def is_number(node: dict) -> bool:
    kind = node.get("type", [])
    return bool({"number", "integer"} & set(kind if isinstance(kind, list) else [kind]))


# A sample name for a mapping of free names (a wall zone, a variant), where its values are numbers.
FREE_NAMES = {("thermal", "walls"): "heated_wall", ("mixer_study", "paper"): "flat_plate"}


def numeric_keys(node=SCHEMA, path=(), tag=None):
    """(key path, its schema, the mixer type it belongs to) of every number the schema asks for."""
    node = resolve(node)
    if is_number(node):
        yield path, node, tag
        return
    alternatives = [resolve(a) for a in node.get("oneOf", [])]
    yield from ((path, a, tag) for a in alternatives[:1] if is_number(a))  # solid_fraction: a number or ...
    yield from ((path, a, tag) for a in alternatives[1:] if is_number(a) and not is_number(alternatives[0]))
    for alternative in (a for a in alternatives if "properties" in a):
        yield from numeric_keys(alternative, path, alternative["properties"].get("type", {}).get("const", tag))
    for key, sub in node.get("properties", {}).items():
        yield from numeric_keys(sub, (*path, key), tag)
    if isinstance(node.get("items"), dict):
        yield from numeric_keys(node["items"], (*path, 0), tag)
    if isinstance(node.get("additionalProperties"), dict) and path in FREE_NAMES:
        yield from numeric_keys(node["additionalProperties"], (*path, FREE_NAMES[path]), tag)


MIXERS = {
    "flat_plate": {"type": "flat_plate", "height": 0.02, "thickness": 5e-4, "opening": 0.65},
    "radial": {"type": "radial", "height": 0.02, "outlet_diameter": 3.3e-3, "angle": 45.0, "wall_thickness": 1.5e-4,
               "n_tubes": 4, "tube_diameter": 1.5e-3, "inclination": 78.0, "tube_inlet_radius": 2.5e-3},
    "stl": {"type": "stl", "file": "mixer.stl"},
}
# The structures a key lives in that config/config.yaml does not have (or has in another form).
SAMPLES = {
    ("particles", "conductivity"): {"temperature": [250.0, 1400.0], "conductivity": [2.0, 2.5]},
    ("thermal", "gas"): {"temperature": [200.0, 1500.0], "conductivity": [0.02, 0.06]},
    ("thermal", "solid_fraction"): {"bulk": 0.6, "near_wall": 0.54},
    ("thermal", "convection"): {"coefficient": 10.0, "gas_temperature": 300.0},
    ("thermal", "frozen_bed"): {"duration": 1.0, "step": 0.1},
    ("thermal", "slice"): {"inlet_height": 0.05, "distance": 0.1},
    ("dem", "drive"): {"velocity": 0.01},
    ("chain", "cuts"): [0.01],
}


def put(tree: dict, path: tuple, value) -> None:
    """Set ``path`` in ``tree``, each key along it moved last (so it is the file's last line)."""
    for key in path[:-1]:
        if isinstance(tree, list):
            tree = tree[key]
            continue
        child = tree.pop(key, {})
        tree[key] = child
        tree = child
    if isinstance(tree, dict):
        tree.pop(path[-1], None)
    tree[path[-1]] = value


def get(tree, path: tuple):
    for key in path:
        tree = tree[key]
    return tree


def schema_case(path: tuple, node: dict, tag: str | None, value) -> Case:
    """``value`` at ``path`` in an override file over config/config.yaml (with the structures the
    key lives in): refused at the file's last line, where the key is."""
    override = {}
    for n in range(1, len(path)):
        sample = [MIXERS[tag]] if path[:n] == ("geometry", "mixers") else SAMPLES.get(path[:n])
        if sample is not None:
            put(override, path[:n], copy.deepcopy(sample))
    if isinstance(path[-1], int):  # one item of a list
        try:
            items = list(get(override, path[:-1]))
        except (KeyError, IndexError, TypeError):
            items = list(get(BASE, path[:-1]))
        items[path[-1]] = value
        put(override, path[:-1], items)
    else:
        put(override, path, value)
    text = yaml.safe_dump(override, sort_keys=False, default_flow_style=None, width=10**6)
    key = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")
    shown = str(value) if isinstance(value, float) and not math.isfinite(value) else repr(value)

    def run(folder: Path) -> str:
        file = folder / "override.yaml"
        file.write_text(text)
        return refused(lambda: config.load(DEFAULT, file))

    where = rf"override\.yaml:{len(text.splitlines())}: {re.escape(key)}: {re.escape(shown)} is [^\n]*expected"
    return Case(f"{key}={shown}" + (f" ({tag})" if tag else ""), run, (where,))


def out_of_range(node: dict) -> list:
    """A value below each lower bound and above each upper bound of a number's schema."""
    step = 1 if node.get("type") == "integer" else 1.0
    low = node.get("minimum", node.get("exclusiveMinimum"))
    high = node.get("maximum", node.get("exclusiveMaximum"))
    return ([low - step] if low is not None else []) + ([high + step] if high is not None else [])


SCHEMA_CASES = [schema_case(path, node, tag, value) for path, node, tag in numeric_keys()
                for value in (math.nan, math.inf, *out_of_range(node))]  # fmt: skip


# --- the tiny scene, tried as an adversary would -----------------------------------------------

TINY = TEST_CONFIG.read_text().replace("../tables/", f"{ROOT}/tables/")  # its RDF table, relative to .test/


def line(text: str, start: str) -> int:
    """The line of ``text`` (1-based) that starts with ``start``."""
    return next(n for n, s in enumerate(text.splitlines(), 1) if s.startswith(start))


def tiny(folder: Path, *edits: tuple[str, str], name="tiny.yaml") -> Path:
    """The tiny scene's config with each (old, new) text replaced, written to ``folder / name``."""
    text = TINY
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    (folder / name).write_text(text)
    return folder / name


def check(*edits, extra=()) -> Callable[[Path], str]:
    """``dpht check`` of the tiny scene with ``edits`` (no Snakemake dry run)."""
    def run(folder: Path) -> str:
        return cli(["check", str(tiny(folder, *edits)), *extra, "--no-jobs", "-d", str(folder)])

    return run


def cli(argv: list[str]) -> str:
    """What ``python -m dpht ARGV`` prints on stderr (argparse's refusals too)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.suppress(SystemExit):
        main(argv)
    return err.getvalue()


def snakemake_dry_run(*args: str, edits=()) -> Callable[[Path], str]:
    def run(folder: Path) -> str:
        tiny(folder, *edits)
        done = subprocess.run([*SNAKEMAKE, "--directory", str(folder), "-n", "--configfile", str(folder / "tiny.yaml"), *args],
                              capture_output=True, text=True, timeout=300)  # fmt: skip
        return done.stderr

    return run


def workflow_with(command_line: dict) -> Callable[[Path], str]:
    """The plan of the tiny scene with Snakemake's ``--config`` values (strings, as Snakemake reads them)."""
    def run(folder: Path) -> str:
        file = tiny(folder)
        merged = config.merge(yaml.safe_load(file.read_text()), command_line)
        return refused(lambda: from_workflow(merged, [file], [file], command_line))

    return run


def mixer(fields: str) -> tuple[str, str]:
    """The edit giving the tiny scene one mixer (on the line after mesh_size, MIXER_LINE)."""
    return "  mesh_size: 1.0\n", f"  mesh_size: 1.0\n  mixers: [{{{fields}}}]\n"


MIXER_LINE = line(TINY, "  mesh_size:") + 1
ADIABATIC_MIXER = ("    orifice: adiabatic\n", "    orifice: adiabatic\n    mixer: adiabatic\n")
CORES = os.cpu_count() or 1


def ring_in_millimetres(folder: Path) -> str:
    mesh = trimesh.creation.annulus(r_min=2.0, r_max=3.5, height=1.0, sections=24)  # mm, inside the 8 mm tube
    mesh.apply_translation([0.0, 0.0, 12.0])
    mesh.export(folder / "ring.stl")
    return check(mixer("type: stl, file: ring.stl"), ADIABATIC_MIXER)(folder)


def folder_as_stl(folder: Path) -> str:
    (folder / "ring.stl").mkdir()
    return check(mixer("type: stl, file: ring.stl"), ADIABATIC_MIXER)(folder)


def scene_without_variants(study: str, section: str) -> Callable[[Path], str]:
    """The tiny scene asking for ``study``, whose ``section`` names a copy of it without variants."""
    def run(folder: Path) -> str:
        tiny(folder, ("variants:\n  base: {}", "variants: {}"), name="scene.yaml")
        return check(("variants:", f"studies: [{study}]\n{section}: {{scene: scene.yaml}}\nvariants:"))(folder)

    return run


def study_overrides(study: str, block: str) -> Callable[[Path], str]:
    """The tiny scene asking for ``study`` whose section (``block``, YAML lines after ``scene:``)
    names a copy of it as its scene and overrides it."""
    def run(folder: Path) -> str:
        tiny(folder, name="scene.yaml")
        return check(("variants:", f"studies: [{study}]\n{block}variants:"))(folder)

    return run


def study_line(block: str, start: str) -> str:
    """``tiny.yaml:<line>:`` of the line of ``block`` (inserted by :func:`study_overrides`) starting with ``start``."""
    return rf"tiny\.yaml:{line(TINY, 'variants:') + 1 + line(block, start) - 1}:"


SCREENED_SCENE = "screening_check:\n  scene: scene.yaml\n  scenes:\n    cold:\n      particles:\n        diameter: -1.0\n"
SHORT_SCENE = "accuracy:\n  scene: scene.yaml\n  short_scene:\n    dem:\n      timestep: .nan\n"


def rays(count: str) -> Callable[[Path], str]:
    def run(folder: Path) -> str:
        (folder / "bed.txt").write_text("0 0 0\n0.003 0 0\n")
        return cli(["rdf", str(folder / "bed.txt"), "--radius", "1e-3", "--emissivity", "0.8", "--rays", count,
                    "--out", str(folder / "rdf.csv")])  # fmt: skip

    return run


def calibrate(*options: str) -> Callable[[Path], str]:
    def run(folder: Path) -> str:
        text = cli(["calibrate-orifice", str(tiny(folder)), "--target", "0.008", "--workdir", str(folder / "trials"),
                    *options])  # fmt: skip
        return text + ("\n(trials started)" if (folder / "trials").exists() else "")

    return run




def at(start: str) -> str:
    """``tiny.yaml:<line>:`` of the tiny scene's line that starts with ``start``."""
    return rf"tiny\.yaml:{line(TINY, start)}:"


SPECIAL_CASES = [
    Case("variants {} in the accuracy study's scene", scene_without_variants("accuracy", "accuracy"),
         (r"tiny\.yaml:\d+: accuracy\.scene: .*scene\.yaml names no variant \(variants: \{\}\); the study runs the "
          r"scene's variants, or its first: give one",)),
    Case("variants {} in the mixer study's scene", scene_without_variants("mixers", "mixer_study"),
         (r"tiny\.yaml:\d+: mixer_study\.scene: .*scene\.yaml names no variant",)),
    Case("variants {} in the Watkins reduction's scene", scene_without_variants("watkins_reduction", "watkins_reduction"),
         (r"tiny\.yaml:\d+: watkins_reduction\.scene: .*scene\.yaml names no variant",)),
    Case("variants {} and no study", check(("variants:\n  base: {}", "variants: {}")),
         (rf"warning: \S*{at('variants:')} variants: \{{\}} names no design variant and the run lists no study",)),
    Case("variants {} and no study, snakemake", snakemake_dry_run(edits=[("variants:\n  base: {}", "variants: {}")]),
         (r"tiny\.yaml:\d+: variants: \{\} names no design variant",)),
    Case("a screening-check scene's override out of range", study_overrides("screening_check", SCREENED_SCENE),
         (rf"{study_line(SCREENED_SCENE, '    cold:')} screening_check\.scenes\.cold: invalid config\n  "
          rf"\S*{study_line(SCREENED_SCENE, '        diameter:')} particles\.diameter: -1\.0 is less than or equal to the "
          r"minimum of 0",)),
    Case("the accuracy study's short scene .nan", study_overrides("accuracy", SHORT_SCENE),
         (rf"{study_line(SHORT_SCENE, '  short_scene:')} accuracy\.short_scene: invalid config\n  "
          rf"\S*{study_line(SHORT_SCENE, '      timestep:')} dem\.timestep: nan is not a finite number",), ("accuracy.knobs",)),
    Case("wall.conductivity .inf", check(("  conductivity: 14.5", "  conductivity: .inf")),
         (rf"{at('  conductivity: 14.5')} wall\.conductivity: inf is not a finite number; expected a number > 0",)),
    Case("particles.conductivity .inf", check(("  conductivity: 2.0", "  conductivity: .inf")),
         (rf"{at('  conductivity: 2.0')} particles\.conductivity: inf is not a finite number; expected a number > 0, "
          r"or a mapping with keys temperature, conductivity",), ("k_solid",)),
    Case("particles.diameter .nan", check(("  diameter: 1.0e-3", "  diameter: .nan")),
         (rf"{at('  diameter: 1.0e-3')} particles\.diameter: nan is not a finite number; expected a number > 0 "
          r"\(particle diameter in m\)",), ("particle_diameter",)),
    Case("particles.diameter .inf", check(("  diameter: 1.0e-3", "  diameter: .inf")),
         (rf"{at('  diameter: 1.0e-3')} particles\.diameter: inf is not a finite number",)),
    Case("particles.emissivity .nan", check(("  emissivity: 0.65", "  emissivity: .nan")),
         (rf"{at('  emissivity: 0.65')} particles\.emissivity: nan is not a finite number; expected a number > 0 and <= 1",),
         ("rdf_table",)),
    Case("--config override refused", snakemake_dry_run("--config", "dem={timestep: -1}"),
         (r"--config override \(command line\): dem\.timestep: -1 is less than or equal to the minimum of 0; expected a "
          r"number > 0",), (r"tiny\.yaml:\d+: dem\.timestep",)),
    Case("--config override .nan", workflow_with({"particles": {"diameter": ".nan"}}),
         (r"--config override \(command line\): particles\.diameter: nan is not a finite number",)),
    Case("--config override warned about", workflow_with({"dem": {"ranks": str(CORES + 62)}}),
         (rf"warning: --config override \(command line\): dem\.ranks = {CORES + 62}: this machine has {CORES} cores",)),
    Case("STL in millimetres", ring_in_millimetres,
         (rf"tiny\.yaml:{MIXER_LINE}: geometry\.mixers\[0\]\.file ring\.stl: .* so the file is probably in millimetres: "
          r"set geometry\.mixers\[0\]\.scale: 0\.001",)),
    Case("STL path is a folder", folder_as_stl,
         (rf"tiny\.yaml:{MIXER_LINE}: geometry\.mixers\[0\]\.file: ring\.stl is a folder; give the STL file in it",)),
    Case("mixer type flat_plat", check(mixer("type: flat_plat, height: 0.01, thickness: 0.0005, opening: 0.6"), ADIABATIC_MIXER),
         (rf"tiny\.yaml:{MIXER_LINE}: geometry\.mixers\[0\]\.type: 'flat_plat' is not allowed; expected one of "
          r"'flat_plate', 'radial', 'stl' \(did you mean 'flat_plate'\?\)",)),
    Case("dem.ranks above the cores", check(("  restart_interval: 4000\n", f"  restart_interval: 4000\n  ranks: {CORES + 62}\n")),
         (rf"warning: \S*tiny\.yaml:{line(TINY, '  restart_interval:') + 1}: dem\.ranks = {CORES + 62}: this machine has {CORES} "
          r"cores",)),
    Case("near-wall solid fraction beyond the built PW table",
         check(("  rdf_table:", "  # rdf_table:"), ("near_wall: measured", "near_wall: 0.58")),
         (rf"{at('  solid_fraction:')} thermal\.solid_fraction\.near_wall = 0\.58 is outside the near-wall solid fractions "
          r"the PW RDF table is built at .*, 0\.2-0\.55",)),
    Case("dpht check --cores 0", check(extra=("--cores", "0")), (r"argument --cores/-c: expected an integer >= 1, got '0'",)),
    Case("dpht rdf --rays 1e11", rays("1e11"),
         (r"--rays 100000000000 for 2 particles needs about [\d.e+]+ GiB of memory at once, more than the [\d.]+ GiB "
          r"available; use at most \d+ rays per particle",)),
    Case("dpht rdf --rays 1.5", rays("1.5"), (r"argument --rays: expected an integer >= 1, got '1\.5'",)),
    Case("calibrate-orifice --ranks 0", calibrate("--ranks", "0"),
         (r"argument --ranks: expected an integer >= 1, got '0'",), (r"trials started",)),
    Case("calibrate-orifice --flow-time nan", calibrate("--flow-time", "nan"),
         (r"argument --flow-time: expected a number > 0, got 'nan'",), (r"trials started",)),
    Case("calibrate-orifice --tolerance 1", calibrate("--tolerance", "1"),
         (r"argument --tolerance: expected a number > 0 and < 1, got '1'",), (r"trials started",)),
]  # fmt: skip


@pytest.mark.parametrize("case", SCHEMA_CASES + SPECIAL_CASES, ids=lambda case: case.name)
def test_bad_input_is_named(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = case.run(tmp_path)
    assert "Traceback" not in text, text
    for expected in case.expect:
        assert re.search(expected, text), f"{expected!r} not in:\n{text}"
    for absent in case.absent:
        assert not re.search(absent, text), f"{absent!r} in:\n{text}"


def test_every_numeric_key_of_the_schema_is_a_case():
    """The generator reaches into the study sections, the alternatives (a mixer's types, a gas table)
    and the free names (wall zones): a key added to the schema becomes cases by itself."""
    keys = {case.name.split("=")[0] for case in SCHEMA_CASES}
    assert {"particles.diameter", "wall.conductivity", "thermal.gas.collision_diameter", "geometry.mixers[0].n_tubes",
            "thermal.walls.heated_wall.temperature", "intraparticle_study.auto_on.diameter", "dem.drive.wall_stress",
            "thermal.solid_fraction.near_wall", "geometry.tube.heated[0]", "mixer_study.paper.flat_plate"} <= keys
    assert len(SCHEMA_CASES) > 250
