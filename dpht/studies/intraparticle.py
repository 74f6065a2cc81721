"""When do particles need resolving? Wall heat of a wall-heated bed, uniform against resolved particles.

Scene: a random packing (:mod:`dpht.radiation.packing`) between hard walls normal to z, periodic in
x and y; the lower wall is a Dirichlet plane at ``wall_temperature``, moved 1% of a radius into the
bed so the particles resting on it touch it (the packing's spheres are packed 0.5% smaller than
the thermal particles, so neighbours touch too, as in a DEM bed). The bed starts at
``initial_temperature`` and is heated for ``duration`` s in frames of at most ``step`` s by the
stage's explicit integrator with the conduction modes (contact and gas gap; radiation is left out so the
study needs no RDF table). For each particle conductivity k_p of the sweep the same bed runs twice,
with uniform (lumped) and resolved particles, and the study records the wall energy of both, their
relative difference |Q_lumped - Q_resolved| / Q_resolved, and the particles' Biot numbers as
``thermal.intraparticle: auto`` computes them (:func:`dpht.thermal.integrate.biot_numbers`). The
Biot numbers at which the difference passes 1% and 5% are interpolated (log-log) between the sweep's
points.

Two series (:data:`SERIES`): the bed in a stagnant gas (the DPHT paper's modes only), and in a gas
stream (``gas``: particle-gas convection ``thermal.convection`` at every particle, the gas at the
wall's temperature, ParScale's fluid-particle setting). In the stagnant gas the wall heat barely
depends on the resolution: it enters the particles touching the wall through their gas gaps, whose
conductance is a few percent of the particle's internal one (about k_gas / (20 k_p) times a
logarithm, whatever the size), and the 1-D radial model passes heat that enters a surface and
leaves it to a neighbour without crossing the interior. In the gas stream every surface takes heat
that must cross the interior, the surface runs ahead of the mean, and resolution matters. Two more
scenes run with ``auto`` in both series: large, poorly conducting particles (resolved) and small,
well conducting ones (uniform), each with both models to show what the decision changes.
"""

from __future__ import annotations

import copy
import csv
import math
from pathlib import Path

import numpy as np

from dpht import config, paths
from dpht.closures import htc
from dpht.config import htc_spec
from dpht.radiation import packing
from dpht.studies import KeyedStage, Output, Planned, Published, Study, first_scene, publish, without_scene
from dpht.thermal import integrate, intraparticle, model as thermal_model
from dpht.geometry.walls import Walls

CONDUCTION = ("pp_contact", "pw_contact", "pfp", "pfw")
LEVELS = (0.01, 0.05)  # relative wall-heat differences whose Biot numbers the study reports
PACKED_SMALLER = 0.995  # packing radius / particle radius: neighbours overlap by about 1% of a diameter
WALL_INSET = 0.01  # radii the heated plane lies inside the packing's wall
SERIES = ("stagnant", "gas")  # without and with the study's particle-gas convection (``gas``)


def scene_spec(base: dict, study: dict, diameter: float, conductivity: float, series: str = "stagnant") -> dict:
    """The thermal spec of one run: the config's material and cutoffs, the study's particles and
    temperatures, conduction modes only, one Dirichlet zone ``hot``, and in the ``gas`` series the
    study's particle-gas convection."""
    s = copy.deepcopy(base)
    s["particles"].update(diameter=diameter, conductivity=conductivity, density=study["density"],
                          specific_heat=study["specific_heat"])  # fmt: skip
    t = s["thermal"]
    t.update(modes={m: m in CONDUCTION for m in t["modes"]}, initial_temperature=study["initial_temperature"],
             inlet_temperature=study["initial_temperature"], walls={"hot": {"temperature": study["wall_temperature"]}},
             solid_fraction=study["solid_fraction"], shells=study["shells"], max_substeps=10**6)  # fmt: skip
    for key in ("rdf_table", "rdf_build", "convection"):
        t.pop(key, None)
    if series == "gas":
        t["convection"] = dict(study["gas"])
    return s


def bed(study: dict, diameter: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, Walls]:
    """Positions (m), the box (lo, hi) and the heated plane of the study's packing for ``diameter``."""
    R = diameter / 2
    width, height = study["width"] * diameter, study["height"] * diameter
    n = int(round(study["solid_fraction"] * width * width * height / (packing.SPHERE_VOLUME * R**3)))
    pack = packing.pack(n, study["solid_fraction"], radius=PACKED_SMALLER * R, aspect=(width / height, width / height, 1.0),
                        wall_axis=2, seed=study["seed"])  # fmt: skip
    lo, hi = pack.box
    z = lo[2] + WALL_INSET * R + (1 - PACKED_SMALLER) * R  # touching spheres overlap the plane by ~1% of R
    return pack.positions, lo, hi, _plane(lo, hi, z)


