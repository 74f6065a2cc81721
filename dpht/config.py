"""Load and validate the workflow config; derive the parameters each stage depends on.

The config (``config/config.yaml``) is checked against ``workflow/schemas/config.schema.yaml``.
Errors name the file and the dotted key, and suggest the closest key for a misspelling. Optional
keys take the schema's defaults. Each stage receives only the keys it depends on (see the
``*_spec`` functions), so Snakemake re-runs a stage exactly when one of *its* parameters changes:
a thermal parameter re-runs the thermal stage and figures, never gmsh or LIGGGHTS.

``variants`` maps a design name to overrides merged into the base config (issue: mixers), so a
variant is a few lines of YAML; stages a variant does not change share their cached outputs.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import re
from pathlib import Path

import jsonschema
import yaml

from dpht.closures.rdf import FORMAT as RDF_FORMAT  # in the RDF tables' cache key: a new format rebuilds them
from dpht.errors import ConfigError
from dpht.thermal import modes

SCHEMA_PATH = Path(__file__).resolve().parent.parent / "workflow" / "schemas" / "config.schema.yaml"


def load(path: str | Path) -> dict:
    """Read and validate a config file; returns the config with defaults filled in."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {path} does not exist")
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from None
    return validate(raw, source=str(path))


def schema() -> dict:
    return yaml.safe_load(SCHEMA_PATH.read_text())


def validate(config, source: str = "config") -> dict:
    """Validate ``config`` (a mapping) and every variant; returns a copy with defaults filled."""
    if not isinstance(config, dict):
        raise ConfigError(f"{source}: expected a mapping of sections at the top level, got {type(config).__name__}")
    full = _numbers(copy.deepcopy(config))
    s = schema()
    _fill_defaults(full, s)
    _check(full, s, source)
    for name in full.get("variants", {}):
        _check(variant(full, name), s, f"{source} (variant {name!r})")
    return full


