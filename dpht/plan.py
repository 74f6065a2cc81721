"""The workflow's plan: stage keys, rule inputs, parameters and targets, from the validated config.

The Snakemake rules (``workflow/rules/*.smk``) are thin: each asks a :class:`Plan` for its inputs
and parameters and runs one stage (:mod:`dpht.stages`). Everything they used to compute inline is
here, where it is unit-tested without Snakemake.

Caching: each stage run writes into a folder named by its *key*, a hash of the parameters the stage
depends on and of the keys of the stage runs it reads (``results/<stage>/<key>/``, tables in
``tables/<kind>/<key>.h5``). Design variants therefore share every stage run they do not change, a
changed parameter re-runs exactly the stages downstream of it, and earlier results stay on disk.
Settings that change how a run is executed or checked, not its result (MPI ranks, the mass-flow
target), ride along outside the key.
"""

from __future__ import annotations

import copy
import functools
import json
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from dpht import config, preflight
from dpht.thermal import effects, modes
from dpht.accuracy import knobs
from dpht.errors import ConfigError
from geometry.errors import GeometryError
from geometry.layout import layout
from geometry.stl_mixer import file_digest

# Per-variant figures of the `figures` rule; each has a caption workflow/report/<name>.rst.
FIGURES = ("cross_section", "wall_heat_flux", "wall_heat_history", "temperature_profiles", "htc_curves", "engineering")

# Table stages write one file per key into tables/<folder>/ (shared between projects).
TABLE_FOLDERS = {"pfp": "htc", "pfw": "htc", "rdf": "rdf"}
# Tables shipped with the project (tables/<folder>/shipped/<key>.h5, e.g. the RDF table of the default
# emissivities, minutes to trace) are read from there: sources, not outputs of a rule, so Snakemake
# has no metadata to miss and never rebuilds them.
SHIPPED = Path(__file__).resolve().parent.parent / "tables"


@dataclass(frozen=True)
class Run:
    """One stage run: what its key hashes (``spec`` and the ``upstream`` keys) and what rides along."""

    stage: str
    key: str
    spec: dict
    upstream: dict
    settings: dict = field(default_factory=dict)  # not part of the key


def from_workflow(snakemake_config: dict, configfiles, overrides=()) -> Plan:
    """The plan of Snakemake's ``config`` merged from ``configfiles`` (``workflow.configfiles``),
    validated and checked before any job runs (:mod:`dpht.preflight`); errors name file and line.
    The variants are those of the last file naming any (see :mod:`dpht.config`).

    ``overrides``: the command line's ``--configfile`` files (``workflow.overwrite_configfiles``).
    Snakemake lists them in ``configfiles`` before the Snakefile's ``configfile:`` but merges them
    over it, so they are moved last: ``--configfile config/mixers.yaml`` alone runs its variants."""
    given = {Path(f).resolve() for f in overrides}
    sources = config.Sources([f for f in configfiles if Path(f).resolve() not in given] + list(overrides))
    plan = Plan(config.validate(sources.with_variants(snakemake_config), source=str(sources), sources=sources))
    preflight.check(plan, sources)
    return plan


WATKINS_SCENE = "watkins"  # label of the Watkins scene; the reduction check's are "full" and "slice:<name>"
WATKINS_FIGURES = ("fig11", "fig12", "fig13")  # results/watkins/<name>.png, captions workflow/report/watkins_<name>.rst


