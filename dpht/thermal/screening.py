"""Screening: which of a scene's effects matter, decided on the scene's own settled bed.

The ``screening`` stage runs after the DEM run and before the thermal stage, for every scene whose
config leaves a switch at ``auto`` that the config alone cannot decide
(:func:`dpht.thermal.effects.from_config`). On the first DEM frame (the settled bed the flow
starts from) it builds the thermal model with every mode that may be on and lists the frame's
pairs and wall contacts once (:func:`dpht.thermal.network.assemble`, the implicit integrator's
network). Then, with every particle and every Dirichlet wall element at one temperature T, it sums
each mode's conductances over the frame — the mode alone, through the very kernels of the thermal
stage — at the scene's coldest and hottest temperatures (initial, inlet, walls), weighted as the
heat they carry scales (:func:`conductance_sums`: pairs by their squared span, as they add to the
bed's effective conductivity; wall contacts by their distance from the wall). A mode's *share* is
its sum over the sum of every candidate mode on its side (particle-particle or particle-wall); it
is switched off when its larger share stays below ``thermal.screening_threshold``.
Radiation's conductance is the exact secant εAσD (T_i² + T_j²)(T_i + T_j) = 4εAσD T³ at one
temperature, so its share grows as T³ (and the gas gap's with k_f(T)).

The gas-gap modes are evaluated from HTC tables built in memory (the closures of Eqs. 8-24, as
the ``htc_table`` stage builds them: a fraction of a second), the radiation modes from an RDF table:
the scene's own where it is a file already (``thermal.rdf_table`` or a shipped table), otherwise
the shipped table nearest in emissivity (:func:`dpht.plan.screening_rdf`). Its distribution
factors D are those of another emissivity then; the screening uses them with the scene's own ε in
εAσD (the D of a bed sum to about one whatever the emissivity, so the sum of a particle's
radiative conductances is about right; where it matters, ``screening_check`` measures the
decision's effect with the scene's own table). Solid fractions outside the RDF table's range are
clamped to it for the estimate.

Resolved intra-particle conduction (``thermal.intraparticle: auto``) is decided here too, on the
same frame, by the particles' Biot number (:func:`dpht.thermal.stage.decide_intraparticle`).
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np

from dpht.closures import rdf
from dpht.dem.dumps import PositionsFile
from dpht.errors import DPHTError
from dpht.thermal import effects, integrate, model as thermal_model, modes as registry, network
from dpht.thermal.effects import Decision
from dpht.thermal.decisions import DemRun, check_measured, decide_intraparticle, resolve_solid_fractions, wall_kinds
from dpht.thermal.schedule import Schedule
from dpht.geometry.walls import load_walls

log = logging.getLogger("dpht")

FORMAT = "dpht-screening-1"


def conductance_sums(model: thermal_model.ThermalModel, net: network.Network, temperature: float,
                     weighted: bool = True) -> dict[str, float]:
    """Each enabled mode's conductances alone, with every particle and every Dirichlet wall element
    at ``temperature`` (K), summed as the heat they carry scales: over the pairs of ``net`` (a
    frame's network, :func:`dpht.thermal.network.assemble`; its conductances are overwritten) (PP modes)
    weighted by the pair's squared centre distance, Σ G r² (W m²/K: the bed's effective
    conductivity, (1/V) Σ G (r·e)², is what a pair adds to the heat flux in a uniform gradient, and
    it grows with the square of the pair's span, so long-range radiation counts for more than its
    conductance), over the wall contacts (PW modes) weighted by the centre-to-wall distance, Σ G d
    (W m/K: a particle's difference to the wall temperature grows with its distance from the wall).
    ``weighted`` False: plain sums of the conductances (W/K)."""
    element_T = np.where(np.isfinite(model.element_temperature), temperature, model.element_temperature)
    at_T = dataclasses.replace(model, element_temperature=element_T)
    T = np.full(net.n, float(temperature))
    sums = {}
    for name in sorted(model.modes):
        network.conductances(dataclasses.replace(at_T, modes=frozenset({name})), net, T)
        if model.registry[name].side == "pp":
            sums[name] = float(np.sum(net.pairs.G * (net.pairs.r2 if weighted else 1.0)))
        else:
            column = model.registry.wall_column(name)
            sums[name] = float(np.sum(net.contacts.G[:, column] * (net.contacts.distance if weighted else 1.0)))
    return sums


def shares(sums: dict[str, float]) -> dict[str, float]:
    """Each mode's share of the sum over the modes of its side (0 where that side has none)."""
    out = {}
    for side in ("pp", "pw"):
        names = [m for m in sums if registry.BY_NAME[m].side == side]
        total = sum(sums[m] for m in names)
        out.update({m: sums[m] / total if total > 0 else 0.0 for m in names})
    return out


def decide_modes(candidates, by_temperature: dict[float, dict[str, float]], threshold: float, pending) -> dict[str, Decision]:
    """Decisions for the ``pending`` modes from their shares at each temperature (K -> {mode: share})."""
    out = {}
    for name in pending:
        side = "the pairs' conductivity (sum of G r^2)" if registry.BY_NAME[name].side == "pp" else "the wall coupling (sum of G d)"
        T, share = max(((T, s[name]) for T, s in by_temperature.items()), key=lambda item: item[1])
        on = share >= threshold
        others = ", ".join(m for m in sorted(candidates) if m != name and registry.BY_NAME[m].side == registry.BY_NAME[name].side)
        out[name] = Decision(name, on, f"{100 * share:.3g}% of {side} at T = {T:.0f} K "
                                       f"(with {others or 'no other mode'}; {'at or above' if on else 'below'} "
                                       f"{100 * threshold:g}%)", effects.AUTO, "screening", share, threshold)  # fmt: skip
    return out


def _estimate_rdf(paths, spec: dict) -> rdf.RDFTables:
    """The RDF tables at the scene's emissivities where ``paths`` (a file or a list) cover them, else
    the first table as it is (the distribution factors of its emissivities; module docstring)."""
    tables = [rdf.load(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    try:
        return rdf.for_emissivities(tables, spec["particles"]["emissivity"], spec["wall"]["emissivity"])
    except DPHTError:
        return tables[0]


def screen(spec: dict, positions_h5, walls_h5, dem_summary, htc_tables: dict, rdf_table=None, rdf_grids=None) -> dict:
    """The screening stage's result for one scene: every screened effect's decision
    (:class:`dpht.thermal.effects.Decision` records) and the numbers behind them.

    ``spec`` is the scene's thermal spec (:func:`dpht.config.thermal_spec`); ``htc_tables`` maps
    "pfp"/"pfw" to :class:`dpht.closures.htc.HTCTable` (those of the candidate gas-gap modes);
    ``rdf_table`` the RDF table file the radiation estimate reads (see the module docstring);
    ``rdf_grids`` the solid fractions of the RDF tables the thermal stage will read, by table
    ("pp", "pw"): a measured solid fraction outside them, for a radiation mode decided on, stops
    the screening (:func:`dpht.thermal.decisions.check_measured`), before the thermal stage is planned."""
    # How a run steps in time is not part of the screening's spec (dpht.config.screening_spec).
    thermal = {"frame_stride": 1, "max_substeps": 1, **spec["thermal"]}
    spec = {**spec, "thermal": thermal}
    walls = load_walls(walls_h5)
    decisions = effects.from_config(thermal, set(walls.zone_names))
    pending = effects.pending(decisions)
    candidates = effects.possible_modes(decisions)
    trial = {**thermal, "modes": {m: m in candidates for m in registry.NAMES}, "intraparticle": False}
    dem_run = DemRun.of(positions_h5, dem_summary)
    rdf_tables = _estimate_rdf(rdf_table, spec) if rdf_table is not None and candidates & set(registry.needing("rdf")) else None
    with PositionsFile(positions_h5) as dem:
        schedule = Schedule.of_spec(dem, thermal)
        positions = np.asarray(dem.frame(schedule.frames[0]).positions, dtype=np.float64)
        resolved, solid_fraction = resolve_solid_fractions({**spec, "thermal": trial}, dem_run.summary, dem_run.source,
                                                           schedule.frames)  # fmt: skip
    if rdf_tables is not None:  # the estimate reads the table within its solid fractions
        phi = resolved["thermal"]["solid_fraction"]
        for mode in registry.MODES:
            if mode.name in candidates and mode.table and mode.table[0] == "rdf":
                grid = getattr(rdf_tables, mode.table[1]).solid_fraction
                phi = {**phi, mode.region: float(np.clip(phi[mode.region], grid[0], grid[-1]))}
        resolved = {**resolved, "thermal": {**resolved["thermal"], "solid_fraction": phi}}
    kinds = wall_kinds(dem_run.summary, dem_run.source, walls)
    model = thermal_model.build(resolved, walls, htc_tables, rdf_tables, kinds)
    frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    net = network.assemble(model, frame)  # the frame's pairs and wall contacts, listed once for every temperature
    sums = {T: conductance_sums(model, net, T) for T in sorted(set(model.temperature_range))}
    by_temperature = {T: shares(s) for T, s in sums.items()}
    threshold = float(thermal.get("screening_threshold", 0.01))
    decisions.update(decide_modes(candidates, by_temperature, threshold, [m for m in pending if m in registry.BY_NAME]))
    on = {m: decisions[m].on for m in registry.NAMES}
    if "intraparticle" in pending:
        decided = thermal_model.build({**resolved, "thermal": {**resolved["thermal"], "modes": on, "intraparticle": "auto"}},
                                      walls, htc_tables, rdf_tables, kinds)  # fmt: skip
        _, record = decide_intraparticle(decided, schedule, positions)
        decisions["intraparticle"] = Decision("intraparticle", record["resolved"], record["reason"], effects.AUTO,
                                              "screening", record["biot_max"], record["threshold"])  # fmt: skip
    for decision in decisions.values():
        log.info("screening: %s", decision.line())
    check_measured({**thermal, "modes": on}, {r: s["value"] for r, s in solid_fraction.items()}, dem_run.source, rdf_grids)
    return {
        "format": FORMAT,
        "decisions": {name: d.record() for name, d in decisions.items()},
        "frame": int(schedule.frames[0]),
        "particles": int(frame.particles.size),
        "conductance_W_K": {f"{T:.6g}": s for T, s in sums.items()},
        "shares": {f"{T:.6g}": s for T, s in by_temperature.items()},
        "solid_fraction": solid_fraction,
        "rdf_table": None if rdf_tables is None else str(rdf_table),
    }
