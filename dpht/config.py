"""Load and validate the workflow config; derive the parameters each stage depends on.

The config (``config/config.yaml``) is checked against ``workflow/schemas/config.schema.yaml``.
Errors name the file and the dotted key, and suggest the closest key for a misspelling. Optional
keys take the schema's defaults. Each stage receives only the keys it depends on (see the
``*_spec`` functions), so Snakemake re-runs a stage exactly when one of *its* parameters changes:
a thermal parameter re-runs the thermal stage and figures, never gmsh or LIGGGHTS.

``variants`` maps a design name to overrides merged into the base config (issue: mixers), so a
variant is a few lines of YAML; stages a variant does not change share their cached outputs. Of
several config files (Snakemake's ``configfile:``, config/config.yaml, and ``--configfile``), later
ones override earlier ones key by key, except three top-level keys that belong to one file:

* ``variants``: the last file that has a ``variants`` section names the variants that run (so an
  override file can drop the default ``base``);
* ``studies``: the studies the run makes (:mod:`dpht.studies`) are the last file's own list, none
  when it has none: config/config.yaml asks for the paper's studies, a user's design file given
  with ``--configfile`` runs that design alone unless it lists studies itself;
* ``name``: the run's folder results/<name>/ (:mod:`dpht.paths`) is the last file's ``name``, or
  else its file name without the extension (``my_design.yaml``: results/my_design/).

Variant names are folder names under results/<name>/ (see :data:`VARIANT_NAME`).
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import math
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import jsonschema
import yaml

from dpht.closures import htc
from dpht.closures.rdf import FORMAT as RDF_FORMAT  # in the RDF tables' cache key: a new format rebuilds them
from dpht.dem.report import FORMAT as DEM_REPORT_FORMAT  # in the DEM key: a run reports what its readers expect
from dpht.geometry.walls import FORMAT as WALLS_FORMAT  # in the geometry key: no cached wall table of an older format
from dpht import defaults
from dpht.errors import ConfigError
from dpht.thermal import effects, modes

SCHEMA_PATH = defaults.SCHEMA_PATH
schema = defaults.schema  # the config schema, read once

# A run's results go to results/<run>/, a variant's to results/<run>/<variant>/: a name is one plain
# path component (no "..", spaces or slashes; case is ignored when names are compared, for
# case-insensitive file systems), and not the name of a folder written beside it (dpht.paths).
VARIANT_NAME = r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}"
ONE_FILE_KEYS = ("studies", "name")  # top-level keys taken from the last config file alone (module docstring)


_SAFE_LOADER = defaults.SAFE_LOADER


class _UniqueKeyLoader(_SAFE_LOADER):
    """PyYAML's safe loader, refusing a key given twice in one mapping (PyYAML keeps the last)."""

    def construct_mapping(self, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} is given twice (first on line {seen[key] + 1})", key_node.start_mark)
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep)


def read_yaml(path: str | Path):
    """The contents of a YAML file; ConfigError names the file, line and column of a syntax error."""
    return _parse(path)[0]


def _parse(path: str | Path) -> tuple[object, dict]:
    """The contents of a YAML file and the line of every key path in it (see :func:`_key_lines`)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {path} does not exist")
    try:
        loader = _UniqueKeyLoader(path.read_text())
        try:
            node = loader.get_single_node()
            return (loader.construct_document(node) if node is not None else None), _key_lines(node)
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f", line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        context = f" ({err.context})" if err.context and err.problem else ""
        raise ConfigError(f"{path}{where}: not valid YAML: {err.problem or err.context}{context}") from None
    except (yaml.YAMLError, UnicodeDecodeError, ValueError) as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from None


def check_yaml(path: str | Path) -> None:
    """Exit with :func:`read_yaml`'s message if ``path`` exists and is not valid YAML (for the
    Snakefile: Snakemake's own message names neither the file nor the line)."""
    if Path(path).is_file():
        try:
            read_yaml(path)
        except ConfigError as err:
            sys.exit(f"dpht: error: {err}")