def _plane(lo, hi, z: float, n: int = 8) -> Walls:
    """The plane at height ``z`` over the box's x-y extent, 2 n^2 triangles (normal +z), zone ``hot``."""
    x, y = np.linspace(lo[0], hi[0], n + 1), np.linspace(lo[1], hi[1], n + 1)
    corners = [[(x[a], y[b]), (x[a + 1], y[b]), (x[a + 1], y[b + 1]), (x[a], y[b + 1])] for a in range(n) for b in range(n)]
    tris = [[(*p[i], z) for i in tri] for p in corners for tri in ((0, 1, 2), (0, 2, 3))]
    return Walls.from_vertices(np.array(tris, dtype=float), np.zeros(len(tris), dtype=np.int32), ["hot"])


def run(spec: dict, positions, lo, hi, walls: Walls, duration: float, step: float) -> dict:
    """Heat the bed: wall energy (J), sub-steps, and the Biot numbers of the decision, for ``spec``
    (its ``thermal.intraparticle`` switch: False, True or "auto").

    The frames are at most ``step`` long and short enough that resolved particles need no explicit
    sub-steps at the hottest temperature (the surface node's effective capacity bounds their step),
    and the same for both models, so their difference is the model's, not the time step's.
    """
    tables = {kind: htc.table_from_spec(htc_spec(spec, kind)) for kind in ("pfp", "pfw")}
    model = thermal_model.build(spec, walls, tables)
    frame = integrate.prepare_frame(model, positions, lo, hi, (True, True, False))
    t = spec["thermal"]
    T_max = max(t["initial_temperature"], t["walls"]["hot"]["temperature"], t.get("convection", {}).get("gas_temperature", 0.0))
    bi, k_p = integrate.biot_numbers(model, frame, T_max)
    if model.intraparticle == "auto" and float(bi.max()) > model.biot_threshold:
        model = thermal_model.resolved(model)
    g_max = float(bi.max()) * math.pi * 2 * model.radius * k_p  # W/K
    outer = intraparticle.grid(model.radius, model.shell_count).outer
    limit = 0.9 * model.mass * outer * model.enthalpy.cp_min / g_max
    frames = max(1, math.ceil(duration / min(step, limit)))
    h = np.full(len(positions), model.enthalpy.enthalpy(model.initial_temperature)[()])
    shells = np.repeat(h[:, None], model.shells.n, axis=1) if model.shells is not None else None
    rates = integrate.Rates.for_frame(model, frame)
    energy, substeps = 0.0, 0
    for _ in range(frames):
        report = integrate.advance(model, frame, h, duration / frames, rates, shells=shells)
        energy += duration / frames * math.fsum(report.element_heat.ravel())
        substeps += report.substeps
    return {"wall_energy_J": energy, "substeps": substeps, "resolved": model.shells is not None,
            "biot_max": float(bi.max()), "biot_median": float(np.median(bi)), "particles": len(positions)}  # fmt: skip


def compare(base: dict, study: dict, diameter: float, conductivity: float, beds: dict, series: str = "stagnant") -> dict:
    """Lumped and resolved runs of one particle in one series (``beds`` caches the packing per diameter)."""
    if diameter not in beds:
        beds[diameter] = bed(study, diameter)
    positions, lo, hi, walls = beds[diameter]
    spec = scene_spec(base, study, diameter, conductivity, series)
    runs = {}
    for name, switch in (("lumped", False), ("resolved", True)):
        spec["thermal"]["intraparticle"] = switch
        runs[name] = run(spec, positions, lo, hi, walls, study["duration"], study["step"])
    lumped, resolved = runs["lumped"]["wall_energy_J"], runs["resolved"]["wall_energy_J"]
    return {"series": series, "diameter_m": diameter, "conductivity_W_mK": conductivity,
            "biot_max": runs["lumped"]["biot_max"], "biot_median": runs["lumped"]["biot_median"],
            "wall_energy_lumped_J": lumped, "wall_energy_resolved_J": resolved,
            "relative_difference": abs(lumped - resolved) / abs(resolved), "substeps_lumped": runs["lumped"]["substeps"],
            "substeps_resolved": runs["resolved"]["substeps"], "particles": runs["lumped"]["particles"]}  # fmt: skip


def crossing(biot, difference, level: float) -> float | None:
    """The Biot number where ``difference`` first passes ``level`` (log-log interpolation), or None."""
    for k in range(1, len(biot)):
        if difference[k - 1] < level <= difference[k]:
            f = math.log(level / difference[k - 1]) / math.log(difference[k] / difference[k - 1])
            return float(math.exp(math.log(biot[k - 1]) + f * math.log(biot[k] / biot[k - 1])))
    return None


