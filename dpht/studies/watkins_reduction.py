"""The check of the Watkins reduction: the travelling slice (:mod:`dpht.thermal.slice`) against the
full tube it stands for, with the same physics, on a case small enough to run both ways. The
scene of the ``watkins_reduction`` section (config/tube.yaml with config/watkins_reduction.yaml):
its first variant is the full tube, every other a slice compared with it (mean temperature rise,
wall heat by mode; :func:`dpht.figures.watkins.reduction_check`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from dpht.errors import ConfigError
from dpht.studies import Output, Planned, Study, load_scene, variants_of
from dpht.studies.watkins import SCENE_FILES


@dataclass(frozen=True)
class Spec:
    slices: tuple[str, ...]  # the slice variants, compared with the full tube in this order
    window: tuple[float, float]  # the full tube's steady window (fractions of its run)


FULL = "full"  # the input prefix of the full tube's files


def plan(plan, section: dict) -> Planned:
    scenes = variants_of(load_scene(section, "watkins_reduction.scene"))
    full, *slices = scenes
    if not slices or FULL in slices:
        raise ConfigError(f"watkins_reduction.scene: {section['scene']}: expected the full tube as the first variant and "
                          f"at least one slice after it (not named {FULL!r}); variants: {list(scenes)}")  # fmt: skip
    unsliced = [name for name in slices if "slice" not in scenes[name]["thermal"]]
    if unsliced:
        raise ConfigError(f"watkins_reduction.scene: {section['scene']}: the slices {unsliced} have no thermal.slice")
    keys = plan.register_scenes(scenes)
    inputs = {f"{FULL}_{k}": v for k, v in plan.scene_files(keys[full], SCENE_FILES).items()}
    for name in slices:
        inputs.update({f"{name}_{k}": v for k, v in plan.scene_files(keys[name], SCENE_FILES).items()})
    spec = Spec(slices=tuple(slices), window=tuple(scenes[full]["figures"]["steady_window"]))
    return Planned(inputs=inputs, spec=spec, scenes=scenes)


def run(spec, inputs, outputs, threads):
    """Each slice against the full tube: the first slice's figure is reduction.png, the others'
    reduction.<slice>.png beside it; the numbers in reduction.json."""
    import logging

    from dpht.figures import watkins as fig

    log = logging.getLogger("dpht")
    spec = Spec(**spec)
    full = (inputs[f"{FULL}_positions"], inputs[f"{FULL}_thermal"], inputs[f"{FULL}_walls"])
    out = Path(outputs["figure"])
    results = {}
    for k, name in enumerate(spec.slices):
        png = out if k == 0 else out.with_name(f"{out.stem}.{name}.png")
        results[name] = fig.reduction_check(full, tuple(inputs[f"{name}_{k}"] for k in ("positions", "thermal", "walls")), png,
                                            window=tuple(spec.window))  # fmt: skip
        log.info("reduction %s: rise at the outlet %+.2f%%, wall heat %s", name, 100 * results[name]["rise_outlet_rel_diff"],
                 ", ".join(f"{key[5:-9]} {100 * v:+.2f}%" for key, v in results[name].items() if key.endswith("_rel_diff")
                           and key.startswith("heat_")))
    Path(outputs["summary"]).write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")


STUDY = Study(
    name="watkins_reduction",
    section="watkins_reduction",
    category="Watkins",
    outputs={"figure": Output("reduction.png", "watkins_reduction"), "summary": Output("reduction.json")},
    plan=plan,
    run=run,
    description="the travelling slice against the full tube it stands for",
)
