"""The workflow's plan: stage keys, rule inputs, parameters and targets, from the validated config.

The Snakemake rules (``workflow/rules/*.smk``) are thin: each asks a :class:`Plan` for its inputs
and parameters and runs one stage (:mod:`dpht.stages`). Everything they used to compute inline is
here, where it is unit-tested without Snakemake.

Caching: each stage run writes into a folder named by its *key*, a hash of the parameters the stage
depends on and of the keys of the stage runs it reads (``results/<stage>/<key>/``, tables in
``tables/<kind>/<key>.h5``). Design variants therefore share every stage run they do not change, a
changed parameter re-runs exactly the stages downstream of it, and earlier results stay on disk.
Settings that change how a run is executed or checked, not its result (MPI ranks, the mass-flow
target), ride along outside the key. Every path is :mod:`dpht.paths`'.

The plan holds the stage graph of the design (geometry, DEM, tables, screening, thermal, figures,
variant summary, comparison); studies (:mod:`dpht.studies`) register their scenes and stage runs
into it through :meth:`Plan.register_scenes` and :meth:`Plan.register`. From Python:
``from_files(["config/config.yaml", "my_design.yaml"])`` plans as ``snakemake --configfile
my_design.yaml`` does.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from dpht import config, paths, preflight, studies
from dpht.chain import handover, scenes as chain_scenes
from dpht.chain.segments import Chain
from dpht.errors import USER_ERRORS, ConfigError
from dpht.thermal import effects, modes
from dpht.geometry.errors import GeometryError
from dpht.geometry.layout import layout
from dpht.geometry.stl_mixer import file_digest

# Per-variant figures of the `figures` rule; each has a caption workflow/report/<name>.rst.
FIGURES = ("cross_section", "wall_heat_flux", "wall_heat_history", "temperature_profiles", "htc_curves", "engineering")
COMPARISON = ("variants.png", "cross_sections.png")  # results/<run>/comparison/: the variants compared

path = paths.stage_file  # where a stage run writes a file (the one table of every path: dpht.paths)

DESIGN = "design"  # the owner of the design variants' scenes (Plan.scene_users), beside the studies


@dataclass(frozen=True)
class ReportItem:
    """Where a file sits in ``snakemake --report``: its category (the run's design, or a study),
    its subcategory (a design variant, or a kind of output) and its labels, the columns of the
    subcategory's table: ``figure``, ``variant`` (the scenes it shows) and ``study``."""

    category: str
    subcategory: str
    labels: dict[str, str]


def _title(file: str) -> str:
    """A report label of an output file or figure name: ``wall_heat_flux.png`` -> ``wall heat flux``."""
    return Path(file).stem.replace("_", " ")


@dataclass(frozen=True)
class SegmentLink:
    """How a chain's segment stage run sits in its chain: the key of the segment run upstream (None
    for the first), whose hand-over field it starts from (and, resolved, is fed by), where it sits
    (its ends and, resolved, its outlet plane in its DEM) and its hand-over's parameters."""

    upstream: str | None
    place: handover.Place
    handover: handover.Spec


@dataclass(frozen=True)
class ChainRuns:
    """A design variant's chain as stage runs: its segment runs in flow order, the DEM runs they
    use (one per resolved shape, one for every slice), and the chain summary's parameters."""

    segments: tuple[str, ...]
    dem: tuple[str, ...]
    spec: dict


@dataclass(frozen=True)
class Run:
    """One stage run: what its key hashes (``spec`` and the ``upstream`` keys) and what rides along."""

    stage: str
    key: str
    spec: dict
    upstream: dict
    settings: dict = field(default_factory=dict)  # not part of the key


def from_files(files: Iterable, studies_asked: Iterable[str] = ()) -> Plan:
    """The plan of config ``files`` merged in order (as Snakemake merges ``--configfile`` files over
    config/config.yaml: pass that first for the command line's view), validated and checked before
    any job (:mod:`dpht.preflight`); errors name file and line. The run's name and studies are the
    last file's (:class:`dpht.config.Sources`); ``studies_asked`` plans more studies (their targets
    are then :meth:`Plan.study_targets`)."""
    sources = config.Sources(list(files))
    return _checked(config.validate(sources.merged(), source=str(sources), sources=sources), sources, studies_asked)


def from_workflow(snakemake_config: dict, configfiles, overrides=(), command_line=None) -> Plan:
    """The plan of Snakemake's ``config`` merged from ``configfiles`` (``workflow.configfiles``),
    validated and checked before any job runs (:mod:`dpht.preflight`); errors name file and line.
    The variants are those of the last file naming any, the run's name and studies the last file's
    (see :mod:`dpht.config`).

    ``overrides``: the command line's ``--configfile`` files (``workflow.overwrite_configfiles``).
    Snakemake lists them in ``configfiles`` before the Snakefile's ``configfile:`` but merges them
    over it, so they are moved last: ``--configfile my_design.yaml`` names the run and its studies.
    ``command_line``: the values of ``--config`` (``workflow.config_settings.config``), which
    errors name as such."""
    given = {Path(f).resolve() for f in overrides}
    sources = config.Sources([f for f in configfiles if Path(f).resolve() not in given] + list(overrides), command_line)
    merged = config.merge(copy.deepcopy(snakemake_config), config.command_line_values(command_line or {}))
    cfg = config.validate(sources.with_own_keys(merged), source=str(sources), sources=sources)
    return _checked(cfg, sources)


def _checked(cfg: dict, sources: config.Sources, studies_asked: Iterable[str] = ()) -> Plan:
    plan = Plan(cfg, sources)
    for name in studies_asked:
        plan.study(name)
    preflight.check(plan, sources)
    return plan


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
    shipped = sorted((paths.SHIPPED / "rdf" / "shipped").glob("*.h5"))
    emissivity = np.array([c["particles"]["emissivity"], c["wall"]["emissivity"]])
    return str(min(shipped, key=lambda f: float(np.abs(_emissivities(f) - emissivity).sum())))


@functools.cache
def _emissivities(table: Path) -> np.ndarray:
    with h5py.File(table, "r") as f:
        return np.array([f.attrs["particle_emissivity"], f.attrs["wall_emissivity"]], dtype=float)


def figure(variant: str, name: str, run: str) -> str:
    """Figure ``name`` (one of FIGURES) of design ``variant`` of run ``run``."""
    return paths.FIGURE.format(run=run, variant=variant, name=name)


class Plan:
    """Stage runs and targets of a validated config (:func:`dpht.config.validate`): every design
    variant, and the studies it asks for (``studies``, :mod:`dpht.studies`) or that are asked for by
    name later (:meth:`study`, e.g. a study's rule named as a Snakemake target).

    ``name``: the run's folder, results/<name>/ (:mod:`dpht.paths`); ``sources``: the config files,
    to say which file and line set a key in the pre-flight messages of a study planned later."""

    def __init__(self, cfg: dict, sources: config.Sources | None = None):
        self.config = cfg
        self.name = cfg["name"]
        self.sources = sources
        self.variants = list(cfg["variants"])
        self.runs: dict[str, Run] = {}
        self.keys: dict[str, dict] = {}  # variant -> {stage: key or None}
        self.configs: dict[str, dict] = {}  # variant -> its merged config
        self.screening_rdf: dict[str, str | None] = {}  # screening key -> the RDF table its radiation estimate reads
        # stage key -> (owner, scene label) of every scene using it; owner DESIGN or a study's name
        self.scene_users: dict[str, list[tuple[str, str]]] = {}
        self._planning = DESIGN  # the owner of the scenes being registered
        self.chains: dict[str, ChainRuns] = {}  # variant -> its chain, for variants with a chain section
        for name in self.variants:
            self.configs[name] = _with_file_digests(config.variant(cfg, name))
            self.keys[name] = self._used(name, self.register_scene(self.configs[name]))
            if "chain" in self.configs[name]:
                try:
                    self.chains[name] = self.register_chain(name, self.configs[name])
                except USER_ERRORS:  # reported by the pre-flight check with the config's other problems
                    pass
        studies.check_asked(cfg["studies"])
        self.asked = tuple(cfg["studies"])  # the studies the config asks for: targets of `all`
        self.studies: dict[str, studies.Planned] = {}  # every study planned so far
        for name in self.asked:
            self._plan_study(name)

    def _plan_study(self, name: str) -> studies.Planned:
        study = studies.STUDIES[name]
        self._planning = name
        try:
            self.studies[name] = study.plan(self, studies.section_of(self.config, study))
        except ConfigError as err:  # a problem of its section: named with the file and line that set it
            text = str(err)
            raise ConfigError(config.locate([text], self.sources)[0] if text.startswith(study.section) else text) from None
        finally:
            self._planning = DESIGN
        return self.studies[name]

    def _used(self, label: str, keys: dict) -> dict:
        """Record that scene ``label`` of the owner being planned uses the stage runs ``keys``."""
        for key in keys.values():
            if key is not None and (self._planning, label) not in self.scene_users.setdefault(key, []):
                self.scene_users[key].append((self._planning, label))
        return keys

    def study(self, name: str) -> studies.Planned:
        """Study ``name`` planned (its scenes registered, checked before any of their jobs, with
        :mod:`dpht.preflight`, when it was not asked for by the config)."""
        if name in self.studies:
            return self.studies[name]
        studies.check_asked([name], "study")
        planned = self._plan_study(name)
        preflight.check_studies(self, {name: planned}, self.sources)
        return planned

    def register_scenes(self, scenes: dict[str, dict], study: bool = False) -> dict[str, dict]:
        """Each of ``scenes`` ({label: merged config}, its STL mixers' digests added) registered as
        :meth:`register_scene` does; returns {label: stage keys}."""
        return {label: self._used(label, self.register_scene(_with_file_digests(c), study)) for label, c in scenes.items()}

    def register_chain(self, variant: str, c: dict) -> ChainRuns:
        """Register the stage runs of design ``variant``'s chain (its merged config ``c`` with a
        ``chain`` section, :mod:`dpht.chain.scenes`): per segment in flow order the scene's stages,
        their DEM run shared by every segment of one shape (and by every slice), and a segment stage
        run (:func:`dpht.stages.segment`) started from the hand-over of the one above."""
        chain = Chain.of(c)
        found = chain_scenes.scenes(c, chain, preflight.farthest_wall_temperature(c))
        d, p = c["particles"]["diameter"], c["particles"]
        mass = p["density"] * 4.0 / 3.0 * np.pi * (d / 2) ** 3
        spec = handover.Spec(chain.field.rings, chain.field.sectors, c["geometry"]["tube"]["inner_diameter"] / 2,
                             tuple(c["figures"]["steady_window"]), chain_scenes.mass_flow(c), mass, d)  # fmt: skip
        segments, upstream = [], None
        for k, scene in enumerate(found):
            place = handover.Place(scene.segment.bottom, scene.segment.top, scene.plane)
            keys = self._used(f"{variant} segment {k}", self.register_scene(scene.config, dem_scene=scene.dem_config,
                                                                            segment=SegmentLink(upstream, place, spec)))
            upstream = keys["thermal"]
            segments.append((scene.segment, keys))
        summary = {"segments": [{"kind": s.kind, "bottom": s.bottom, "top": s.top, "key": keys["thermal"], "dem": keys["dem"],
                                 "inserts": [i.index for i in s.inserts], "outlet": s.outlet} for s, keys in segments],
                   "mass_flow": spec.mass_flow, "inlet_temperature": c["thermal"]["inlet_temperature"],
                   "specific_heat": p["specific_heat"], "shapes": len(chain.shapes(c["geometry"]))}  # fmt: skip
        dem = tuple(dict.fromkeys(keys["dem"] for _, keys in segments))
        return ChainRuns(tuple(keys["thermal"] for _, keys in segments), dem, summary)

    def register_scene(self, c: dict, study: bool = False, dem_scene: dict | None = None,
                       segment: SegmentLink | None = None) -> dict:  # fmt: skip
        """Register the stage runs of one scene (a variant's merged config ``c``); returns
        {stage: key, or None for a stage the scene does not run}. Studies that derive scenes from
        the config (other thermal steps, effects switched on, ...) register them the same way
        (``study``: their run settings never replace a variant's). A chain's segment
        (:meth:`register_chain`) has its DEM run from ``dem_scene`` (its geometry's wall zones the
        scene's, its heated zone perhaps cut elsewhere) and, in place of the thermal stage, a
        segment stage run placed in its chain by ``segment`` (its key under "thermal")."""
        geometry = self.register("geometry", config.geometry_spec(c))
        moved = dem_scene if dem_scene is not None else c
        dem_geometry = self.register("geometry", config.geometry_spec(moved)) if dem_scene is not None else geometry
        dem = self.register("dem", config.dem_spec(moved), geometry=dem_geometry)
        # Not part of the key: ranks and the mass-flow check do not change the DEM result
        # (scenes sharing a DEM run share these too; the last variant registered wins).
        if not (study and self.runs[dem].settings):
            self.runs[dem].settings.update(ranks=moved["dem"]["ranks"], checks=config.dem_checks(moved))
        try:
            zones = layout(c["geometry"], c["particles"]["diameter"]).zone_names
        except GeometryError:  # reported by the pre-flight check with the config's other problems
            zones = None
        # Tables only for the modes that are on or may be once the screening stage has decided.
        decisions = effects.from_config(c["thermal"], zones)
        possible = effects.possible_modes(decisions)
        htc_specs = {kind: config.htc_spec(c, kind, dem) for kind in ("pfp", "pfw") if kind in possible}
        pfp, pfw = (self.register(kind, htc_specs[kind]) if kind in htc_specs else None for kind in ("pfp", "pfw"))
        rdf = config.rdf_spec(c, zones)
        rdf = self.register("rdf", rdf) if rdf is not None else None
        thermal = config.thermal_spec(c, zones, dem)
        screening = None
        if effects.pending(decisions):  # the scene's settled bed decides the rest
            screening = self.register("screening", config.screening_spec(thermal, htc_specs), geometry=geometry, dem=dem)
            self.screening_rdf[screening] = screening_rdf(c) if possible & set(modes.needing("rdf")) else None
        upstream = {"geometry": geometry, "dem": dem, "pfp": pfp, "pfw": pfw, "rdf": rdf, "screening": screening}
        if segment is None:
            thermal = self.register("thermal", thermal, **upstream)
        else:
            place = {k: v for k, v in dataclasses.asdict(segment.place).items() if k != "velocity"}  # a slice's: its spec's
            thermal = self.register("segment", {**thermal, "outlet": place, "handover": dataclasses.asdict(segment.handover)},
                                    **upstream, segment=segment.upstream)  # fmt: skip
        if not (study and self.runs[thermal].settings):  # not part of the key either
            self.runs[thermal].settings.update(checkpoints=config.thermal_checkpoints(c), effects=decisions)
        return {"geometry": geometry, "dem": dem, "pfp": pfp, "pfw": pfw, "rdf": rdf, "screening": screening,
                "thermal": thermal}  # fmt: skip

    def register(self, stage: str, spec: dict, **upstream) -> str:
        """Register a run of ``stage`` computing from ``spec`` and the ``upstream`` runs ({stage: key});
        returns its key (a run registered twice is one run)."""
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
        if run.upstream.get("segment") is not None:  # a chain's segment: the hand-over of the one above
            inputs["initial_field"] = self.upstream_file(key, "segment", "handover.h5")
            if run.spec["outlet"]["plane"] is not None:  # resolved: also what re-enters at its top
                inputs["inlet_field"] = inputs["initial_field"]
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

    def keyed_inputs(self, key: str) -> dict:
        """The tables run ``key`` of a study's keyed stage reads (:class:`dpht.studies.KeyedStage`):
        {upstream stage: its table}."""
        return {stage: path(stage, upstream) for stage, upstream in self.runs[key].upstream.items()}

    def scene_files(self, keys: dict, files: dict) -> dict:
        """Files of a registered scene's stage runs (``keys``, as :meth:`register_scene` returns
        them): ``files`` maps an input name to (stage, file)."""
        return {name: path(stage, keys[stage], file) for name, (stage, file) in files.items()}

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
                **{f"figure_{name}": figure(variant, name, self.name) for name in FIGURES}}  # fmt: skip

    def comparison_inputs(self) -> dict:
        files = {"thermal": ("thermal", "thermal.h5"), "walls": ("geometry", "walls.h5"), "positions": ("dem", "positions.h5")}
        return {f"{name}_{v}": self.variant_file(v, stage, file) for name, (stage, file) in files.items()
                for v in self.compared}  # fmt: skip

    @property
    def compared(self) -> list[str]:
        """The variants run as one tube, not as a chain: those the comparison shows (and with figures
        and a headline)."""
        return [v for v in self.variants if v not in self.chains]

    def chain_inputs(self, variant: str) -> dict:
        """The summary and hand-over field of every segment run of ``variant``'s chain, in flow order."""
        return {f"{name}_{k}": path("segment", key, file) for k, key in enumerate(self.chains[variant].segments)
                for name, file in (("summary", "summary.json"), ("handover", "handover.h5"))}  # fmt: skip

    def chain_spec(self, variant: str) -> str:
        return json.dumps(self.chains[variant].spec, sort_keys=True)

    # --- parameters (JSON for `python -m dpht stage NAME --spec ...`) ---------------------------

    def spec_json(self, key: str) -> str:
        run = self.runs[key]
        spec = run.spec
        if run.stage == "dem":  # the mass-flow check rides along: changing it re-checks the cached run
            spec = {**spec, "dem": {**spec["dem"], **run.settings["checks"]}}
        elif run.stage in ("thermal", "segment"):  # and how often the thermal stage saves its state
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
                "radial_band": config.radial_band(c),
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
        return json.dumps({"variants": self.compared, "window": self.config["figures"]["steady_window"]})

    def calibration_spec(self, variant: str) -> str:
        return json.dumps(self.configs[variant], sort_keys=True)

    def calibration_threads(self, variant: str) -> int:
        return self.configs[variant]["dem"]["ranks"]

    # --- the report (`snakemake --report`) -----------------------------------------------------

    @property
    def design_category(self) -> str:
        return f"Design: {self.name}"

    def _labels(self, figure: str, variants, owners) -> dict[str, str]:
        """The labels of a report item: ``variants`` the scenes it shows (the first four named),
        ``owners`` the design or the studies they belong to."""
        names = list(dict.fromkeys(variants))
        variant = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
        owners = [f"{DESIGN}: {self.name}" if o == DESIGN else o for o in dict.fromkeys(owners)]
        return {"figure": figure, "variant": variant or "-", "study": ", ".join(owners)}

    def variant_report(self, variant: str, file: str) -> ReportItem:
        """A figure or table of design ``variant``: in the design's category, its own subcategory."""
        return ReportItem(self.design_category, variant, self._labels(_title(file), [variant], [DESIGN]))

    def comparison_report(self, file: str) -> ReportItem:
        return ReportItem(self.design_category, "Comparison", self._labels(_title(file), self.compared, [DESIGN]))

    def geometry_report(self, key: str) -> ReportItem:
        """The picture of geometry run ``key``: in the category of the first owner of a scene using
        it (the design, or a study), subcategory Geometry, labelled with every scene using it."""
        users = self.scene_users[key]
        owner = users[0][0]
        category = self.design_category if owner == DESIGN else studies.STUDIES[owner].category
        return ReportItem(category, "Geometry", self._labels("geometry", [s for _, s in users], [o for o, _ in users]))

    def study_report(self, name: str, output: str) -> ReportItem:
        """Output ``output`` of study ``name`` (planning it first): in the study's category, Figures
        or Tables, labelled with the study's scenes."""
        file = studies.STUDIES[name].outputs[output].file
        kind = "Figures" if Path(file).suffix == ".png" else "Tables"
        return ReportItem(studies.STUDIES[name].category, kind, self._labels(_title(file), self.study(name).scenes, [name]))

    # --- targets -------------------------------------------------------------------------------

    def targets(self) -> list[str]:
        """Every figure and summary of every variant (a variant with a chain: its chain's summary),
        their comparison when there are several without a chain, and the outputs of every study the
        config asks for."""
        whole = [v for v in self.variants if v not in self.chains]
        targets = [figure(v, name, self.name) for v in whole for name in FIGURES]
        targets += [paths.SUMMARY.format(run=self.name, variant=v) for v in whole]
        targets += [paths.CHAIN.format(run=self.name, variant=v) for v in self.chains]
        if len(whole) > 1:
            targets += self.comparison_files()
        return targets + [t for name in self.asked for t in self.study_targets(name)]

    def comparison_files(self) -> list[str]:
        return [paths.COMPARISON.format(run=self.name, file=file) for file in COMPARISON]

    def study_targets(self, name: str) -> list[str]:
        """The outputs of study ``name`` in this run's folder (planning it first)."""
        self.study(name)
        return list(studies.STUDIES[name].files(self.name).values())

    def calibration_targets(self) -> list[str]:
        return [paths.CALIBRATION.format(run=self.name, variant=v) for v in self.variants]