def run_study(base: dict, study: dict, out_dir, progress=print) -> dict:
    """The sweep of both series and the two auto scenes; writes ``biot_sweep.csv``,
    ``auto_scenes.csv`` and ``biot_sweep.png`` into ``out_dir`` and returns the summary."""
    from dpht.figures import intraparticle as figures

    out_dir = Path(out_dir)
    beds: dict = {}
    rows, curves, thresholds = [], {}, {}
    for series in SERIES:
        picked = []
        for k in sorted(study["conductivities"], reverse=True):  # rising Bi
            picked.append(compare(base, study, study["diameter"], k, beds, series))
            progress(f"intraparticle study: {series}: k_p {k:g} W/(m K): Bi up to {picked[-1]['biot_max']:.3g}, wall heat "
                     f"differs by {picked[-1]['relative_difference']:.3%}")  # fmt: skip
        biot = [r["biot_max"] for r in picked]
        difference = [r["relative_difference"] for r in picked]
        curves[series] = (biot, difference)
        thresholds[series] = {level: crossing(biot, difference, level) for level in LEVELS}
        rows += picked
    _write(out_dir / "biot_sweep.csv", rows)
    figures.biot_sweep(out_dir / "biot_sweep.png", curves, thresholds, study["gas"])
    scenes = []
    for name in ("auto_on", "auto_off"):
        scene = study[name]
        for series in SERIES:
            row = compare(base, study, scene["diameter"], scene["conductivity"], beds, series)
            spec = scene_spec(base, study, scene["diameter"], scene["conductivity"], series)
            spec["thermal"].update(intraparticle="auto", biot_threshold=study["biot_threshold"])
            positions, lo, hi, walls = beds[scene["diameter"]]
            auto = run(spec, positions, lo, hi, walls, study["duration"], study["step"])
            scenes.append({"scene": name, **row, "auto_resolved": auto["resolved"], "biot_threshold": study["biot_threshold"]})
            progress(f"intraparticle study: {name}, {series}: auto {'resolves' if auto['resolved'] else 'keeps uniform'} "
                     f"(Bi up to {row['biot_max']:.3g}, threshold {study['biot_threshold']:g}); wall heat differs by "
                     f"{row['relative_difference']:.3%}")  # fmt: skip
    _write(out_dir / "auto_scenes.csv", scenes)
    return {"sweep": rows, "biot_at": {series: {f"{level:g}": value for level, value in t.items()} for series, t in thresholds.items()},
            "auto_scenes": scenes, "gas": study["gas"], "parscale_biot_crit": {"bed": 0.1, "dense_bed": 0.01}}  # fmt: skip


def _write(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


# --- the study in the workflow (dpht.studies) ------------------------------------------------------
# The keyed stage `intraparticle_study` (results/intraparticle_study/<key>/, cached by content)
# computes from the `intraparticle_study` section and the material, gas and cutoffs of its scene
# (config/tube.yaml; its scenes set particles, modes and temperatures), with the cooled-sphere
# verification of the resolved model; the study `intraparticle` publishes its tables and figures.

STAGE = "intraparticle_study"
FILES = {"sweep": "biot_sweep.csv", "figure": "biot_sweep.png", "scenes": "auto_scenes.csv", "cooled": "cooled_sphere.png",
         "convergence": "cooled_sphere_convergence.png", "profiles": "cooled_sphere.csv",
         "convergence_table": "cooled_sphere_convergence.csv", "summary": "summary.json"}  # fmt: skip


def stage_spec(section: dict, scene: dict) -> dict:
    """What the keyed stage computes from: the section's parameters, and the scene's thermal model."""
    return {"study": without_scene(section), "base": config.thermal_spec(scene)}


def _plan(plan, section: dict) -> Planned:
    scene = first_scene(section, "intraparticle_study.scene")
    key = plan.register(STAGE, stage_spec(section, scene))
    inputs = {name: paths.stage_file(STAGE, key, FILES[name]) for name in STUDY.outputs}
    return Planned(inputs=inputs, spec=Published(key))


def _stage(spec, inputs, outputs, threads):
    """The keyed stage: the cooled sphere of ParScale's Table 1 against Crank's series, then the sweep."""
    import json
    import logging

    import numba

    from dpht.studies import cooled_sphere

    log = logging.getLogger("dpht")
    if threads:
        numba.set_num_threads(threads)
    folder = Path(outputs["sweep"]).parent
    errors = cooled_sphere.write(folder)  # the verification of the resolved model, for the report
    log.info("cooled sphere (ParScale Table 1): mean relative error %.3g, max %.3g", errors.mean(), errors.max())
    summary = run_study(spec["base"], spec["study"], folder, progress=log.info)
    summary["cooled_sphere"] = {"mean_relative_error": float(errors.mean()), "max_relative_error": float(errors.max()),
                                "shells": cooled_sphere.SHELLS, "step_s": cooled_sphere.STEP}  # fmt: skip
    Path(outputs["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


STUDY = Study(
    name="intraparticle",
    section="intraparticle_study",
    category="Intra-particle conduction",
    outputs={"sweep": Output("biot_sweep.csv", "intraparticle_study"), "figure": Output("biot_sweep.png", "intraparticle_study"),
             "scenes": Output("auto_scenes.csv", "intraparticle_auto"), "cooled": Output("cooled_sphere.png", "cooled_sphere"),
             "convergence": Output("cooled_sphere_convergence.png", "cooled_sphere_convergence"),
             "profiles": Output("cooled_sphere.csv"), "convergence_table": Output("cooled_sphere_convergence.csv"),
             "summary": Output("summary.json")},  # fmt: skip
    plan=_plan,
    run=publish,
    threads=1,
    stages=(KeyedStage(STAGE, FILES, _stage, threads=2),),
    description="lumped against resolved particles over the Biot number, and the cooled sphere",
)
