"""The config's defaults, as the schema gives them (workflow/schemas/config.schema.yaml, the one place
a default is written), for code handed a config section the schema may not have filled: a stage's
function called directly (tests, benchmarks, the verification cases) rather than on the workflow's
validated config, or a key the stage spec leaves out where it changes nothing (``thermal.shells``
with uniform particles, :func:`dpht.config.thermal_spec`).

:mod:`dpht.config` imports some of the modules that read defaults, so this module reads the schema
file, once (:func:`schema`), below every module that asks it; :mod:`dpht.config` validates with it.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path

import yaml

SCHEMA_PATH = Path(__file__).resolve().parent.parent / "workflow" / "schemas" / "config.schema.yaml"
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's, ten times faster, when built


@functools.cache
def schema() -> dict:
    """The config schema (read once; do not modify it)."""
    return yaml.load(SCHEMA_PATH.read_text(), Loader=SAFE_LOADER)  # noqa: S506 (a safe loader)


def default(key: str):
    """The schema's default of the dotted config ``key`` (``"thermal.checkpoint_frames"``); a copy.
    KeyError naming the key where the schema has no such key or gives it no default."""
    s = schema()
    node = s
    for part in key.split("."):
        node = node.get("properties", {}).get(part)
        if node is None:
            raise KeyError(f"{key}: not a key of the config schema")
    if "default" not in node and "$ref" in node:  # a shared definition's default ("#/$defs/switch")
        node = s["$defs"][node["$ref"].rsplit("/", 1)[1]]
    if "default" not in node:
        raise KeyError(f"{key}: the config schema gives no default")
    return copy.deepcopy(node["default"])


def setting(section: dict, key: str):
    """``section``'s value of the dotted config ``key`` (``section`` being the mapping that holds its
    last part), or the schema's default where the section leaves the key out."""
    name = key.rsplit(".", 1)[-1]
    return section[name] if name in section else default(key)
