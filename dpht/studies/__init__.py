"""The registry of studies: every study the workflow can run derives from :data:`STUDIES`.

A study is a module of this package that defines ``STUDY``, a :class:`Study`: its name (the entry of
the config's ``studies`` list that asks for it, its Snakemake rule and its folder
``results/<run>/studies/<name>/``), its config section, its outputs with their report captions, the
function that plans it and the stage that computes it. The plan (:mod:`dpht.plan`) calls
``plan(plan, section)`` for each study asked for; that function registers the study's scenes as
the design variants' are (geometry, DEM, tables, screening, thermal: :meth:`dpht.plan.Plan.register_scene`)
and returns a :class:`Planned`: the files its stage reads, its parameters (a frozen dataclass) and
its scenes, which the pre-flight check checks with the design's (:mod:`dpht.preflight`). A study
may also have content-keyed stages of its own (:class:`KeyedStage`, cached in
``results/<stage>/<key>/`` like the scene stages). The Snakemake rules of every study are made from
this registry (``workflow/rules/studies.smk``); ``python -m dpht stage NAME`` finds their stages here.

A study's scenes are its own: they come from the files its section names (``scene``: one config
file or a list merged in order, each read alone over the schema's defaults), never from the run's
base scene, so a user's config changes no study's stage keys. Adding a study: a module here
listed in :data:`MODULES` (or :func:`register`), its section in the config schema and a caption per
report output (docs/manual/adding-a-study.md).
"""

from __future__ import annotations

import copy
import dataclasses
import importlib
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from dpht import config, paths
from dpht.errors import ConfigError


@dataclass(frozen=True)
class Output:
    """One output file of a study, in its folder; with a caption (workflow/report/<caption>.rst) it
    is in the report."""

    file: str
    caption: str | None = None


@dataclass(frozen=True)
class KeyedStage:
    """A stage of a study cached by content like the scene stages: run ``key`` writes its
    ``outputs`` ({name: file}) into results/<name>/<key>/ and reads the tables its run names
    upstream (:meth:`dpht.plan.Plan.keyed_inputs`). ``run(spec, inputs, outputs, threads)``."""

    name: str
    outputs: Mapping[str, str]
    run: Callable
    threads: int = 1


@dataclass(frozen=True)
class Planned:
    """What planning a study gives: ``inputs`` (rule input name -> file), ``spec`` (its stage's
    parameters, a frozen dataclass), ``scenes`` (label -> merged config, pre-flight checked) and
    ``problems`` found in its own section (pre-flight messages starting with the key)."""

    inputs: Mapping[str, str]
    spec: object
    scenes: Mapping[str, dict] = field(default_factory=dict)
    problems: tuple[str, ...] = ()

    def spec_json(self) -> str:
        return json.dumps(dataclasses.asdict(self.spec), sort_keys=True)


@dataclass(frozen=True)
class Published:
    """The parameters of a study that publishes a keyed stage run's files (:func:`publish`)."""

    key: str


@dataclass(frozen=True)
class Study:
    """One study (module docstring). ``plan(plan, section) -> Planned``; ``run(spec, inputs,
    outputs, threads)`` is its stage (``spec`` the JSON of :attr:`Planned.spec`)."""

    name: str
    section: str
    category: str  # the report's heading of its outputs
    outputs: Mapping[str, Output]
    plan: Callable
    run: Callable
    threads: int = 1
    stages: tuple[KeyedStage, ...] = ()
    description: str = ""

    def files(self, run: str) -> dict[str, str]:
        """Its output files in run ``run``'s folder."""
        return {name: paths.STUDY.format(run=run, study=self.name, file=out.file) for name, out in self.outputs.items()}


# The study modules, in the order of the report and of a run's targets.
MODULES = ("watkins", "watkins_reduction", "mixers", "radiation", "intraparticle", "accuracy", "screening_check")

STUDIES: dict[str, Study] = {}
KEYED: dict[str, KeyedStage] = {}  # the keyed stages of every study, by name


def register(study: Study) -> Study:
    """Add ``study`` to the registry (and its keyed stages, whose cache folders become reserved names)."""
    if study.name in STUDIES and STUDIES[study.name] is not study:
        raise ValueError(f"a study named {study.name!r} is registered already")
    STUDIES[study.name] = study
    for stage in study.stages:
        KEYED[stage.name] = stage
        paths.add_cache_folder(stage.name)
    return study


