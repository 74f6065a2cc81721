"""The package layout: dependencies between subpackages run in one direction (no import cycles),
``dpht.geometry`` depends on nothing else in ``dpht``, and only the CLI reaches the verification package."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Lowest first: a unit may import units of its own rank or below, never above. Units are the
# subpackages of dpht and its top-level modules; figures and radiation are siblings.
LAYERS = (
    ("dpht.geometry",),
    ("dpht.errors", "dpht.paths", "dpht.defaults"),
    ("dpht.util",),
    ("dpht.closures",),
    ("dpht.dem",),
    ("dpht.chain",),
    ("dpht.thermal",),
    ("dpht.figures", "dpht.radiation", "dpht.headline"),
    ("dpht.config",),
    ("dpht.accuracy",),
    ("dpht.studies",),
    ("dpht.preflight",),
    ("dpht.plan",),
    ("dpht.verification", "dpht.integrity", "dpht.cost", "dpht.export"),
    ("dpht.stages", "dpht.htc"),
    ("dpht.__main__",),
)
RANK = {unit: rank for rank, units in enumerate(LAYERS) for unit in units}
ONLY_CLI_IMPORTS = "dpht.verification"  # test oracles and synthetic scenes stay out of the workflow


def unit(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else module


def imports(path: Path, module: str, is_package: bool):
    """Absolute names of the project modules (or their attributes) that ``path`` imports,
    including imports inside functions."""
    package = module if is_package else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            names = [f"{base}.{a.name}" for a in node.names] if base == "dpht" else [base]
        else:
            continue
        yield from (n for n in names if n.split(".")[0] == "dpht" and n != "dpht")


def modules():
    for path in sorted((ROOT / "dpht").rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        yield path, ".".join(parts[:-1] if is_package else parts), is_package


def test_every_unit_has_a_layer():
    units = {unit(module) for _, module, _ in modules()} - {"dpht"}
    assert units <= set(RANK), f"add {sorted(units - set(RANK))} to LAYERS"


def test_dependencies_point_down_the_layers():
    upward = []
    for path, module, is_package in modules():
        here = unit(module)
        for name in imports(path, module, is_package):
            there = unit(name)
            if there != here and RANK.get(there, -1) > RANK.get(here, -1):
                upward.append(f"{path.relative_to(ROOT)}: {here} imports {name}")
    assert not upward, "\n".join(upward)


def test_only_the_cli_imports_the_verification_package():
    offenders = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path, module, is_package in modules()
        if unit(module) not in (ONLY_CLI_IMPORTS, "dpht.__main__")
        for name in imports(path, module, is_package)
        if unit(name) == ONLY_CLI_IMPORTS
    ]
    assert not offenders, "\n".join(offenders)


def test_geometry_depends_on_nothing_else_in_dpht():
    offenders = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path, module, is_package in modules()
        if unit(module) == "dpht.geometry"
        for name in imports(path, module, is_package)
        if unit(name) != "dpht.geometry"
    ]
    assert not offenders, "\n".join(offenders)
