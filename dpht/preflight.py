"""The pre-flight check: everything a config asks for is checked when the workflow's plan is built,
before gmsh or LIGGGHTS run, with the functions the stages themselves use.

For every design variant and every scene of a study planned (:mod:`dpht.studies`; a study's own
section is checked by its module):

* the geometry as the geometry stage checks it (tube, heated range, orifice against the tube,
  mixers and their passages and clearances; :func:`dpht.geometry.layout.layout`), and its wall zones;
* the wall boundary conditions on those zones, each expression evaluated on points of the zones'
  surfaces (:func:`dpht.geometry.layout.sample_walls`; the thermal stage checks every element again), and
  every zone named in ``thermal.walls`` against the geometry's zones;
* the specific heat over the scene's temperature range (initial, inlet and wall temperatures), the
  particle conductivity (number or table) over it, the HTC tables' temperature range and the gas
  table over that range, and at a finite gas pressure the gas's molecular data and the
  accommodation coefficients of the temperature jump (none of the gas checks in a vacuum);
* the RDF tables: a given ``thermal.rdf_table`` is read and must cover the emissivities and both
  solid fractions; built tables must cover them with their grids, ``rdf_build.solid_fractions``
  for the bulk and the fixed near-wall grid (:func:`rdf_solid_fractions`); a measured solid
  fraction is checked after the DEM run, by the screening stage (or the thermal stage);
* the DEM run as the DEM stage checks it (fill height, orifice and tube against the particles,
  restart and dump intervals, seed) and its time step against the Rayleigh time;
* enough thermal frames for ``thermal.frame_stride`` and the figures' ``steady_window``.
* a chain's segments against the tube and its inserts (:class:`dpht.chain.segments.Chain`);
* resolved particles (``thermal.intraparticle``) and particle-gas convection only with an integrator
  that advances them (:func:`dpht.thermal.integrators.check_intraparticle`).

All problems are reported together, each once with the variants it concerns, prefixed with the file
and line that set the key when the config files are known (or naming Snakemake's ``--config``).
Warned about, not refused: ``dem.ranks`` above this machine's cores, and a run with no design
variant (``variants: {}``) and no study.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from dpht import config
from dpht.chain import scenes as chain_scenes
from dpht.chain.segments import Chain
from dpht.closures import gas, heat_capacity, htc, rdf
from dpht.dem.liggghts import RAYLEIGH_MAX, RAYLEIGH_WARN
from dpht.dem.params import DemParams
from dpht.errors import USER_ERRORS, ConfigError
from dpht.figures.windows import window_intervals
from dpht.radiation.tables import PW_SOLID_FRACTIONS
from dpht.thermal import integrators, model as thermal_model, modes
from dpht.thermal.slice import Slice
from dpht.thermal.schedule import frozen_times
from dpht.geometry.layout import layout, sample_walls

_CONDUCTION_GAS_MODES = ("pfp", "pfw")


def check(plan, sources: config.Sources | None = None) -> None:
    """Check every scene of ``plan`` (a :class:`dpht.plan.Plan`): its design variants and the
    scenes and sections of the studies planned; ConfigError lists every problem."""
    found: dict[str, list[str]] = {}
    for name, cfg in plan.configs.items():
        for problem in scene_problems(cfg):
            found.setdefault(config.locate([problem], sources, name)[0], []).append(name)
    warnings = [] if plan.variants or plan.studies else config.locate([
        "variants: {} names no design variant and the run lists no study, so `snakemake` makes nothing (a study "
        "named as a target still runs); give a variant (base: {} is the base scene) or list studies"], sources)
    for name, cfg in plan.configs.items():
        warnings += config.locate(ranks_warnings(cfg), sources, name)
    for warning in warnings:
        print(f"dpht: warning: {warning}", file=sys.stderr)
    _raise(found, _study_problems(plan.studies, sources), len(plan.configs) > 1, sources)


def check_studies(plan, planned: dict, sources: config.Sources | None = None) -> None:
    """Check the scenes and sections of ``planned`` studies ({name: dpht.studies.Planned}) of ``plan``."""
    _raise({}, _study_problems(planned, sources), False, sources)


def _study_problems(planned: dict, sources) -> dict[str, list[str]]:
    """{problem: [study]} of the studies ``planned``: their scenes (their own files: no line
    numbers of the run's config) and their sections' own problems."""
    found: dict[str, list[str]] = {}
    for study, plan in planned.items():
        for label, cfg in plan.scenes.items():
            for problem in scene_problems(cfg):
                found.setdefault(f"{study} ({label}): {problem}", []).append(study)
        for problem in plan.problems:
            found.setdefault(config.locate([problem], sources)[0], []).append(study)
    return found


def _raise(variants: dict, studies: dict, several: bool, sources) -> None:
    lines = [problem + (f" (variant{'s' * (len(names) > 1)} {', '.join(names)})" if several else "")
             for problem, names in variants.items()]  # fmt: skip
    lines += list(studies)
    if lines:
        raise ConfigError(f"{sources or 'config'}: the config cannot run (checked before any job started):\n  "
                          + "\n  ".join(lines))  # fmt: skip


def ranks_warnings(cfg: dict, cores: int | None = None) -> list[str]:
    """dem.ranks above the cores of this machine (``cores``, default all): a local run gives the DEM
    at most ``--cores`` ranks (the rule's threads), so the run would not have the ranks it asks for."""
    cores = cores or os.cpu_count() or 1
    ranks = cfg["dem"]["ranks"]
    if ranks <= cores:
        return []
    return [f"dem.ranks = {ranks}: this machine has {cores} cores, so a local run (snakemake --cores N) runs the DEM "
            f"on at most N ranks; {ranks} ranks need a cluster profile (profiles/slurm)"]


def _collect(problems: list[str], check_function, *args):
    """Run ``check_function(*args)``; a user error becomes a problem (returns None), else its result."""
    try:
        return check_function(*args)
    except USER_ERRORS as err:
        problems.append(str(err))
        return None


def scene_problems(cfg: dict) -> list[str]:
    """Every problem of one scene (a variant's merged config), as messages that start with the key."""
    problems: list[str] = []
    parts = _collect(problems, layout, cfg["geometry"], cfg["particles"]["diameter"])
    temperatures = [cfg["thermal"]["initial_temperature"], cfg["thermal"]["inlet_temperature"]]
    if parts is not None:
        walls = _collect(problems, thermal_model.wall_temperatures, sample_walls(parts), cfg["thermal"]["walls"])
        if walls is not None:
            temperatures += walls[np.isfinite(walls)].tolist()
        _collect(problems, _dem, cfg, parts)
        if "chain" in cfg:
            _collect(problems, _chain, cfg)
    _collect(problems, _materials, cfg, min(temperatures), max(temperatures))
    _collect(problems, _rdf, cfg)
    _collect(problems, integrators.check_intraparticle, cfg["thermal"])
    return problems


def _chain(cfg: dict) -> None:
    """A chain's segments built (:func:`dpht.chain.scenes.check`) and their DEM runs checked as the
    DEM stage checks them (naming the segment)."""
    bound = farthest_wall_temperature(cfg)
    chain_scenes.check(cfg, bound)
    found = chain_scenes.scenes(cfg, Chain.of(cfg), bound)
    for k, scene in enumerate(found):
        try:
            _dem({**scene.dem_config, "thermal": scene.config["thermal"]},
                 layout(scene.dem_config["geometry"], cfg["particles"]["diameter"]))
        except USER_ERRORS as err:
            raise ConfigError(f"chain: segment {k} ({scene.segment.kind}, z {scene.segment.bottom:.6g}-"
                              f"{scene.segment.top:.6g} m): its DEM run: {err}") from None


def farthest_wall_temperature(cfg: dict) -> float:
    """K: of a scene's wall temperatures, the one farthest from its inlet temperature (the inlet's
    without a heated wall); what a chain's segments after the first bound their tables with
    (:mod:`dpht.chain.scenes`)."""
    walls = thermal_model.wall_temperatures(sample_walls(layout(cfg["geometry"], cfg["particles"]["diameter"])),
                                            cfg["thermal"]["walls"])  # fmt: skip
    walls, inlet = walls[np.isfinite(walls)], cfg["thermal"]["inlet_temperature"]
    return float(walls[np.argmax(np.abs(walls - inlet))]) if walls.size else float(inlet)


def _materials(cfg: dict, T_low: float, T_high: float) -> None:
    """Specific heat, particle conductivity, HTC and gas tables over the scene's temperatures (K)."""
    p, t = cfg["particles"], cfg["thermal"]
    enthalpy = heat_capacity.build(heat_capacity.specific_heat(p["specific_heat"]), T_low, T_high)
    # The thermal model tabulates the conductivity over the enthalpy table's range (5 K wider).
    htc.solid_conductivity(p["conductivity"], np.linspace(enthalpy.T0, enthalpy.T_max, 64))
    if not any(t["modes"][m] for m in _CONDUCTION_GAS_MODES):
        return
    lo, hi = t["htc_table"]["temperature_range"]
    if not lo < hi:
        raise ConfigError(f"thermal.htc_table.temperature_range: [{lo}, {hi}] K must increase")
    if T_low < lo or T_high > hi:
        raise ConfigError(
            f"thermal.htc_table.temperature_range: the scene reaches {T_low:.1f}-{T_high:.1f} K (initial, "
            f"inlet and wall temperatures) but the HTC tables cover [{lo}, {hi}] K; widen it"
        )
    if not htc.gas_conducts(t):  # a vacuum: the tables are all 0, the gas is not read
        return
    grid = np.linspace(lo, hi, t["htc_table"]["temperatures"])
    try:
        gas.conductivity(t["gas"], grid)
    except USER_ERRORS as err:
        raise ConfigError(f"thermal.gas: {err} (the HTC tables cover thermal.htc_table.temperature_range)") from None
    htc.solid_conductivity(p["conductivity"], grid)
    if htc.rarefied(t["gas_pressure"]):
        try:
            gas.molecular(t["gas"])
        except USER_ERRORS as err:
            raise ConfigError(f"thermal.gas: {err}; give them, or set thermal.gas_pressure: continuum") from None
        try:
            htc.accommodation_of(t.get("accommodation"), t["gas"])
        except USER_ERRORS as err:
            raise ConfigError(f"thermal.accommodation: {err}") from None


def _inside(key: str, value: float, grid, what: str) -> None:
    lo, hi = min(grid), max(grid)
    if not lo <= value <= hi:
        raise ConfigError(f"{key} = {value} is outside {what}, {lo}-{hi}")


def rdf_solid_fractions(cfg: dict) -> dict[str, tuple[np.ndarray, str]]:
    """The solid fractions the RDF tables of a scene cover, by table ("pp": the bulk, "pw": the
    near-wall band), each with the words naming the tables: the files of ``thermal.rdf_table`` at
    the scene's emissivities, or the tables the workflow builds, the particle-particle one at
    ``thermal.rdf_build.solid_fractions`` and the particle-wall one at its fixed near-wall solid
    fractions (:data:`dpht.radiation.tables.PW_SOLID_FRACTIONS`). ConfigError for tables that
    cannot be read or do not cover the emissivities."""
    t = cfg["thermal"]
    if "rdf_table" not in t:
        grid = t["rdf_build"]["solid_fractions"]
        if np.any(np.diff(grid) <= 0):
            raise ConfigError(f"thermal.rdf_build.solid_fractions: {grid} must increase strictly")
        return {"pp": (np.asarray(grid, dtype=float), "the solid fractions the RDF tables are built at "
                                                      "(thermal.rdf_build.solid_fractions)"),
                "pw": (np.asarray(PW_SOLID_FRACTIONS), "the near-wall solid fractions the PW RDF table is built at "
                                                       "(fixed: dpht/radiation/tables.py)")}  # fmt: skip
    files = [t["rdf_table"]] if isinstance(t["rdf_table"], str) else t["rdf_table"]
    try:
        tables = rdf.for_emissivities([rdf.load(f) for f in files], cfg["particles"]["emissivity"],
                                      cfg["wall"]["emissivity"])  # fmt: skip
    except USER_ERRORS as err:
        raise ConfigError(f"thermal.rdf_table: {err}") from None
    return {kind: (getattr(tables, kind).solid_fraction, f"the solid fractions of the {kind.upper()} RDF table {', '.join(files)}")
            for kind in ("pp", "pw")}  # fmt: skip


def _rdf(cfg: dict) -> None:
    """The RDF tables cover the emissivities and the bulk (PP) and near-wall (PW) solid fractions."""
    t = cfg["thermal"]
    used = {"pp": t["modes"]["pp_radiation"], "pw": t["modes"]["pw_radiation"]}
    if not any(used.values()):
        return
    phi = modes.solid_fractions(t["solid_fraction"])
    region = {"pp": "bulk", "pw": "near_wall"}
    # A measured solid fraction is known after the DEM run: the screening stage checks it then, or
    # else the thermal stage before it starts (dpht.thermal.decisions.check_measured).
    used = {kind: on and not modes.is_measured(phi[region[kind]]) for kind, on in used.items()}
    key = "thermal.solid_fraction" + ("" if isinstance(t["solid_fraction"], (int, float)) else ".{}")
    grids = rdf_solid_fractions(cfg)
    for kind in (k for k, on in used.items() if on):
        _inside(key.format(region[kind]), phi[region[kind]], *grids[kind])


def _dem(cfg: dict, parts) -> None:
    """The DEM stage's own checks (:func:`dem_params`), its time step, and the frames the thermal
    stage (:func:`thermal_times`) and the figures get."""
    params = dem_params(cfg, parts)
    fraction = params.timestep / params.rayleigh_time
    if fraction > RAYLEIGH_MAX:
        raise ConfigError(
            f"dem.timestep = {params.timestep} s is {fraction:.2f} of the Rayleigh time {params.rayleigh_time:.3e} s "
            f"(particles.diameter, density, youngs_modulus_dem, poisson_ratio); keep it below {RAYLEIGH_WARN} "
            f"(at most {RAYLEIGH_WARN * params.rayleigh_time:.2e} s)"
        )
    times = thermal_times(cfg, params)
    try:
        window_intervals(times, cfg["figures"]["steady_window"])
    except USER_ERRORS as err:
        raise ConfigError(f"figures.steady_window = {cfg['figures']['steady_window']}: {err} "
                          f"({times.size} thermal frames)") from None  # fmt: skip


def dem_params(cfg: dict, parts) -> DemParams:
    """The DEM stage's parameters of a scene (checked as the stage checks them) on a geometry
    summary made from its layout ``parts`` (mixer volumes unknown before gmsh: they only size the fill)."""
    summary = {
        "geometry": cfg["geometry"],
        "zone_names": list(parts.zone_names),
        "mixers": [{"key": m.key, "zone": m.zone, "z_range": list(m.z_range()), "volume": 0.0} for m in parts.mixers],
    }
    return DemParams.from_spec(config.dem_spec(cfg), summary)


def thermal_times(cfg: dict, params: DemParams) -> np.ndarray:
    """Times (s, from the first) of the thermal stage's frames of a scene whose DEM run has
    ``params``; ConfigError when they cannot make a run."""
    steps = params.steps()
    dem_frames = (steps["flow_end"] - steps["settle_end"]) // params.dump_interval + 1
    stride = cfg["thermal"]["frame_stride"]
    frames = np.arange(0, dem_frames, stride)
    frozen = cfg["thermal"].get("frozen_bed")
    if frozen:  # one DEM frame held: the thermal frames are its steps
        if not -dem_frames <= frozen.get("frame", 0) < dem_frames:
            raise ConfigError(f"thermal.frozen_bed.frame = {frozen['frame']}: the DEM run writes {dem_frames} frames")
        times = frozen_times(frozen)
    elif frames.size < 2:
        raise ConfigError(
            f"thermal.frame_stride = {stride}: the DEM run writes {dem_frames} frames (dem.flow_time / "
            f"(dem.dump_interval x dem.timestep) + 1), which leaves {frames.size} thermal frame; at least 2 are needed"
            + (" (dem.flow_time 0 is a static bed: give it thermal.frozen_bed)" if params.flow_time == 0 else "")
        )
    else:
        times = frames * params.dump_interval * params.timestep
    # A travelling slice reuses its frames until it has travelled its distance, at the drive's velocity
    # (config.thermal_spec: a ConfigError for a drive without one, a mass_flow or orifice drive).
    s = Slice.of(config.thermal_spec(cfg)["thermal"]) if "slice" in cfg["thermal"] else None
    if s is not None:
        record = s.record
        step = stride * params.dump_interval * params.timestep
        if record is not None and record > params.flow_time * (1 + 1e-9):
            raise ConfigError(f"thermal.slice.record = {record} s: longer than the DEM's record, dem.flow_time = "
                              f"{params.flow_time} s")
        if record is not None and record < step * (1 - 1e-9):
            raise ConfigError(f"thermal.slice.record = {record} s: shorter than one thermal step ({step:.6g} s); "
                              "the reused record needs two frames")
        frames = np.arange(s.n_frames(step)) * stride
        times = frames * params.dump_interval * params.timestep
        # The cell list needs a periodic axis at least 2.5 of the largest pair cutoff long.
        cutoff = max((m.cutoff_radii(cfg["thermal"]) for m in modes.MODES
                      if m.side == "pp" and cfg["thermal"]["modes"][m.name] is not False), default=0.0)
        if params.length < 2.5 * cutoff * params.radius:
            raise ConfigError(f"geometry.tube.length = {params.length} m: a periodic slice must be at least 2.5 pair "
                              f"cutoffs ({cutoff} radii) long, {2.5 * cutoff * params.radius:.4g} m; shorten the "
                              "cutoff (thermal.radiation_cutoff, pfp_cutoff) or lengthen the slice")
    return times
