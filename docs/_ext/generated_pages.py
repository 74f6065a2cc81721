"""Pages of the manual written from the code at build time, so that they cannot drift from it.

- ``_generated/config_keys.md``: every key of ``workflow/schemas/config.schema.yaml``, one table per
  top-level section (key, type, unit, default, description), in the schema's order;
- ``_generated/cli_help.md``: ``dpht --help`` and the help of every subcommand, from the parser itself;
- ``_generated/verification_cases.md``: every case ``dpht verify`` runs, from its registry.

The pages that show them include these files (MyST ``{include}``). ``python docs/_ext/generated_pages.py``
writes them without Sphinx.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

import yaml

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
SCHEMA = ROOT / "workflow" / "schemas" / "config.schema.yaml"
OUT = DOCS / "_generated"

# Units a description may start with ("m, z of the plate's top face", "W/(m K)") or end with
# ("particle diameter in m"). Longest first, so that "m/s" is not read as "m".
UNITS = sorted(
    ["m", "s", "K", "Pa", "kg/s", "kg/m3", "m/s", "W/(m K)", "J/(kg K)", "W/(m2 K)", "degrees", "particle radii",
     "radii", "diameters", "relative", "h_conv, W/(m2 K)"],
    key=len,
    reverse=True,
)  # fmt: skip


@dataclass(frozen=True)
class KeyRow:
    """One row of a section's table: a key of the config and what the schema says of it."""

    key: str
    type: str
    unit: str
    default: str
    description: str


def _resolve(node: dict, defs: dict) -> dict:
    """The node with its ``$ref`` (to ``#/$defs/NAME``) merged under its own keywords."""
    if "$ref" not in node:
        return node
    target = _resolve(defs[node["$ref"].rsplit("/", 1)[1]], defs)
    merged = {k: v for k, v in target.items()}
    merged.update({k: v for k, v in node.items() if k != "$ref"})
    return merged


def _bounds(node: dict) -> str:
    parts = []
    for word, sign in (("minimum", "≥"), ("exclusiveMinimum", ">"), ("maximum", "≤"), ("exclusiveMaximum", "<")):
        if word in node:
            parts.append(f"{sign} {node[word]}")
    return ", ".join(parts)


def type_text(node: dict, defs: dict) -> str:
    """What values a key takes, in words: type, bounds, allowed values."""
    node = _resolve(node, defs)
    if "const" in node:
        return f"`{json.dumps(node['const'])}`"
    if "enum" in node:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in node["enum"])
    if "oneOf" in node:
        return " or ".join(type_text(alt, defs) for alt in node["oneOf"])
    kind = node.get("type")
    if isinstance(kind, list):
        text = " or ".join(kind)
    elif kind == "array":
        items = node.get("items", {})
        inner = type_text(items, defs) if items and "oneOf" not in _resolve(items, defs) else "mapping"
        count = ""
        if node.get("minItems") is not None and node.get("minItems") == node.get("maxItems"):
            count = f", {node['minItems']} items"
        elif "minItems" in node:
            count = f", at least {node['minItems']}"
        text = f"list of ({inner}){count}"
    elif kind == "object" or "properties" in node:
        text = "mapping"
    elif kind is None:
        text = "any"
    else:
        text = kind
    bounds = _bounds(node)
    return f"{text}, {bounds}" if bounds else text


def split_unit(description: str) -> tuple[str, str]:
    """(unit, the rest of the description) from a description that names its unit first or last."""
    text = " ".join(description.split())
    for unit in UNITS:
        if text == unit:
            return unit, ""
        for sep in (", ", "; ", ": ", " ("):
            if text.startswith(unit + sep):
                rest = text[len(unit) + len(sep) :]
                if sep == " (" and rest.endswith(")"):
                    rest = rest[:-1]
                return unit.split(", ")[-1], rest
        # "m above z = 0", "s of heating", "degrees from horizontal": the unit begins a phrase; keep it.
        if text.startswith(unit + " ") and (not unit.isalpha() or unit == "degrees" or len(unit) <= 2):
            return unit, text
        if text.endswith(" in " + unit):
            return unit, text[: -len(unit) - 4]
    return "", text


_SPECIAL = re.compile(r"([\\*_\[\]|<>])")


def _escape(text: str) -> str:
    """Markdown-safe table cell: special characters escaped outside `code spans`."""
    pieces = text.split("`")
    for i, piece in enumerate(pieces):
        pieces[i] = _SPECIAL.sub(r"\\\1", piece) if i % 2 == 0 else piece.replace("|", "\\|")
    return "`".join(pieces)


def _default_text(node: dict, name: str, required: list) -> str:
    if "default" in node:
        return f"`{json.dumps(node['default'], ensure_ascii=False)}`"
    return "required" if name in required else "(none)"