def watkins_scenes(cfg: dict) -> dict[str, dict]:
    """The merged configs of the Watkins validation (``watkins`` section of ``cfg``): the scene file's
    (its first variant) and, with ``watkins.reduction``, the full tube and each slice, overrides of
    ``cfg`` (without its variants). ConfigError names the file of a problem."""
    section = cfg["watkins"]
    scene = config.load(_project_file(section["scene"], "watkins.scene"))
    scenes = {WATKINS_SCENE: config.variant(scene, next(iter(scene["variants"])))}
    if "reduction" in section:
        overrides = config.read_yaml(_project_file(section["reduction"], "watkins.reduction"))
        if not isinstance(overrides, dict) or not isinstance(overrides.get("full"), dict) or not overrides.get("slices"):
            raise ConfigError(f"{section['reduction']}: expected a mapping with 'full' (overrides) and "
                                     "'slices' (name -> overrides)")
        base = {k: v for k, v in cfg.items() if k not in ("variants", "watkins")}
        named = {"full": overrides["full"], **{f"slice:{n}": o for n, o in overrides["slices"].items()}}
        for label, o in named.items():
            merged = config.validate({**config.merge(copy.deepcopy(base), o or {}), "variants": {"base": {}}},
                                     source=f"{section['reduction']} ({label})")
            scenes[label] = config.variant(merged, "base")
        for label in scenes:
            if label.startswith("slice:") and "slice" not in scenes[label]["thermal"]:
                raise ConfigError(f"{section['reduction']}: slices.{label[6:]} has no thermal.slice")
    if "slice" not in scenes[WATKINS_SCENE]["thermal"]:
        raise ConfigError(f"{section['scene']}: the Watkins scene needs thermal.slice (a travelling slice)")
    return scenes


MIXERS = "mixers"  # results/mixers/: the mixer study (DPHT paper, Section 6)
MIXER_FIGURES = ("fig14", "fig15", "fig16")  # results/mixers/<name>.png, captions workflow/report/mixers_<name>.rst
MIXER_TABLES = ("mixers.csv", "mixers.md", "mixers.json")  # results/mixers/: per variant against the reference


def mixer_scenes(cfg: dict) -> dict[str, dict]:
    """The merged config of every variant of the mixer study's scene file (``mixer_study.scene``, a whole
    config whose first variant is the reference); ConfigError names the file of a problem."""
    section = cfg["mixer_study"]
    scene = config.load(_project_file(section["scene"], "mixer_study.scene"))
    names = list(scene["variants"])
    if len(names) < 2:
        raise ConfigError(f"{section['scene']}: the mixer study compares variants with the first, {names[0]!r}; "
                          "it needs at least two")
    unknown = sorted(set(section.get("paper", {})) - set(names[1:]))
    if unknown:
        raise ConfigError(f"mixer_study.paper: {unknown} are not variants of {section['scene']} other than the "
                          f"reference {names[0]!r} (its variants: {names})")
    return {name: config.variant(scene, name) for name in names}


def _project_file(name: str, key: str) -> Path:
    """A config file named in the config: relative to the working folder, or else to the project
    folder (where config/ is shipped), so the shipped Watkins files are found from any folder."""
    for candidate in (Path(name), SHIPPED.parent / name):
        if candidate.is_file():
            return candidate
    raise ConfigError(f"{key}: file {name} not found in the working folder or in {SHIPPED.parent}")


def _with_file_digests(c: dict) -> dict:
    """``c`` with the SHA-256 of every STL mixer's file (where it exists) in its mixer item: the
    geometry and DEM keys change when the file does, and the geometry stage checks it read that file."""
    if not any(isinstance(m, dict) and m.get("type") == "stl" for m in c["geometry"].get("mixers") or []):
        return c
    c = copy.deepcopy(c)
    for mixer in c["geometry"]["mixers"]:
        if isinstance(mixer, dict) and mixer.get("type") == "stl" and Path(mixer["file"]).is_file():
            mixer["sha256"] = file_digest(mixer["file"])
    return c


def screening_rdf(c: dict) -> str | list:
    """The RDF table file the screening stage estimates radiation with: the scene's own where the
    config names one (``thermal.rdf_table``), else the shipped table nearest in emissivity (the
    scene's own when it is shipped; see :mod:`dpht.thermal.screening`)."""
    t = c["thermal"]
    if "rdf_table" in t:
        return t["rdf_table"]
    shipped = sorted((SHIPPED / "rdf" / "shipped").glob("*.h5"))
    emissivity = np.array([c["particles"]["emissivity"], c["wall"]["emissivity"]])
    return str(min(shipped, key=lambda f: float(np.abs(_emissivities(f) - emissivity).sum())))