def load(*paths: str | Path) -> dict:
    """Read config files (later ones override earlier ones, as Snakemake merges them) and validate
    them; returns the config with defaults filled in."""
    sources = Sources(paths)
    return validate(sources.merged(), source=str(sources), sources=sources)


def validate(config, source: str = "config", sources: Sources | Within | None = None) -> dict:
    """Validate ``config`` (a mapping), its variant names and every variant; returns a copy with
    defaults filled. With ``sources`` (the files the config came from) every error line starts with
    the file and line that set the key."""
    if not isinstance(config, dict):
        raise ConfigError(f"{source}: expected a mapping of sections at the top level, got {type(config).__name__}")
    full = _numbers(copy.deepcopy(config))
    s = schema()
    _fill_defaults(full, s)
    _check(full, s, source, sources)
    _check_run_name(full, source)
    _check_variant_names(full["variants"], source)
    for name in full.get("variants", {}):
        _check(variant(full, name), s, f"{source} (variant {name!r})", sources, name)
    return full


def _check_run_name(config: dict, source: str) -> None:
    from dpht.paths import reserved_run_names  # the keyed study stages register their folders there

    if "name" in config and config["name"].lower() in reserved_run_names():
        raise ConfigError(f"{source}: name: {config['name']!r} is the stage folder results/{config['name'].lower()}/ "
                          f"shared by every run (taken: {', '.join(sorted(reserved_run_names()))}); choose another name")


def _check_variant_names(variants: dict, source: str) -> None:
    from dpht.paths import reserved_variant_names

    seen = {}
    for name in variants:
        if not isinstance(name, str) or not re.fullmatch(VARIANT_NAME, name):
            raise ConfigError(
                f"{source}: variants: the name {name!r} is not allowed; a variant's results go to "
                f"results/<run>/<name>/, so a name is 1-64 letters, digits, '_', '-' or '.', starting with a letter or digit"
            )
        if name.lower() in reserved_variant_names():
            raise ConfigError(f"{source}: variants: the name {name!r} is taken by the folder results/<run>/{name.lower()}/ "
                              f"beside the variants (taken: {', '.join(sorted(reserved_variant_names()))}); choose another")  # fmt: skip
        if name.lower() in seen:
            raise ConfigError(f"{source}: variants: {seen[name.lower()]!r} and {name!r} differ only in case, "
                              "and would share a results folder on some file systems")  # fmt: skip
        seen[name.lower()] = name