# YAML 1.2 floats; PyYAML (YAML 1.1, also used by Snakemake) reads "5.0e6" as a string.
_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def _numbers(node):
    """Turn strings that are YAML 1.2 numbers into floats, so `5.0e6` means what it says."""
    if isinstance(node, dict):
        return {k: _numbers(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_numbers(v) for v in node]
    if isinstance(node, str) and _FLOAT.match(node.strip()):
        return float(node)
    return node


def variant(config: dict, name: str) -> dict:
    """The config of design variant ``name``: the base config with the variant's overrides merged."""
    variants = config.get("variants", {})
    if name not in variants:
        raise ConfigError(f"unknown variant {name!r}; the config defines {sorted(variants)}")
    merged = merge(copy.deepcopy({k: v for k, v in config.items() if k != "variants"}), variants[name] or {})
    _fill_defaults(merged, schema())
    return merged


def merge(base: dict, overrides: dict) -> dict:
    """Merge ``overrides`` into ``base`` in place, section by section (as a variant's overrides and
    Snakemake's ``--configfile`` files are merged); returns ``base``."""
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            merge(base[key], value)
        else:
            base[key] = copy.deepcopy(value)
    return base


def _fill_defaults(node, s):
    if not isinstance(node, dict) or s.get("type") != "object":
        return
    for key, sub in s.get("properties", {}).items():
        if key not in node and "default" in sub:
            node[key] = copy.deepcopy(sub["default"])
        if key in node:
            _fill_defaults(node[key], sub)


def _check(config: dict, s: dict, source: str) -> None:
    errors = sorted(jsonschema.Draft202012Validator(s).iter_errors(config), key=lambda e: list(map(str, e.absolute_path)))
    if errors:
        lines = [_describe(e, s) for e in errors[:10]]
        more = f"\n  ... and {len(errors) - 10} more" if len(errors) > 10 else ""
        raise ConfigError(f"{source}: invalid config\n  " + "\n  ".join(lines) + more)


def _describe(error: jsonschema.ValidationError, s: dict) -> str:
    key = ".".join(map(str, error.absolute_path)) or "(top level)"
    if error.validator == "additionalProperties":
        allowed = sorted(error.schema.get("properties", {}))
        unknown = sorted(set(error.instance) - set(allowed))
        parts = []
        for name in unknown:
            close = difflib.get_close_matches(name, allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            parts.append(f"{_join(key, name)}: unknown key{hint}; allowed here: {', '.join(allowed)}")
        return "\n  ".join(parts)
    if error.validator == "required":
        missing = error.message.split("'")[1]
        return f"{_join(key, missing)}: missing (required)"
    description = error.schema.get("description")
    expected = f" (expected: {description})" if description else ""
    return f"{key}: {error.message}{expected}"


def _join(key: str, name: str) -> str:
    return name if key == "(top level)" else f"{key}.{name}"


def digest(spec) -> str:
    """Short stable hash of a JSON-able spec: names cached artefacts shared between variants."""
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:12]


# --- what each stage depends on ------------------------------------------------------------

MECHANICAL_PARTICLE_KEYS = ("diameter", "density", "youngs_modulus_dem", "poisson_ratio")
MECHANICAL_WALL_KEYS = ("youngs_modulus_dem", "poisson_ratio")


def geometry_spec(cfg: dict) -> dict:
    return {"geometry": cfg["geometry"], "particle_diameter": cfg["particles"]["diameter"]}


def dem_spec(cfg: dict) -> dict:
    """DEM inputs: mechanical properties only, so thermal changes never re-run LIGGGHTS."""
    return {
        "particles": {k: cfg["particles"][k] for k in MECHANICAL_PARTICLE_KEYS},
        "wall": {k: cfg["wall"][k] for k in MECHANICAL_WALL_KEYS},
        "contact": cfg["contact"],
        "geometry": cfg["geometry"],
        "dem": {k: v for k, v in cfg["dem"].items() if k not in DEM_RUN_SETTINGS},
    }


# DEM settings that change how a run is executed or checked, not its result: not part of the key.
DEM_RUN_SETTINGS = ("ranks", "target_mass_flow", "mass_flow_tolerance")


def dem_checks(cfg: dict) -> dict:
    """The mass-flow target the DEM run is checked against (re-checked without re-running)."""
    return {k: cfg["dem"][k] for k in ("target_mass_flow", "mass_flow_tolerance") if k in cfg["dem"]}


def htc_spec(cfg: dict, kind: str) -> dict:
    """Inputs of one HTC table ("pfp" or "pfw"), Eqs. 8-13 and 18-20."""
    t = cfg["thermal"]
    mode = modes.reader("htc", kind)
    return {
        "kind": kind,
        "radius": cfg["particles"]["diameter"] / 2,
        "k_solid": cfg["particles"]["conductivity"],
        "solid_fraction": modes.solid_fractions(t["solid_fraction"])[mode.region],
        "gas": t["gas"],
        "cutoff": t[mode.cutoff_key],
        **t["htc_table"],
    }


RADIATION_MODES = modes.needing("rdf")  # the modes that need the ray-traced RDF tables


def rdf_spec(cfg: dict) -> dict | None:
    """Inputs of the ray-traced RDF tables, or None when no radiation mode is on or a table file is given."""
    t = cfg["thermal"]
    if not any(t["modes"].get(m, False) for m in RADIATION_MODES) or "rdf_table" in t:
        return None
    return {"particle_emissivity": cfg["particles"]["emissivity"], "wall_emissivity": cfg["wall"]["emissivity"], **t["rdf_build"],
            "format": RDF_FORMAT}


def radiation_study_rdf_spec(cfg: dict) -> dict:
    """The RDF tables the Section 4 study needs: its particles' emissivity, the config's build settings."""
    return {"particle_emissivity": cfg["radiation_study"]["emissivity"], "wall_emissivity": cfg["wall"]["emissivity"],
            **cfg["thermal"]["rdf_build"], "format": RDF_FORMAT}


def radiation_study_spec(cfg: dict) -> dict:
    """Inputs of the Section 4 study: its own section, and the thermal model of its bed."""
    return {"study": cfg["radiation_study"], "thermal": study_thermal_spec(thermal_spec(cfg), cfg["radiation_study"])}


# Thermal keys that describe the workflow's scene (wall zones, tables, DEM frames): not the study's bed.
SCENE_THERMAL_KEYS = ("walls", "rdf_table", "rdf_build", "htc_table", "frame_stride")


def study_thermal_spec(spec: dict, study: dict) -> dict:
    """The thermal model of the radiation study's bed from a :func:`thermal_spec` ``spec``: its
    materials and numerics with only particle-particle radiation on (Eq. 25), the study's particles
    (radius m, emissivity, density kg/m^3, specific heat J/(kg K)), solid fraction and radiation
    cutoff (radii), its cold and hot temperatures (K) as the temperature range, and no walls."""
    particles = {**spec["particles"], "diameter": 2 * study["radius"], "emissivity": study["emissivity"],
                 "density": study["density"], "specific_heat": study["specific_heat"]}  # fmt: skip
    thermal = {k: v for k, v in spec["thermal"].items() if k not in SCENE_THERMAL_KEYS}
    thermal.update(
        modes={m: m == "pp_radiation" for m in spec["thermal"]["modes"]},
        solid_fraction=study["solid_fraction"],
        radiation_cutoff=study["radiation_cutoff"],
        initial_temperature=study["cold_temperature"],
        inlet_temperature=study["hot_temperature"],
        walls={},
    )
    return {"particles": particles, "wall": spec["wall"], "thermal": thermal}


def thermal_spec(cfg: dict) -> dict:
    """Everything the thermal stage computes with (particles, wall, thermal sections)."""
    thermal = {k: v for k, v in cfg["thermal"].items() if k not in THERMAL_RUN_SETTINGS}
    return {"particles": cfg["particles"], "wall": cfg["wall"], "thermal": thermal}


# Thermal settings that change how a run is executed, not its result: not part of the key.
THERMAL_RUN_SETTINGS = ("checkpoint_frames", "checkpoint_minutes")


def thermal_checkpoints(cfg: dict) -> dict:
    """How often the thermal stage saves its state (schema defaults applied)."""
    return {k: cfg["thermal"][k] for k in THERMAL_RUN_SETTINGS if k in cfg["thermal"]}
