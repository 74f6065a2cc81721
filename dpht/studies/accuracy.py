"""The accuracy study: every numerical knob of :mod:`dpht.accuracy.knobs` varied around its default,
against a converged reference, on the scene of the ``accuracy`` section (config/tube.yaml), the
Section 4 bed of the ``radiation_study`` section and the Watkins slice of the ``watkins`` section
(each when the config has it); each setting is a scene (or bed) of its own, cached like a variant's
stage runs. Error against cost: :mod:`dpht.accuracy.study`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from dpht import config, paths
from dpht.accuracy import knobs
from dpht.studies import Output, Planned, Study, first_scene, radiation, scene_of, watkins


@dataclass(frozen=True)
class Spec:
    """The study's runs ({knob, setting, label, value, scene, reference, default, record, keys}) and
    what the outputs are measured with (the scene's steady window, radial band (m), c_p J/(kg K),
    inlet temperature K), and the relative error a recommended default stays within."""

    runs: tuple[dict, ...]
    window: tuple[float, float]
    radial_band: tuple[float, float]
    specific_heat: float | str
    inlet_temperature: float
    tolerance: float


def _section(cfg: dict, name: str) -> dict | None:
    return cfg[name] if isinstance(cfg.get(name), dict) else None


def plan(plan, section: dict) -> Planned:
    """Each setting (:func:`dpht.accuracy.knobs.settings`, around the scene's first variant, or the
    Watkins scene for the slice's) registered as a scene of its own: bed knobs run the Section 4
    stage, when the config has that section; slice knobs need the Watkins scene."""
    bed = _section(plan.config, "radiation_study")
    base = {**first_scene(section, "accuracy.scene"), "accuracy": section, **({"radiation_study": bed} if bed else {})}
    slice_scene = watkins.scene(plan.config["watkins"]) if _section(plan.config, "watkins") else None
    bed_scene = first_scene(bed, "radiation_study.scene") if bed else None
    scene_of(base, section["short_scene"], "accuracy.short_scene", plan.sources)  # its own problems, at their lines
    runs = []
    for run in knobs.settings(base, slice_scene):
        scene = slice_scene if run["scene"] == "slice" else base
        c = scene_of(scene, run.pop("overrides"), f"accuracy study ({run['knob']} = {run['label']})")
        if run["scene"] == "bed":
            if bed is None:
                continue
            run["keys"] = radiation.register(plan, c["radiation_study"], bed_scene)
        else:
            label = f"{run['knob']} = {run['label']}"  # the scene's name in the report
            run["keys"] = plan.register_scenes({label: c}, study=True)[label]
        runs.append(run)
    spec = Spec(runs=tuple(runs), window=tuple(base["figures"]["steady_window"]), radial_band=tuple(config.radial_band(base)),
                specific_heat=base["particles"]["specific_heat"], inlet_temperature=base["thermal"]["inlet_temperature"],
                tolerance=section["tolerance"])  # fmt: skip
    return Planned(inputs=inputs(runs), spec=spec)


def inputs(runs: list[dict]) -> dict:
    """The summaries (and for scenes, thermal and DEM files; for the slice, the wall table) of
    every run, named ``<index>_<file>``."""
    files = {}
    for i, run in enumerate(runs):
        keys = run["keys"]
        if radiation.STAGE in keys:
            files[f"{i}_study"] = paths.stage_file(radiation.STAGE, keys[radiation.STAGE], "summary.json")
            continue
        files.update({f"{i}_thermal": paths.stage_file("thermal", keys["thermal"], "thermal.h5"),
                      f"{i}_thermal_summary": paths.stage_file("thermal", keys["thermal"], "summary.json"),
                      f"{i}_positions": paths.stage_file("dem", keys["dem"], "positions.h5"),
                      f"{i}_dem_summary": paths.stage_file("dem", keys["dem"], "summary.json")})  # fmt: skip
        if run["scene"] == "slice":
            files[f"{i}_walls"] = paths.stage_file("geometry", keys["geometry"], "walls.h5")
    return files


def run(spec, inputs, outputs, threads):
    import logging

    from dpht.accuracy import study

    summary = study.run(asdict(Spec(**spec)), inputs, outputs, progress=logging.getLogger("dpht").info)
    logging.getLogger("dpht").info("accuracy study: %d settings; stage runs took %.0f s", len(summary["rows"]),
                                   summary["study_cost_s"])  # fmt: skip


STUDY = Study(
    name="accuracy",
    section="accuracy",
    category="Accuracy and cost",
    outputs={"table": Output("accuracy.csv", "accuracy_table"), "recommended": Output("recommended.csv", "accuracy_recommended"),
             "markdown": Output("recommended.md"), "convergence": Output("convergence.csv", "accuracy_convergence"),
             "knobs": Output("knobs.png", "accuracy_knobs"), "pareto": Output("pareto.png", "accuracy_pareto"),
             "convergence_figure": Output("convergence.png", "accuracy_convergence"),
             "summary": Output("summary.json")},  # fmt: skip
    plan=plan,
    run=run,
    description="what accuracy costs: every numerical knob against a converged reference",
)