class Sources:
    """The config files a config was merged from, to say which file and line set a key.

    ``str()`` lists the files. :meth:`merged` merges them as Snakemake does, except that the
    ``variants`` of the last file naming any replace the earlier ones', and ``studies`` and ``name``
    are the last file's (see the module docstring). ``command_line``: the values of Snakemake's
    ``--config`` (merged over every file), named as such in messages, never blamed on a file.
    """

    def __init__(self, paths, command_line: Mapping | None = None):
        self.paths = [Path(p) for p in paths]
        self.command_line = command_line or {}
        self.raw, self._lines = [], []
        for path in self.paths:
            raw, lines = _parse(path)
            if not isinstance(raw, dict):
                raise ConfigError(f"{path}: expected a mapping of sections at the top level, got {type(raw).__name__}")
            self.raw.append(raw)
            self._lines.append(lines)

    def __str__(self) -> str:
        return ", ".join([*map(str, self.paths), *(["--config"] if self.command_line else [])]) or "config"

    def variants(self):
        """The ``variants`` section of the last file that has one, or None."""
        for raw in reversed(self.raw):
            if "variants" in raw:
                return raw["variants"]
        return None

    def merged(self) -> dict:
        config = {}
        for raw in self.raw:
            merge(config, raw)
        return self.with_own_keys(config)

    def with_own_keys(self, config: dict) -> dict:
        """``config`` (e.g. Snakemake's, merged from these files) with the variants of
        :meth:`variants`, and the studies and name of the last file (its stem for a name it lacks;
        no studies when it lists none: the schema's default)."""
        variants = self.variants()
        own = {k: v for k, v in config.items() if k not in ONE_FILE_KEYS}
        if variants is not None:
            own["variants"] = copy.deepcopy(variants)
        if not self.paths:
            return {**own, **{k: config[k] for k in ONE_FILE_KEYS if k in config}}
        last = self.raw[-1]
        own.update({k: copy.deepcopy(last[k]) for k in ONE_FILE_KEYS if k in last})
        own.setdefault("name", self.paths[-1].stem)
        return own

    def where(self, key: str, variant: str | None = None) -> str | None:
        """``file:line`` of the last file setting the dotted ``key`` (or the nearest enclosing key
        it sets), in ``variant``'s overrides first; :data:`COMMAND_LINE` where Snakemake's
        ``--config`` sets it; None if nothing sets any part of it."""
        parts = [p for p in re.split(r"\.|\[(\d+)\]", key) if p]
        prefixes = ([("variants", variant)] if variant else []) + [()]
        for prefix in prefixes:
            for length in range(len(parts), 0, -1):
                path = (*prefix, *parts[:length])
                if _sets(self.command_line, path):
                    return COMMAND_LINE
                for file, lines in zip(reversed(self.paths), reversed(self._lines)):
                    if path in lines:
                        return f"{file}:{lines[path]}"
        return None


    def within(self, prefix: str) -> Within:
        """These sources seen from the mapping at the dotted key ``prefix`` (a study's scene
        overrides): a key ``k`` is located where ``prefix.k`` is set."""
        return Within(self, prefix)


@dataclass(frozen=True)
class Within:
    """:meth:`Sources.within`: the same :meth:`where` for keys relative to ``prefix``."""

    sources: Sources
    prefix: str

    def where(self, key: str, variant: str | None = None) -> str | None:
        return self.sources.where(f"{self.prefix}.{key}")


COMMAND_LINE = "--config override (command line)"  # where Sources.where finds a value of snakemake --config


def _sets(values, path: tuple) -> bool:
    """Whether the nested mapping ``values`` (lists indexed by number) holds the key path ``path``."""
    for part in path:
        if isinstance(values, Mapping) and part in values:
            values = values[part]
        elif isinstance(values, list) and part.isdigit() and int(part) < len(values):
            values = values[int(part)]
        else:
            return False
    return True


def command_line_values(values: Mapping) -> dict:
    """Snakemake's ``--config`` values as a config file's: Snakemake reads a nested value
    (``dem={ranks: 64}``) with YAML's base loader, which leaves every scalar a string ('64',
    'true', '.nan'); each such string is read as the YAML scalar it is."""
    def typed(value):
        if isinstance(value, Mapping):
            return {k: typed(v) for k, v in value.items()}
        if isinstance(value, list):
            return [typed(v) for v in value]
        if isinstance(value, str):
            try:
                scalar = yaml.load(value, Loader=_SAFE_LOADER)  # noqa: S506 (a safe loader)
            except yaml.YAMLError:
                return value
            return scalar if isinstance(scalar, (str, int, float, bool)) else value
        return value

    return typed(values)


def _key_lines(node, prefix=()) -> dict:
    """1-based line of every key path in a composed YAML document (list items by index string)."""
    lines = {}
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            path = (*prefix, str(key.value))
            lines[path] = key.start_mark.line + 1
            lines.update(_key_lines(value, path))
    elif isinstance(node, yaml.SequenceNode):
        for index, value in enumerate(node.value):
            path = (*prefix, str(index))
            lines[path] = value.start_mark.line + 1
            lines.update(_key_lines(value, path))
    return lines


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


