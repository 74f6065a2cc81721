"""The DPHT paper's Section 4 (Table 1, Fig. 9): four radiation models on a static bed with a hot and a
cold slab (:mod:`dpht.radiation.study`).

Two parts: the keyed stage ``radiation_study`` (results/radiation_study/<key>/, cached by content
like the scene stages, as the accuracy study's bed knobs run it too) computes from the
``radiation_study`` section and the thermal model of its bed, the materials and numerics of the
section's scene (config/tube.yaml) with the study's particles; the study ``radiation`` publishes
its table and Fig. 9 in the run's folder.
"""

from __future__ import annotations

from dpht import config, paths
from dpht.closures.rdf import FORMAT as RDF_FORMAT
from dpht.errors import USER_ERRORS
from dpht.studies import KeyedStage, Output, Planned, Published, Study, first_scene, publish, without_scene

STAGE = "radiation_study"
# The keyed stage's files; the study publishes those with a report caption.
FILES = {"table": "table.csv", "markdown": "table.md", "history": "history.csv", "figure": "fig9.png",
         "summary": "summary.json"}  # fmt: skip

# Thermal keys that describe the workflow's scene (wall zones, tables, DEM frames): not the study's bed.
SCENE_THERMAL_KEYS = ("walls", "rdf_table", "rdf_build", "htc_table", "frame_stride")


def study_thermal_spec(spec: dict, study: dict) -> dict:
    """The thermal model of the radiation study's bed from a :func:`dpht.config.thermal_spec` ``spec``:
    its materials and numerics with only particle-particle radiation on (Eq. 25), the study's
    particles (radius m, emissivity, density kg/m^3, specific heat J/(kg K)), solid fraction and
    radiation cutoff (radii), its cold and hot temperatures (K) as the temperature range, and no walls."""
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


def rdf_spec(section: dict, scene: dict) -> dict:
    """The RDF tables the study needs: its particles' emissivity, the scene's wall and build settings."""
    return {"particle_emissivity": section["emissivity"], "wall_emissivity": scene["wall"]["emissivity"],
            **scene["thermal"]["rdf_build"], "format": RDF_FORMAT}


def stage_spec(section: dict, scene: dict) -> dict:
    """What the keyed stage computes from: the section's parameters, and the thermal model of its bed."""
    study = without_scene(section)
    return {"study": study, "thermal": study_thermal_spec(config.thermal_spec(scene), study)}


def register(plan, section: dict, scene: dict) -> dict:
    """Register the study's RDF table and keyed stage run in ``plan``: {"rdf": key, STAGE: key}."""
    rdf = plan.register("rdf", rdf_spec(section, scene))
    return {"rdf": rdf, STAGE: plan.register(STAGE, stage_spec(section, scene), rdf=rdf)}


def problems(section: dict, scene: dict) -> list[str]:
    """The section's parameters, and its solid fraction within its RDF table's."""
    from dpht.radiation import study

    try:
        spec = study.check_spec(without_scene(section))
    except USER_ERRORS as err:
        return [str(err)]
    lo, hi = min(phis := scene["thermal"]["rdf_build"]["solid_fractions"]), max(phis)
    if not lo <= spec["solid_fraction"] <= hi:
        return [f"radiation_study.solid_fraction = {spec['solid_fraction']} is outside the solid fractions of its RDF "
                f"table (thermal.rdf_build.solid_fractions of {section['scene']}), {lo}-{hi}"]
    return []


def plan(plan, section: dict) -> Planned:
    scene = first_scene(section, "radiation_study.scene")
    key = register(plan, section, scene)[STAGE]
    inputs = {name: paths.stage_file(STAGE, key, file) for name, file in FILES.items() if name in STUDY.outputs}
    return Planned(inputs=inputs, spec=Published(key), problems=tuple(problems(section, scene)))


def stage(spec, inputs, outputs, threads):
    """The keyed stage: the bed, traced, its four models' steady states and transients, Fig. 9."""
    import logging

    from dpht.figures.radiation_study import radiation_models_figure
    from dpht.radiation.study import run_study
    from dpht.util.files import staged, write_json

    with staged(outputs) as out:
        summary, times, histories = run_study(spec, inputs["rdf"], out["table"].parent, progress=logging.getLogger("dpht").info,
                                              threads=threads)  # fmt: skip
        radiation_models_figure(times, histories, summary["models"], summary["cross_section_m2"], out["figure"])
        write_json(out["summary"], summary)


STUDY = Study(
    name="radiation",
    section="radiation_study",
    category="Radiation models",
    outputs={"table": Output("table.csv", "radiation_table"), "markdown": Output("table.md"),
             "history": Output("history.csv"),  # the numbers of Fig. 9 beside it
             "figure": Output("fig9.png", "radiation_study"), "summary": Output("summary.json")},  # fmt: skip
    plan=plan,
    run=publish,
    stages=(KeyedStage(STAGE, FILES, stage, threads=2),),
    description="DPHT paper, Section 4, Table 1 and Fig. 9: four radiation models on a static bed",
)