def rows(name: str, node: dict, defs: dict, required: list, prefix: str = "", parent: str = "") -> list[KeyRow]:
    """The rows of one key and of every key under it, depth first, in the schema's order.

    A key whose schema must stay a bare reference (the mode switches, which a test holds to
    ``{$ref: switch}``) is described in its parent's description, which names it: ``parent``.
    """
    resolved = _resolve(node, defs)
    key = f"{prefix}{name}"
    unit, description = split_unit(resolved.get("description", ""))
    if not (unit or description) and re.search(rf"\b{re.escape(name)}\b", parent):
        description = f"see `{prefix.rstrip('.')}`"
    out = [KeyRow(key, type_text(node, defs), unit, _default_text(resolved, name, required), description)]
    out += children(key, resolved, defs)
    return out


def children(key: str, node: dict, defs: dict) -> list[KeyRow]:
    """Rows of the keys a mapping (or a list of mappings, or a choice of them) holds."""
    node = _resolve(node, defs)
    out: list[KeyRow] = []
    for child, sub in node.get("properties", {}).items():
        out += rows(child, sub, defs, node.get("required", []), prefix=f"{key}.", parent=node.get("description", ""))
    extra = node.get("additionalProperties")
    if isinstance(extra, dict) and extra:
        out += rows("<name>", extra, defs, [], prefix=f"{key}.")
    for alt in node.get("oneOf", []):
        alt = _resolve(alt, defs)
        if "properties" in alt:
            kind = alt["properties"].get("type", {}).get("const")
            label = f"{key.removesuffix('[]')}[type={kind}]" if kind else key
            for child, sub in alt["properties"].items():
                if child != "type":
                    out += rows(child, sub, defs, alt.get("required", []), prefix=f"{label}.")
        elif "oneOf" not in node.get("properties", {}):
            out += children(key, alt, defs)
    items = node.get("items")
    if isinstance(items, dict):
        out += children(f"{key}[]", items, defs)
    return out


def schema_rows(schema: dict | None = None) -> dict[str, list[KeyRow]]:
    """Every top-level section of the config schema and its rows."""
    schema = schema if schema is not None else yaml.safe_load(SCHEMA.read_text())
    defs = schema.get("$defs", {})
    # A section's own row is its heading, so its table starts with the keys it holds.
    return {name: rows(name, node, defs, schema.get("required", []))[1:] for name, node in schema["properties"].items()}


def leaves_without_description(schema: dict | None = None) -> list[str]:
    """Keys that hold no other keys and whose schema gives no description."""
    found = []
    for section_rows in schema_rows(schema).values():
        for i, row in enumerate(section_rows):
            holds = i + 1 < len(section_rows) and section_rows[i + 1].key.startswith((row.key + ".", row.key + "["))
            if not holds and not (row.unit or row.description):
                found.append(row.key)
    return found


def config_keys_page() -> str:
    schema = yaml.safe_load(SCHEMA.read_text())
    defs = schema.get("$defs", {})
    lines = []
    for section, section_rows in schema_rows(schema).items():
        node = _resolve(schema["properties"][section], defs)
        lines += [f"# `{section}`", ""]
        status = "required" if section in schema.get("required", []) else "optional"
        summary = " ".join(node.get("description", "").split())
        lines += [_escape(f"{summary} ({status} section)" if summary else f"({status} section)"), ""]
        lines += ["| key | type | unit | default | description |", "|---|---|---|---|---|"]
        for row in section_rows:
            cells = [f"`{row.key}`", row.type, _escape(row.unit) or "–", row.default, _escape(row.description) or "–"]
            lines.append("| " + " | ".join(cell.replace("\n", " ") for cell in cells) + " |")
        lines.append("")
    return "\n".join(lines)


def cli_help_page() -> str:
    from dpht.__main__ import build_parser

    os.environ["COLUMNS"] = "100"
    parser = build_parser()
    parser.prog = "dpht"
    lines = ["# `dpht --help`", "", "```text", parser.format_help().rstrip(), "```", ""]
    commands = next(a for a in parser._actions if a.dest == "command")
    for name, sub in commands.choices.items():
        sub.prog = f"dpht {name}"
        lines += [f"# `dpht {name}`", "", "```text", sub.format_help().rstrip(), "```", ""]
    return "\n".join(lines)


def verification_cases_page() -> str:
    """Every case of ``dpht verify``, from the harness's own registry."""
    from dpht.verification import harness

    lines = ["| case | what it checks | unit of its error |", "|---|---|---|"]
    for name, case in harness.cases().items():
        lines.append(f"| `{name}` | {_escape(' '.join(case.description.split()))} | {_escape(case.unit)} |")
    return "\n".join(lines) + "\n"


def write_pages(out: Path = OUT) -> list[Path]:
    """Write the generated pages, touching a file only when its text changes (Sphinx rebuilds on mtime)."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    pages = (("config_keys.md", config_keys_page()), ("cli_help.md", cli_help_page()),
             ("verification_cases.md", verification_cases_page()))  # fmt: skip
    for name, text in pages:
        path = out / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        written.append(path)
    return written


def _on_builder_inited(app) -> None:
    write_pages()


def setup(app):
    app.connect("builder-inited", _on_builder_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}


if __name__ == "__main__":
    for page in write_pages():
        print(page)
