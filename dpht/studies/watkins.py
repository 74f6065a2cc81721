"""The Watkins validation (DPHT paper, Section 5, Figs. 11-13): the travelling-slice scene of the
``watkins`` section (config/watkins.yaml, its first variant) carried down the Watkins tube, and its
numbers beside the paper's and the experiment's. Its geometry, DEM, tables and thermal run are the
scene stages' (registered as a variant's); the figures are :mod:`dpht.figures.watkins`'.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from dpht.errors import ConfigError
from dpht.studies import Output, Planned, Study, first_scene

SCENE = "watkins"  # the label of its scene
FIGURES = ("fig11", "fig12", "fig13")  # captions workflow/report/watkins_<name>.rst
# What the figures read of a scene: input name -> (stage, file).
SCENE_FILES = {"positions": ("dem", "positions.h5"), "walls": ("geometry", "walls.h5"), "thermal": ("thermal", "thermal.h5")}


@dataclass(frozen=True)
class Spec:
    """Nothing beyond its inputs: the slice's path and velocity are in its thermal run."""


def scene(section: dict) -> dict:
    """The merged config of the Watkins scene (the first variant of ``section["scene"]``); it must
    be a travelling slice."""
    c = first_scene(section, "watkins.scene")
    if "slice" not in c["thermal"]:
        raise ConfigError(f"watkins.scene: {section['scene']}: the Watkins scene needs thermal.slice (a travelling slice)")
    return c


def plan(plan, section: dict) -> Planned:
    scenes = {SCENE: scene(section)}
    keys = plan.register_scenes(scenes)[SCENE]
    return Planned(inputs=plan.scene_files(keys, SCENE_FILES), spec=Spec(), scenes=scenes)


def run(spec, inputs, outputs, threads):
    """Figs. 11-13 from the travelling-slice scene, and its numbers beside the paper's and the
    experiment's (watkins.json, watkins.csv)."""
    import logging

    from dpht.figures import watkins as fig

    log = logging.getLogger("dpht")
    Spec(**spec)
    results = fig.fig11(inputs["positions"], inputs["thermal"], inputs["walls"], outputs["fig11"])
    results.update(fig.fig13(inputs["positions"], inputs["thermal"], inputs["walls"], outputs["fig13"]))
    results.update(fig.fig12(inputs["positions"], inputs["thermal"], inputs["walls"], outputs["fig12"]))
    fig.watkins_summary(results, Path(outputs["summary"]).with_suffix(".csv"))
    Path(outputs["summary"]).write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    log.info("watkins: mean temperature rise to %.3g m %.1f K (measured 570 at 0.645 m, paper 547); wall heat split "
             "overall %s", results["rise_distance_m"], results["rise_K"],
             ", ".join(f"{m} {v:.1f}%" for m, v in results["split_overall_percent"].items()))  # fmt: skip


STUDY = Study(
    name="watkins",
    section="watkins",
    category="Watkins",
    outputs={**{name: Output(f"{name}.png", f"watkins_{name}") for name in FIGURES}, "summary": Output("watkins.json")},
    plan=plan,
    run=run,
    description="DPHT paper, Section 5, Figs. 11-13: the travelling slice down the Watkins tube",
)