def _fill_defaults(node, s, root=None):
    root = s if root is None else root
    kind = s.get("type")
    if not isinstance(node, dict) or "object" not in (kind if isinstance(kind, list) else [kind]):  # a section may be null
        return
    for key, sub in s.get("properties", {}).items():
        if "$ref" in sub:  # a local definition, "#/$defs/<name>"
            sub = root["$defs"][sub["$ref"].rsplit("/", 1)[1]]
        if key not in node and "default" in sub:
            node[key] = copy.deepcopy(sub["default"])
        if key in node:
            _fill_defaults(node[key], sub, root)


def _finite_number(checker, instance) -> bool:
    """JSON Schema's "number", less NaN and infinity (YAML's .nan and .inf, or 1e400): a number the
    schema asks for is finite wherever it is, so no key needs a check of its own."""
    number = jsonschema.Draft202012Validator.TYPE_CHECKER.is_type(instance, "number")
    return number and (isinstance(instance, int) or math.isfinite(instance))


_VALIDATOR = jsonschema.validators.extend(
    jsonschema.Draft202012Validator,
    type_checker=jsonschema.Draft202012Validator.TYPE_CHECKER.redefine("number", _finite_number),
)


def _check(config: dict, s: dict, source: str, sources: Sources | Within | None = None, variant_name: str | None = None) -> None:
    errors = sorted(_VALIDATOR(s).iter_errors(config), key=lambda e: list(map(str, e.absolute_path)))
    if errors:
        lines = [line for e in errors[:10] for line in _describe(e, s).split("\n  ")]
        more = f"\n  ... and {len(errors) - 10} more" if len(errors) > 10 else ""
        raise ConfigError(f"{source}: invalid config\n  " + "\n  ".join(locate(lines, sources, variant_name)) + more)


def locate(lines: list[str], sources: Sources | Within | None, variant_name: str | None = None) -> list[str]:
    """Error lines that start with a dotted config key, each prefixed with the file and line setting it."""
    if sources is None:
        return lines
    located = []
    for line in lines:
        match = re.match(r"[a-z_]+(\.[A-Za-z0-9_-]+|\[\d+\])*", line)
        where = sources.where(match.group(0), variant_name) if match else None
        located.append(f"{where}: {line}" if where else line)
    return located