@functools.cache
def _emissivities(table: Path) -> np.ndarray:
    with h5py.File(table, "r") as f:
        return np.array([f.attrs["particle_emissivity"], f.attrs["wall_emissivity"]], dtype=float)


def path(stage: str, key: str, file: str) -> str:
    """Where run ``key`` of ``stage`` writes ``file`` (the table stages write one file, ``file`` unused;
    a shipped table is read where it is shipped)."""
    if stage in TABLE_FOLDERS:
        shipped = SHIPPED / TABLE_FOLDERS[stage] / "shipped" / f"{key}.h5"
        return str(shipped) if shipped.is_file() else f"tables/{TABLE_FOLDERS[stage]}/{key}.h5"
    return f"results/{stage}/{key}/{file}"


def _number(text) -> bool:
    try:
        float(text)
    except (TypeError, ValueError):
        return False
    return True


def radial_band(c: dict) -> list[float]:
    """z range (m) of the radial temperature profile: two particle diameters above the orifice plate."""
    orifice = c["geometry"]["tube"]["orifice_height"]
    return [orifice, orifice + 2 * c["particles"]["diameter"]]


def figure(variant: str, name: str) -> str:
    """Figure ``name`` (one of FIGURES) of design ``variant``."""
    return f"results/{variant}/figures/{name}.png"


