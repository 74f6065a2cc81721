"""The screening check: what the effects a scene screened out would have changed. The first variant
of the ``screening_check`` section's scene (config/tube.yaml) and each of its ``scenes`` (overrides
of it, as a variant's) run as configured and with every ``auto`` switch on; the change of wall heat
and outlet temperature is what the screening cost (:mod:`dpht.accuracy.screening_check`).
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

from dpht import config, paths
from dpht.studies import Output, Planned, Study, first_scene, scene_of
from dpht.thermal import effects

DEFAULT = "default"  # the name of the scene's own check


@dataclass(frozen=True)
class Check:
    """One check scene: its name, steady window, radial band (m), specific heat J/(kg K), inlet
    temperature K, temperature range (initial, inlet, the walls' constants; K) and screening threshold."""

    name: str
    window: tuple[float, float]
    radial_band: tuple[float, float]
    specific_heat: float | str
    inlet_temperature: float
    temperatures: tuple[float, float]
    threshold: float

    @classmethod
    def of(cls, name: str, c: dict) -> Check:
        t = c["thermal"]
        walls = [float(bc["temperature"]) for bc in t["walls"].values() if isinstance(bc, dict) and _number(bc["temperature"])]
        temperatures = [t["initial_temperature"], t["inlet_temperature"], *walls]
        return cls(name=name, window=tuple(c["figures"]["steady_window"]), radial_band=tuple(config.radial_band(c)),
                   specific_heat=c["particles"]["specific_heat"], inlet_temperature=t["inlet_temperature"],
                   temperatures=(min(temperatures), max(temperatures)), threshold=t["screening_threshold"])  # fmt: skip


@dataclass(frozen=True)
class Spec:
    scenes: tuple[Check, ...]


def _number(text) -> bool:
    try:
        float(text)
    except (TypeError, ValueError):
        return False
    return True


def plan(plan, section: dict) -> Planned:
    base = first_scene(section, "screening_check.scene")
    scenes, files, checks = {}, {}, []
    for i, (name, overrides) in enumerate({DEFAULT: {}, **section["scenes"]}.items()):
        c = scene_of(base, overrides, f"screening_check.scenes.{name}", plan.sources)
        on = config.merge(copy.deepcopy(c), {"thermal": effects.all_on(c["thermal"])})
        keys = plan.register_scenes({name: c, f"{name} (all on)": on}, study=True)  # labels: the report's
        for run, k in zip(("auto", "all"), keys.values()):
            files.update({f"{i}_{run}_thermal": paths.stage_file("thermal", k["thermal"], "thermal.h5"),
                          f"{i}_{run}_summary": paths.stage_file("thermal", k["thermal"], "summary.json"),
                          f"{i}_{run}_positions": paths.stage_file("dem", k["dem"], "positions.h5")})  # fmt: skip
        scenes[name] = c
        checks.append(Check.of(name, c))
    return Planned(inputs=files, spec=Spec(scenes=tuple(checks)), scenes=scenes)


def run(spec, inputs, outputs, threads):
    import logging

    from dpht.accuracy.screening_check import run as check
    from dpht.util.files import staged

    spec = Spec(scenes=tuple(Check(**scene) for scene in spec["scenes"]))
    with staged(outputs) as out:
        rows = check(asdict(spec), inputs, out)
    for row in rows:
        logging.getLogger("dpht").info(
            "screening check %s: off %s; wall heat %+.3f%%, outlet %+.3f%% when switched back on (%s)", row["scene"],
            ", ".join(row["off"]), 100 * row["change_wall_heat"], 100 * row["change_outlet"],
            "holds" if row["holds"] else "DOES NOT HOLD")  # fmt: skip


STUDY = Study(
    name="screening_check",
    section="screening_check",
    category="Screening",
    outputs={"table": Output("check.csv", "screening_check"), "markdown": Output("check.md"), "summary": Output("summary.json")},
    plan=plan,
    run=run,
    description="what the effects the screening switched off would have changed",
)