def _describe(error: jsonschema.ValidationError, s: dict, expect: bool = True) -> str:
    """One line per problem of ``error``, starting with the key; ``expect`` False leaves out what the
    key's schema expects (an alternative of a oneOf: the oneOf says what all of them accept)."""
    key = dotted(error.absolute_path)
    if _non_finite(error.instance) and error.validator in ("type", "oneOf", "anyOf"):
        return f"{key}: {error.instance} is not a finite number; expected {_expectation(error.schema, s)}{_unit(error, s)}"
    if error.validator in ("oneOf", "anyOf"):
        tag = _tag(error)
        if tag is not None:  # alternatives told apart by one key (a mixer's type): that key is wrong
            name, allowed = tag
            value = error.instance[name]
            close = difflib.get_close_matches(str(value), [str(a) for a in allowed], n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            return f"{_join(key, name)}: {value!r} is not allowed; expected one of {', '.join(map(repr, allowed))}{hint}"
        # Report the alternatives of the value's own type (0.9 against the number's bounds, a
        # mapping against the mapping's keys; not those whose fixed value or tag it lacks); if none
        # has that type, what each would accept.
        mismatched = {e.relative_schema_path[0] for e in error.context
                      if (e.validator == "type" and not e.relative_path) or (e.validator in ("const", "enum")
                                                                             and len(e.relative_path) <= 1)}
        relevant = [e for e in error.context if e.relative_schema_path[0] not in mismatched]
        expected = ", or ".join(_expectation(alt, s) for alt in error.validator_value)
        if relevant:
            # A problem inside the value (a key of the mapping) already says what is expected there.
            inside = all(len(e.absolute_path) > len(error.absolute_path) for e in relevant)
            described = "\n  ".join(_describe(e, s, expect=inside) for e in relevant)
            return described if inside else described + f"; expected {expected}"
        return f"{key}: {error.instance!r} is not allowed; expected {expected}"
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
    if error.validator == "enum":  # in YAML's words: true, not True
        return f"{key}: {error.instance!r} is not allowed; expected one of {', '.join(map(json.dumps, error.validator_value))}"
    if expect and error.validator in ("type", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return f"{key}: {error.message}; expected {_expectation(error.schema, s)}{_unit(error, s)}"
    return f"{key}: {error.message}{_unit(error, s)}"


def dotted(path) -> str:
    """A key path as messages name it: ``geometry.mixers[0].height``."""
    return "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".") or "(top level)"


def _non_finite(value) -> bool:
    return isinstance(value, float) and not math.isfinite(value)


def _tag(error: jsonschema.ValidationError) -> tuple[str, list] | None:
    """(key, the values it may take) when every alternative of a oneOf refused the mapping for one
    key's fixed value (``type: flat_plat`` against flat_plate, radial and stl), else None."""
    if not isinstance(error.instance, dict):
        return None
    refused = {}
    for e in error.context:
        if e.validator in ("const", "enum") and len(e.relative_path) == 1:
            refused.setdefault(e.relative_path[0], {})[e.relative_schema_path[0]] = e.validator_value
    for name, by_alternative in refused.items():
        if name in error.instance and len(by_alternative) == len(error.validator_value):
            allowed = [v for values in by_alternative.values() for v in (values if isinstance(values, list) else [values])]
            return name, allowed
    return None


def _unit(error: jsonschema.ValidationError, s: dict) -> str:
    """`` (<description>)`` of the key's schema (its own, or that of the key naming a shared
    definition: ``{$ref: positive, description: m}``), or ''."""
    node = s
    for part in list(error.absolute_schema_path)[:-1]:  # the keyword last; JSON Schema's path skips "$ref"
        if isinstance(node, dict) and part not in node and "$ref" in node:
            node = s["$defs"][node["$ref"].rsplit("/", 1)[1]]
        node = node[part]
    description = node.get("description") or error.schema.get("description")
    return f" ({description})" if description else ""


def _join(key: str, name: str) -> str:
    return name if key == "(top level)" else f"{key}.{name}"


def _expectation(sub: dict, s: dict) -> str:
    """What the schema ``sub`` accepts, in words ("a number > 0 and < 0.75", "one of 'air', ...")."""
    if "$ref" in sub:
        sub = s["$defs"][sub["$ref"].rsplit("/", 1)[-1]]
    if "const" in sub:
        return repr(sub["const"])
    if "enum" in sub:
        return "one of " + ", ".join(map(repr, sub["enum"]))
    if "oneOf" in sub or "anyOf" in sub:
        return ", or ".join(_expectation(alt, s) for alt in sub.get("oneOf", sub.get("anyOf")))
    kind = sub.get("type")
    if kind in ("number", "integer"):
        bounds = [f"{op} {sub[name]}" for name, op in (("minimum", ">="), ("exclusiveMinimum", ">"),
                                                         ("maximum", "<="), ("exclusiveMaximum", "<")) if name in sub]
        return f"{'an integer' if kind == 'integer' else 'a number'}" + (" " + " and ".join(bounds) if bounds else "")
    if kind == "object" or (kind is None and "required" in sub):
        keys = sub.get("required") or sorted(sub.get("properties", {}))
        return "a mapping with keys " + ", ".join(keys) if keys else "a mapping"
    if kind == "array":
        return "a list"
    if isinstance(kind, list):
        return " or ".join(_expectation({**sub, "type": k}, s) for k in kind)
    if kind == "string":
        return "a string"
    return sub.get("description") or json.dumps(sub)


def digest(spec) -> str:
    """Short stable hash of a JSON-able spec: names cached artefacts shared between variants."""
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:12]


# --- what each stage depends on ------------------------------------------------------------

MECHANICAL_PARTICLE_KEYS = ("diameter", "density", "youngs_modulus_dem", "poisson_ratio")
MECHANICAL_WALL_KEYS = ("youngs_modulus_dem", "poisson_ratio")


def geometry_spec(cfg: dict) -> dict:
    return {"geometry": cfg["geometry"], "particle_diameter": cfg["particles"]["diameter"], "format": WALLS_FORMAT}


def dem_spec(cfg: dict) -> dict:
    """DEM inputs: mechanical properties only, so thermal changes never re-run LIGGGHTS. A static
    bed, a frozen bed of the settled bed (``thermal.frozen_bed.frame`` 0), needs no flow phase:
    ``dem.flow_time`` is 0 then (settle only)."""
    dem = {k: v for k, v in cfg["dem"].items() if k not in DEM_RUN_SETTINGS}
    if static_bed(cfg):
        dem["flow_time"] = 0.0
    return {
        "particles": {k: cfg["particles"][k] for k in MECHANICAL_PARTICLE_KEYS},
        "wall": {k: cfg["wall"][k] for k in MECHANICAL_WALL_KEYS},
        "contact": cfg["contact"],
        "geometry": cfg["geometry"],
        "dem": dem,
        "report": DEM_REPORT_FORMAT,
    }


def static_bed(cfg: dict) -> bool:
    """Whether the scene's thermal stage holds the settled bed fixed (a frozen bed of frame 0)."""
    frozen = cfg["thermal"].get("frozen_bed")
    return bool(frozen) and frozen.get("frame", 0) == 0


# DEM settings that change how a run is executed or checked, not its result: not part of the key.
DEM_RUN_SETTINGS = ("ranks", "target_mass_flow", "mass_flow_tolerance")


def dem_checks(cfg: dict) -> dict:
    """The mass-flow target the DEM run is checked against (re-checked without re-running)."""
    return {k: cfg["dem"][k] for k in ("target_mass_flow", "mass_flow_tolerance") if k in cfg["dem"]}


def htc_spec(cfg: dict, kind: str, dem: str | None = None) -> dict:
    """Inputs of one HTC table ("pfp" or "pfw"), Eqs. 8-13 and 18-20, with the gas pressure (Pa or
    "continuum") and, where the temperature jump applies, the accommodation coefficients the config
    gives for the surfaces the table's gaps touch (PFP: the particle; PFW: both; a coefficient left
    out is the gas's typical one). A measured solid fraction names the DEM run ``dem`` (its key) it
    is read from (:func:`dpht.thermal.modes.measured`)."""
    t = cfg["thermal"]
    mode = modes.reader("htc", kind)
    pressure = t["gas_pressure"] if t["gas_pressure"] == htc.CONTINUUM else float(t["gas_pressure"])
    spec = {
        "kind": kind,
        "radius": cfg["particles"]["diameter"] / 2,
        "k_solid": cfg["particles"]["conductivity"],
        "solid_fraction": modes.measured(modes.solid_fractions(t["solid_fraction"])[mode.region], mode.region, dem),
        "gas": t["gas"],
        "gas_pressure": pressure,
        "cutoff": t[mode.cutoff_key],
        **t["htc_table"],
        "format": htc.FORMAT,
    }
    given = {s: a for s, a in t.get("accommodation", {}).items() if s in htc.TOUCHES[kind]}
    if given and htc.rarefied(pressure):
        spec["accommodation"] = given
    return spec


RADIATION_MODES = modes.needing("rdf")  # the modes that need the ray-traced RDF tables


def rdf_spec(cfg: dict, zones=None) -> dict | None:
    """Inputs of the ray-traced RDF tables, or None when no radiation mode is or may be on (what the
    config decides, :func:`dpht.thermal.effects.from_config`; ``zones``: the geometry's wall zones)
    or a table file is given."""
    t = cfg["thermal"]
    if not effects.possible_modes(effects.from_config(t, zones)) & set(RADIATION_MODES) or "rdf_table" in t:
        return None
    return {"particle_emissivity": cfg["particles"]["emissivity"], "wall_emissivity": cfg["wall"]["emissivity"], **t["rdf_build"],
            "format": RDF_FORMAT}


def thermal_spec(cfg: dict, zones=None, dem: str | None = None) -> dict:
    """Everything the thermal stage computes with (particles, wall, thermal sections). With the
    geometry's wall ``zones``, adiabatic entries of ``thermal.walls`` for zones it lacks are left
    out (a base variant next to a mixer variant may name the mixer's zone): they change nothing.
    How often the stage saves its state (THERMAL_RUN_SETTINGS) is not part of it either. The solid
    fraction is given per region, a measured one naming the DEM run ``dem`` (its key)."""
    thermal = {k: v for k, v in cfg["thermal"].items() if k not in THERMAL_RUN_SETTINGS}
    thermal["modes"] = {m: effects.switch(thermal, m) for m in modes.NAMES}  # every switch, as the schema fills it
    # Only the styles off their default: a run at the default styles keeps its key (and its cache).
    thermal.pop("styles", None)
    if styles := modes.spec_styles(cfg["thermal"]):
        thermal["styles"] = styles
    if zones is not None:
        walls = {z: bc for z, bc in thermal["walls"].items() if z in zones or bc != "adiabatic"}
        thermal = {**thermal, "walls": walls}
    if dem is not None:
        phi = modes.solid_fractions(thermal["solid_fraction"])
        thermal = {**thermal, "solid_fraction": {region: modes.measured(v, region, dem) for region, v in phi.items()}}
    if "slice" in thermal:  # the slice travels at the DEM's drive velocity (one value for both stages)
        drive = cfg["dem"].get("drive")
        if drive is None or "velocity" not in drive or drive.get("orifice"):
            raise ConfigError("thermal.slice: needs dem.drive.velocity, a driven slice (without orifice), the plug-flow "
                              "velocity the slice travels at")
        thermal = {**thermal, "slice": {"frames": "mirror", **thermal["slice"], "velocity": drive["velocity"]}}
    # Intra-particle keys only where they change the result: none with uniform particles, no
    # threshold when the particles are resolved anyway.
    unused = {False: ("intraparticle", "shells", "biot_threshold"), True: ("biot_threshold",)}.get(
        thermal.get("intraparticle", False), ())
    thermal = {k: v for k, v in thermal.items() if k not in unused}
    return {"particles": cfg["particles"], "wall": cfg["wall"], "thermal": thermal}


# Thermal keys the screening stage does not read: how a run steps in time (its first frame is the
# bed it screens, whatever the stride), and how it is executed.
NOT_SCREENED = ("frame_stride", "max_substeps", "integrator", "implicit", "shells", "checkpoint_frames", "checkpoint_minutes")


def screening_spec(spec: dict, htc_specs: dict) -> dict:
    """Inputs of the screening stage: a scene's :func:`thermal_spec` ``spec`` less what it does not
    read, and the HTC tables (``htc_specs`` by kind) of the gas-gap modes that may be on."""
    thermal = {k: v for k, v in spec["thermal"].items() if k not in NOT_SCREENED}
    return {"thermal": {**spec, "thermal": thermal}, "htc": htc_specs}


# Thermal settings that change how a run is executed, not its result: not part of the key.
THERMAL_RUN_SETTINGS = ("checkpoint_frames", "checkpoint_minutes")


def thermal_checkpoints(cfg: dict) -> dict:
    """How often the thermal stage saves its state (schema defaults applied)."""
    return {k: cfg["thermal"][k] for k in THERMAL_RUN_SETTINGS if k in cfg["thermal"]}


def radial_band(c: dict) -> list[float]:
    """z range (m) of the radial temperature profile: two particle diameters above the orifice plate."""
    orifice = c["geometry"]["tube"]["orifice_height"]
    return [orifice, orifice + 2 * c["particles"]["diameter"]]