def stage(name: str) -> Callable | None:
    """The stage function of study or keyed stage ``name`` (for ``python -m dpht stage``), or None."""
    if name in STUDIES:
        return STUDIES[name].run
    return KEYED[name].run if name in KEYED else None


def check_asked(names, source: str = "studies") -> None:
    """ConfigError for a name in the config's ``studies`` list that is no registered study."""
    unknown = [n for n in names if n not in STUDIES]
    if unknown:
        raise ConfigError(f"{source}: unknown stud{'ies' if len(unknown) > 1 else 'y'} {', '.join(map(repr, unknown))}; "
                          f"studies: {', '.join(STUDIES)}")  # fmt: skip


# --- helpers of the study modules ------------------------------------------------------------


def section_of(cfg: dict, study: Study) -> dict:
    """The config section of ``study``; ConfigError when the config leaves it out or sets it to null."""
    section = cfg.get(study.section)
    if not isinstance(section, dict):
        raise ConfigError(f"{study.section}: the study {study.name!r} is asked for, but the config "
                          f"{'sets the section to null' if study.section in cfg else 'has no such section'}")  # fmt: skip
    return section


def scene_files(section: dict, key: str) -> list[Path]:
    """The files of a section's ``scene`` (one file or a list), found in the working folder or else
    in the project folder (where config/ is shipped)."""
    names = section["scene"] if isinstance(section["scene"], list) else [section["scene"]]
    return [project_file(name, key) for name in names]


def project_file(name: str, key: str) -> Path:
    """A config file named in the config: relative to the working folder, or else to the project folder."""
    for candidate in (Path(name), paths.PROJECT / name):
        if candidate.is_file():
            return candidate
    raise ConfigError(f"{key}: file {name} not found in the working folder or in {paths.PROJECT}")


def load_scene(section: dict, key: str) -> dict:
    """The validated config of a section's ``scene`` files merged in order over the schema's defaults;
    ConfigError for a scene without variants (the studies run its variants, or its first)."""
    files = scene_files(section, key)
    loaded = config.load(*files)
    if not loaded["variants"]:
        raise ConfigError(f"{key}: {', '.join(map(str, files))} names no variant (variants: {{}}); the study runs the "
                          "scene's variants, or its first: give one (base: {} is the scene as it is)")
    return loaded


def first_scene(section: dict, key: str) -> dict:
    """The merged config of the first variant of a section's ``scene``."""
    loaded = load_scene(section, key)
    return config.variant(loaded, next(iter(loaded["variants"])))


def variants_of(scene: dict) -> dict[str, dict]:
    """The merged config of every variant of a loaded scene config, in order."""
    return {name: config.variant(scene, name) for name in scene["variants"]}


def scene_of(base: dict, overrides: dict, source: str, sources: config.Sources | None = None) -> dict:
    """A validated scene: the merged config ``base`` (without variants) with ``overrides`` merged as
    a variant's are; ConfigError names ``source``, and with the run's ``sources`` (``source`` then
    the dotted key of ``overrides`` in the run's config) each problem the file and line setting it."""
    merged = config.merge(copy.deepcopy({k: v for k, v in base.items() if k != "variants"}), overrides or {})
    within = sources.within(source) if sources is not None else None
    return config.variant(config.validate({**merged, "variants": {"base": {}}}, source=source, sources=within), "base")


def publish(spec, inputs, outputs, threads):
    """The stage of a study that publishes files of its keyed stage in the run's folder: each input
    copied to the output of its name (a copy, not a link: the cached file keeps its own time)."""
    import shutil

    from dpht.util.files import replacing

    for name, target in outputs.items():
        with replacing(target) as tmp:
            shutil.copyfile(inputs[name], tmp)


def without_scene(section: dict) -> dict:
    """A section's parameters without the file naming its scene (not part of any stage key: the
    scene's contents are)."""
    return {k: v for k, v in section.items() if k != "scene"}


# The registry itself, last: the study modules use the helpers above.
for _module in MODULES:
    register(importlib.import_module(f"{__name__}.{_module}").STUDY)