class Plan:
    """Stage runs and targets of every design variant of a validated config (:func:`dpht.config.validate`)."""

    def __init__(self, cfg: dict):
        self.config = cfg
        self.variants = list(cfg["variants"])
        self.runs: dict[str, Run] = {}
        self.keys: dict[str, dict] = {}  # variant -> {stage: key or None}
        self.configs: dict[str, dict] = {}  # variant -> its merged config
        self.screening_rdf: dict[str, str | None] = {}  # screening key -> the RDF table its radiation estimate reads
        for name in self.variants:
            self.configs[name] = _with_file_digests(config.variant(cfg, name))
            self.keys[name] = self.register_scene(self.configs[name])
        # The Watkins validation (DPHT paper, Section 5), when configured: its scene and the reduction
        # check's full tube and slices, each registered as a scene ({label: stage keys}, {label: config}).
        self.watkins, self.watkins_configs = self._register_scenes(watkins_scenes(cfg) if "watkins" in cfg else {})
        # The mixer study (DPHT paper, Section 6), when configured: each variant of its scene file
        # registered as a scene ({variant: stage keys}, {variant: config}; the first is the reference).
        self.mixers, self.mixer_configs = self._register_scenes(mixer_scenes(cfg) if "mixer_study" in cfg else {})
        self.study = None  # key of the radiation-model study (DPHT paper, Section 4), when configured
        if "radiation_study" in cfg:
            study_rdf = self._register("rdf", config.radiation_study_rdf_spec(cfg))
            self.study = self._register("radiation_study", config.radiation_study_spec(cfg), rdf=study_rdf)
        # key of the intra-particle study (lumped against resolved particles over Bi), when configured
        self.intraparticle_study = (self._register("intraparticle_study", config.intraparticle_study_spec(cfg))
                                    if "intraparticle_study" in cfg else None)  # fmt: skip
        # The accuracy study's runs (`accuracy_cost` target); a config it cannot study still runs the rest.
        self.accuracy, self.accuracy_error = [], None
        try:
            self.accuracy = self._register_accuracy()
        except ConfigError as err:
            self.accuracy_error = err
        # The screening check's scenes (`screening_check` target), each as configured and all on.
        self.screening_check, self.screening_check_error = [], None
        try:
            self.screening_check = self._register_screening_check()
        except ConfigError as err:
            self.screening_check_error = err

    def _register_accuracy(self) -> list[dict]:
        """Each setting of the accuracy study (:func:`dpht.accuracy.knobs.settings`, around the
        first variant, or the Watkins scene for the slice's) as a scene of its own, registered like a
        variant: {knob, setting, ..., keys}. Bed knobs run the Section 4 study's stage, when the
        config has one; slice knobs need the Watkins scene."""
        base = self.configs[self.variants[0]]
        watkins = self.watkins_configs.get(WATKINS_SCENE)
        runs = []
        for run in knobs.settings(base, watkins):
            scene = watkins if run["scene"] == "slice" else base
            c = config.validate({**config.merge(copy.deepcopy(scene), run.pop("overrides")), "variants": {"base": {}}},
                                source=f"accuracy study ({run['knob']} = {run['label']})")  # fmt: skip
            if run["scene"] == "bed":
                if "radiation_study" not in c:
                    continue
                rdf = self._register("rdf", config.radiation_study_rdf_spec(c))
                run["keys"] = {"rdf": rdf, "radiation_study": self._register("radiation_study", config.radiation_study_spec(c), rdf=rdf)}
            else:
                run["keys"] = self.register_scene(c, study=True)
            runs.append(run)
        return runs

    def _register_scenes(self, scenes: dict[str, dict]) -> tuple[dict[str, dict], dict[str, dict]]:
        """Each of ``scenes`` ({label: merged config}) registered like a variant: ({label: stage keys},
        {label: config with its STL mixers' digests})."""
        configs = {label: _with_file_digests(c) for label, c in scenes.items()}
        return {label: self.register_scene(c) for label, c in configs.items()}, configs

    def _register_screening_check(self) -> list[dict]:
        """Each scene of the screening check (:mod:`dpht.accuracy.screening_check`: the first variant
        and ``screening_check.scenes``) as configured and with every auto switch on:
        {name, config, keys of both}."""
        base = self.configs[self.variants[0]]
        checks = []
        for name, overrides in {"default": {}, **self.config["screening_check"]["scenes"]}.items():
            c = config.variant(config.validate({**config.merge(copy.deepcopy(base), overrides or {}), "variants": {"base": {}}},
                                               source=f"screening_check.scenes.{name}"), "base")  # fmt: skip
            on = config.merge(copy.deepcopy(c), {"thermal": effects.all_on(c["thermal"])})
            checks.append({"name": name, "config": c, "auto": self.register_scene(c, study=True),
                           "all": self.register_scene(on, study=True)})  # fmt: skip
        return checks

    def register_scene(self, c: dict, study: bool = False) -> dict:
        """Register the stage runs of one scene (a variant's merged config ``c``); returns
        {stage: key, or None for a stage the scene does not run}. Studies that derive scenes from
        the config (other thermal steps, effects switched on, ...) register them the same way
        (``study``: their run settings never replace a variant's)."""
        geometry = self._register("geometry", config.geometry_spec(c))
        dem = self._register("dem", config.dem_spec(c), geometry=geometry)
        # Not part of the key: ranks and the mass-flow check do not change the DEM result
        # (scenes sharing a DEM run share these too; the last variant registered wins).
        if not (study and self.runs[dem].settings):
            self.runs[dem].settings.update(ranks=c["dem"]["ranks"], checks=config.dem_checks(c))
        try:
            zones = layout(c["geometry"], c["particles"]["diameter"]).zone_names
        except GeometryError:  # reported by the pre-flight check with the config's other problems
            zones = None
        # Tables only for the modes that are on or may be once the screening stage has decided.
        decisions = effects.from_config(c["thermal"], zones)
        possible = effects.possible_modes(decisions)
        htc_specs = {kind: config.htc_spec(c, kind, dem) for kind in TABLE_FOLDERS if kind in possible}
        pfp, pfw = (self._register(kind, htc_specs[kind]) if kind in htc_specs else None for kind in ("pfp", "pfw"))
        rdf = config.rdf_spec(c, zones)
        rdf = self._register("rdf", rdf) if rdf is not None else None
        thermal = config.thermal_spec(c, zones, dem)
        screening = None
        if effects.pending(decisions):  # the scene's settled bed decides the rest
            screening = self._register("screening", config.screening_spec(thermal, htc_specs), geometry=geometry, dem=dem)
            self.screening_rdf[screening] = screening_rdf(c) if possible & set(modes.needing("rdf")) else None
        thermal = self._register("thermal", thermal, geometry=geometry, dem=dem, pfp=pfp, pfw=pfw, rdf=rdf,
                                 screening=screening)  # fmt: skip
        if not (study and self.runs[thermal].settings):  # not part of the key either
            self.runs[thermal].settings.update(checkpoints=config.thermal_checkpoints(c), effects=decisions)
        return {"geometry": geometry, "dem": dem, "pfp": pfp, "pfw": pfw, "rdf": rdf, "screening": screening,
                "thermal": thermal}  # fmt: skip

    def _register(self, stage: str, spec: dict, **upstream) -> str:
        key = config.digest({"spec": spec, "upstream": upstream})
        if key not in self.runs:
            self.runs[key] = Run(stage, key, spec, upstream)
        return key

    # --- files -------------------------------------------------------------------------------

    def upstream_file(self, key: str, stage: str, file: str = "") -> str:
        """``file`` of the ``stage`` run that run ``key`` reads."""
        return path(stage, self.runs[key].upstream[stage], file)

    def variant_file(self, variant: str, stage: str, file: str = "") -> str:
        """``file`` of the ``stage`` run of design ``variant``."""
        return path(stage, self.keys[variant][stage], file)

    def dem_inputs(self, key: str) -> dict:
        return {"walls": self.upstream_file(key, "geometry", "walls.h5"),
                "geometry": self.upstream_file(key, "geometry", "geometry.json")}  # fmt: skip

    def htc_inputs(self, key: str) -> dict:
        """The DEM run's summary when the table's solid fraction is measured (``{"measured": dem}``)."""
        phi = self.runs[key].spec["solid_fraction"]
        return {"dem_summary": path("dem", phi["measured"], "summary.json")} if modes.is_measured(phi) else {}

    def thermal_modes(self, key: str, screened=None) -> frozenset:
        """The modes thermal run ``key`` computes: those the config decides on
        (:func:`dpht.thermal.effects.from_config`) and those its screening stage decides on;
        ``screened(screening key)`` returns that stage's decisions (the workflow reads them once
        its checkpoint has run)."""
        decisions = dict(self.runs[key].settings["effects"])
        screening = self.runs[key].upstream.get("screening")
        if screening is not None:
            if screened is None:
                raise ValueError(f"thermal run {key} needs the decisions of its screening stage {screening}")
            records = screened(screening)
            decisions.update({name: effects.Decision(**records[name]) for name in effects.pending(decisions)})
        return frozenset(m for m in modes.NAMES if decisions[m].on)

    def thermal_inputs(self, key: str, screened=None) -> dict:
        """DEM frames and summary (the measured solid fractions, the wall surfaces LIGGGHTS used),
        wall table, the screening stage's decisions, and the tables of the modes that are on
        (:meth:`thermal_modes`): HTC tables, and with radiation the RDF table(s), built by the
        workflow or the file (or list of files) named by ``thermal.rdf_table``."""
        on = self.thermal_modes(key, screened)
        run = self.runs[key]
        inputs = {
            "positions": self.upstream_file(key, "dem", "positions.h5"),
            "dem_summary": self.upstream_file(key, "dem", "summary.json"),
            "walls": self.upstream_file(key, "geometry", "walls.h5"),
        }
        if run.upstream["screening"] is not None:
            inputs["screening"] = self.upstream_file(key, "screening", "screening.json")
        inputs.update({kind: self.upstream_file(key, kind) for kind in ("pfp", "pfw") if kind in on})
        if on & set(modes.needing("rdf")):
            if run.upstream["rdf"] is not None:
                inputs["rdf"] = self.upstream_file(key, "rdf")
            else:
                inputs["rdf"] = run.spec["thermal"]["rdf_table"]
        return inputs

    def screening_inputs(self, key: str) -> dict:
        """The scene's settled bed (the first DEM frame), the DEM summary (solid fractions, wall
        surfaces), the wall table and, when a radiation mode may be on, an RDF table to estimate it
        with (:func:`screening_rdf`)."""
        inputs = {"positions": self.upstream_file(key, "dem", "positions.h5"),
                  "dem_summary": self.upstream_file(key, "dem", "summary.json"),
                  "walls": self.upstream_file(key, "geometry", "walls.h5")}  # fmt: skip
        if self.screening_rdf[key] is not None:
            inputs["rdf"] = self.screening_rdf[key]
        return inputs

    def study_inputs(self, key: str) -> dict:
        return {"rdf": self.upstream_file(key, "rdf")}

    def figures_inputs(self, variant: str) -> dict:
        return {"positions": self.variant_file(variant, "dem", "positions.h5"),
                "walls": self.variant_file(variant, "geometry", "walls.h5"),
                "thermal": self.variant_file(variant, "thermal", "thermal.h5")}  # fmt: skip

    def summary_inputs(self, variant: str) -> dict:
        """The stage summaries of ``variant``, and its figures: the summary is written after them, so
        it always names the stage runs its figures were drawn from (a failed figures job leaves it
        as it was)."""
        return {"geometry": self.variant_file(variant, "geometry", "geometry.json"),
                "dem": self.variant_file(variant, "dem", "summary.json"),
                "thermal": self.variant_file(variant, "thermal", "summary.json"),
                **{f"figure_{name}": figure(variant, name) for name in FIGURES}}  # fmt: skip

    def comparison_inputs(self) -> dict:
        files = {"thermal": ("thermal", "thermal.h5"), "walls": ("geometry", "walls.h5"), "positions": ("dem", "positions.h5")}
        return {f"{name}_{v}": self.variant_file(v, stage, file) for name, (stage, file) in files.items() for v in self.variants}

    def accuracy_inputs(self) -> dict:
        """The summaries (and for scenes, thermal and DEM files; for the slice, the wall table) of
        every run of the accuracy study, named ``<index>_<file>``."""
        if self.accuracy_error is not None:
            raise self.accuracy_error
        inputs = {}
        for i, run in enumerate(self.accuracy):
            keys = run["keys"]
            if "radiation_study" in keys:
                inputs[f"{i}_study"] = path("radiation_study", keys["radiation_study"], "summary.json")
                continue
            inputs.update({f"{i}_thermal": path("thermal", keys["thermal"], "thermal.h5"),
                           f"{i}_thermal_summary": path("thermal", keys["thermal"], "summary.json"),
                           f"{i}_positions": path("dem", keys["dem"], "positions.h5"),
                           f"{i}_dem_summary": path("dem", keys["dem"], "summary.json")})  # fmt: skip
            if run["scene"] == "slice":
                inputs[f"{i}_walls"] = path("geometry", keys["geometry"], "walls.h5")
        return inputs

    def screening_check_inputs(self) -> dict:
        """The thermal files, positions and thermal summaries of both runs of every check scene,
        named ``<index>_<auto|all>_<file>``."""
        if self.screening_check_error is not None:
            raise self.screening_check_error
        # The pre-flight check of its scenes, before any of their jobs (only when the check is asked for).
        problems = [f"screening_check.scenes.{check['name']}: {problem}" for check in self.screening_check
                    for problem in preflight.scene_problems(check["config"])]  # fmt: skip
        if problems:
            raise ConfigError("the screening check cannot run:\n  " + "\n  ".join(problems))
        inputs = {}
        for i, check in enumerate(self.screening_check):
            for run in ("auto", "all"):
                keys = check[run]
                inputs.update({f"{i}_{run}_thermal": path("thermal", keys["thermal"], "thermal.h5"),
                               f"{i}_{run}_summary": path("thermal", keys["thermal"], "summary.json"),
                               f"{i}_{run}_positions": path("dem", keys["dem"], "positions.h5")})  # fmt: skip
        return inputs

    def screening_check_spec(self) -> str:
        """Per check scene: its name, steady window, radial band, specific heat, inlet temperature,
        temperature range (initial, inlet, the walls' constants) and screening threshold."""
        scenes = []
        for check in self.screening_check:
            c = check["config"]
            t = c["thermal"]
            walls = [float(bc["temperature"]) for bc in t["walls"].values() if isinstance(bc, dict) and _number(bc["temperature"])]
            temperatures = [t["initial_temperature"], t["inlet_temperature"], *walls]
            scenes.append({"name": check["name"], "window": c["figures"]["steady_window"], "radial_band": radial_band(c),
                           "specific_heat": c["particles"]["specific_heat"], "inlet_temperature": t["inlet_temperature"],
                           "temperatures": [min(temperatures), max(temperatures)], "threshold": t["screening_threshold"]})  # fmt: skip
        return json.dumps({"scenes": scenes}, sort_keys=True)

    def accuracy_spec(self) -> str:
        """The accuracy study's parameters: its runs (without the stage keys' contents) and what the
        outputs are measured with (the first variant's steady window, radial band, c_p, inlet)."""
        c = self.configs[self.variants[0]]
        return json.dumps({"runs": self.accuracy, "window": c["figures"]["steady_window"],
                           "radial_band": radial_band(c), "specific_heat": c["particles"]["specific_heat"],
                           "inlet_temperature": c["thermal"]["inlet_temperature"],
                           "tolerance": c["accuracy"]["tolerance"]}, sort_keys=True)  # fmt: skip

    # --- parameters (JSON for `python -m dpht stage NAME --spec ...`) ---------------------------

    def spec_json(self, key: str) -> str:
        run = self.runs[key]
        spec = run.spec
        if run.stage == "dem":  # the mass-flow check rides along: changing it re-checks the cached run
            spec = {**spec, "dem": {**spec["dem"], **run.settings["checks"]}}
        elif run.stage == "thermal":  # and how often the thermal stage saves its state
            spec = {**spec, "thermal": {**spec["thermal"], **run.settings["checkpoints"]}}
        return json.dumps(spec, sort_keys=True)

    def threads(self, key: str) -> int:
        """MPI ranks of a DEM run."""
        return self.runs[key].settings["ranks"]

    def figures_spec(self, variant: str) -> str:
        c = self.configs[variant]
        d = c["particles"]["diameter"]
        return json.dumps(
            {
                "window": c["figures"]["steady_window"],
                "heated_zones": sorted(z for z, bc in c["thermal"]["walls"].items() if bc != "adiabatic"),
                "radial_band": radial_band(c),
                "htc": {  # the solid fractions: those the thermal run used (its summary)
                    "radius": d / 2,
                    "k_solid": c["particles"]["conductivity"],
                    "gas": c["thermal"]["gas"],
                    "pressure": c["thermal"]["gas_pressure"],
                    "accommodation": c["thermal"].get("accommodation"),
                },
            },
            sort_keys=True,
        )

    def summary_spec(self, variant: str) -> str:
        return json.dumps({"stage_keys": self.keys[variant]}, sort_keys=True)

    def comparison_spec(self) -> str:
        return json.dumps({"variants": self.variants, "window": self.config["figures"]["steady_window"]})

    def calibration_spec(self, variant: str) -> str:
        return json.dumps(self.configs[variant], sort_keys=True)

    def calibration_threads(self, variant: str) -> int:
        return self.configs[variant]["dem"]["ranks"]

    # --- targets -------------------------------------------------------------------------------

    def targets(self) -> list[str]:
        """Every figure and summary of every variant, their comparison when there are several, and
        the radiation-model and intra-particle studies when configured."""
        targets = [figure(v, name) for v in self.variants for name in FIGURES]
        targets += [f"results/{v}/summary.json" for v in self.variants]
        if len(self.variants) > 1:
            targets += ["results/comparison/variants.png", "results/comparison/cross_sections.png"]
        if self.study is not None:
            targets.append(path("radiation_study", self.study, "fig9.png"))
        if self.intraparticle_study is not None:
            targets.append(path("intraparticle_study", self.intraparticle_study, "biot_sweep.png"))
        return targets + self.watkins_targets() + self.mixer_targets()

    # --- the Watkins validation ------------------------------------------------------------------

    def watkins_targets(self) -> list[str]:
        """Figures 11-13 and the summary of the Watkins scene, and the reduction check when configured."""
        if not self.watkins:
            return []
        targets = [f"results/watkins/{name}.png" for name in WATKINS_FIGURES] + ["results/watkins/watkins.json"]
        return targets + (["results/watkins/reduction.png"] if "full" in self.watkins else [])

    def _scene_files(self, label: str) -> dict:
        keys = self.watkins[label]
        return {"positions": path("dem", keys["dem"], "positions.h5"), "walls": path("geometry", keys["geometry"], "walls.h5"),
                "thermal": path("thermal", keys["thermal"], "thermal.h5")}  # fmt: skip

    def watkins_inputs(self) -> dict:
        return self._scene_files(WATKINS_SCENE) if self.watkins else {}

    def reduction_inputs(self) -> dict:
        if "full" not in self.watkins:
            return {}
        files = {f"full_{k}": v for k, v in self._scene_files("full").items()}
        for label in self.watkins:
            if label.startswith("slice:"):
                files.update({f"{label[6:]}_{k}": v for k, v in self._scene_files(label).items()})
        return files

    def reduction_spec(self) -> str:
        if "full" not in self.watkins:
            return "{}"
        c = self.watkins_configs["full"]
        return json.dumps({"slices": [label[6:] for label in self.watkins if label.startswith("slice:")],
                           "window": c["figures"]["steady_window"]}, sort_keys=True)  # fmt: skip

    # --- the mixer study -----------------------------------------------------------------------

    def mixer_targets(self) -> list[str]:
        """Figs. 14-16 of the mixer study and its table, when configured."""
        if not self.mixers:
            return []
        return [f"results/{MIXERS}/{name}.png" for name in MIXER_FIGURES] + [f"results/{MIXERS}/{t}" for t in MIXER_TABLES]

    def mixer_inputs(self) -> dict:
        """Per variant of the mixer study (``<file>_<variant>``): wall table, positions, thermal output, and
        the DEM and thermal summaries (mass flow, the drive's acceleration, wall times)."""
        files = {"walls": ("geometry", "walls.h5"), "positions": ("dem", "positions.h5"), "thermal": ("thermal", "thermal.h5"),
                 "dem": ("dem", "summary.json"), "thermal_summary": ("thermal", "summary.json")}  # fmt: skip
        return {f"{name}_{v}": path(stage, keys[stage], file) for v, keys in self.mixers.items()
                for name, (stage, file) in files.items()}  # fmt: skip

    def mixer_spec(self) -> str:
        """The mixer study's parameters: its variants in order (the first is the reference), the paper's
        relative wall heats, the variant whose radial mixer Fig. 14 shows close up, the mixers' heights
        (shaded in Fig. 16), and what the outputs are measured with (the reference's steady window,
        heated zones, c_p, inlet temperature)."""
        if not self.mixers:
            return "{}"
        reference = self.mixer_configs[next(iter(self.mixers))]
        thermal = reference["thermal"]
        radial = [v for v, c in self.mixer_configs.items()
                  if any(m.get("type") == "radial" for m in c["geometry"].get("mixers") or [])]  # fmt: skip
        spans = {}  # the mixers' heights as distances from the inlet, the top of the tube (m)
        for v, c in self.mixer_configs.items():
            parts = layout(c["geometry"], c["particles"]["diameter"])
            spans[v] = [[parts.tube.length - top, parts.tube.length - bottom] for bottom, top in
                        (m.z_range() for m in parts.mixers)]  # fmt: skip
        return json.dumps({"variants": list(self.mixers), "paper": self.config["mixer_study"].get("paper", {}),
                           "close_up": radial[0] if radial else None, "spans": spans,
                           "window": reference["figures"]["steady_window"],
                           "heated_zones": sorted(z for z, bc in thermal["walls"].items() if bc != "adiabatic"),
                           "specific_heat": reference["particles"]["specific_heat"],
                           "inlet_temperature": thermal["inlet_temperature"]}, sort_keys=True)  # fmt: skip

    def calibration_targets(self) -> list[str]:
        return [f"results/calibration/{v}/orifice.json" for v in self.variants]
