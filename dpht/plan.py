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
import json
from dataclasses import dataclass, field
from pathlib import Path

from dpht import config, preflight
from dpht.thermal import modes
from geometry.errors import GeometryError
from geometry.layout import layout
from geometry.stl_mixer import file_digest

# Per-variant figures of the `figures` rule; each has a caption workflow/report/<name>.rst.
FIGURES = ("cross_section", "wall_heat_flux", "wall_heat_history", "temperature_profiles", "htc_curves")

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


def from_workflow(snakemake_config: dict, configfiles) -> Plan:
    """The plan of Snakemake's ``config`` merged from ``configfiles`` (``workflow.configfiles``),
    validated and checked before any job runs (:mod:`dpht.preflight`); errors name file and line.
    The variants are those of the last file naming any (see :mod:`dpht.config`)."""
    sources = config.Sources(configfiles)
    plan = Plan(config.validate(sources.with_variants(snakemake_config), source=str(sources), sources=sources))
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


def path(stage: str, key: str, file: str) -> str:
    """Where run ``key`` of ``stage`` writes ``file`` (the table stages write one file, ``file`` unused;
    a shipped table is read where it is shipped)."""
    if stage in TABLE_FOLDERS:
        shipped = SHIPPED / TABLE_FOLDERS[stage] / "shipped" / f"{key}.h5"
        return str(shipped) if shipped.is_file() else f"tables/{TABLE_FOLDERS[stage]}/{key}.h5"
    return f"results/{stage}/{key}/{file}"


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
        for name in self.variants:
            self.configs[name] = _with_file_digests(config.variant(cfg, name))
            self.keys[name] = self.register_scene(self.configs[name])
        self.study = None  # key of the radiation-model study (DPHT paper, Section 4), when configured
        if "radiation_study" in cfg:
            study_rdf = self._register("rdf", config.radiation_study_rdf_spec(cfg))
            self.study = self._register("radiation_study", config.radiation_study_spec(cfg), rdf=study_rdf)
        # key of the intra-particle study (lumped against resolved particles over Bi), when configured
        self.intraparticle_study = (self._register("intraparticle_study", config.intraparticle_study_spec(cfg))
                                    if "intraparticle_study" in cfg else None)  # fmt: skip

    def register_scene(self, c: dict) -> dict:
        """Register the stage runs of one scene (a variant's merged config ``c``); returns
        {stage: key, or None for a stage the scene does not run}. Studies that derive scenes from
        the config (other thermal steps, effects switched off, ...) register them the same way."""
        geometry = self._register("geometry", config.geometry_spec(c))
        dem = self._register("dem", config.dem_spec(c), geometry=geometry)
        # Not part of the key: ranks and the mass-flow check do not change the DEM result
        # (scenes sharing a DEM run share these too; the last one registered wins).
        self.runs[dem].settings.update(ranks=c["dem"]["ranks"], checks=config.dem_checks(c))
        pfp = self._register("pfp", config.htc_spec(c, "pfp", dem))
        pfw = self._register("pfw", config.htc_spec(c, "pfw", dem))
        rdf = config.rdf_spec(c)
        rdf = self._register("rdf", rdf) if rdf is not None else None
        try:
            zones = layout(c["geometry"], c["particles"]["diameter"]).zone_names
        except GeometryError:  # reported by the pre-flight check with the config's other problems
            zones = None
        thermal = config.thermal_spec(c, zones, dem)
        thermal = self._register("thermal", thermal, geometry=geometry, dem=dem, pfp=pfp, pfw=pfw, rdf=rdf)
        self.runs[thermal].settings.update(checkpoints=config.thermal_checkpoints(c))  # not part of the key either
        return {"geometry": geometry, "dem": dem, "pfp": pfp, "pfw": pfw, "rdf": rdf, "thermal": thermal}

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

    def thermal_inputs(self, key: str) -> dict:
        """DEM frames and summary (the measured solid fractions, the wall surfaces LIGGGHTS used),
        wall table, HTC tables and, with radiation, the RDF table(s): built by the workflow, or the
        file (or list of files) named by ``thermal.rdf_table``."""
        inputs = {
            "positions": self.upstream_file(key, "dem", "positions.h5"),
            "dem_summary": self.upstream_file(key, "dem", "summary.json"),
            "walls": self.upstream_file(key, "geometry", "walls.h5"),
            "pfp": self.upstream_file(key, "pfp"),
            "pfw": self.upstream_file(key, "pfw"),
        }
        if self.runs[key].upstream["rdf"] is not None:
            inputs["rdf"] = self.upstream_file(key, "rdf")
        elif "rdf_table" in self.runs[key].spec["thermal"]:
            inputs["rdf"] = self.runs[key].spec["thermal"]["rdf_table"]
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
        orifice = c["geometry"]["tube"]["orifice_height"]
        return json.dumps(
            {
                "window": c["figures"]["steady_window"],
                "heated_zones": sorted(z for z, bc in c["thermal"]["walls"].items() if bc != "adiabatic"),
                "radial_band": [orifice, orifice + 2 * d],
                "htc": {  # the solid fractions: those the thermal run used (its summary)
                    "radius": d / 2,
                    "k_solid": c["particles"]["conductivity"],
                    "gas": c["thermal"]["gas"],
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
        return targets

    def calibration_targets(self) -> list[str]:
        return [f"results/calibration/{v}/orifice.json" for v in self.variants]
