"""The mixer study (DPHT paper, Section 6, Figs. 14-16): every variant of the scene of the
``mixer_study`` section (config/mixers.yaml) against its first, the plain tube, at one mass flow.
Their geometry, DEM, tables and thermal runs are the scene stages' (registered as variants'); the
figures and the table are :func:`dpht.figures.mixers.study`'s.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from dpht.errors import ConfigError
from dpht.studies import Output, Planned, Study, load_scene, variants_of
from dpht.geometry.layout import layout

FIGURES = ("fig14", "fig15", "fig16")  # captions workflow/report/mixers_<name>.rst
# What the study reads of each variant: input name -> (stage, file).
SCENE_FILES = {"walls": ("geometry", "walls.h5"), "positions": ("dem", "positions.h5"), "thermal": ("thermal", "thermal.h5"),
               "dem": ("dem", "summary.json"), "thermal_summary": ("thermal", "summary.json")}  # fmt: skip


@dataclass(frozen=True)
class Spec:
    """The variants in order (the first is the reference), the paper's relative wall heats, the
    variant whose radial mixer Fig. 14 shows close up, the mixers' heights as distances from the
    inlet (m, shaded in Fig. 16), and what the outputs are measured with (the reference's steady
    window, heated zones, c_p, inlet temperature K)."""

    variants: tuple[str, ...]
    paper: dict
    close_up: str | None
    spans: dict
    window: tuple[float, float]
    heated_zones: tuple[str, ...]
    specific_heat: float | str
    inlet_temperature: float


def plan(plan, section: dict) -> Planned:
    scenes = variants_of(load_scene(section, "mixer_study.scene"))
    names = list(scenes)
    if len(names) < 2:
        raise ConfigError(f"mixer_study.scene: {section['scene']}: the mixer study compares variants with the first, "
                          f"{names[0]!r}; it needs at least two")  # fmt: skip
    paper = section.get("paper", {})  # optional, no default: the table leaves the paper's column out
    unknown = sorted(set(paper) - set(names[1:]))
    if unknown:
        raise ConfigError(f"mixer_study.paper: {unknown} are not variants of {section['scene']} other than the "
                          f"reference {names[0]!r} (its variants: {names})")
    keys = plan.register_scenes(scenes)
    inputs = {f"{name}_{v}": file for v in names for name, file in plan.scene_files(keys[v], SCENE_FILES).items()}
    reference = scenes[names[0]]
    thermal = reference["thermal"]
    radial = [v for v, c in scenes.items() if any(m.get("type") == "radial" for m in c["geometry"].get("mixers") or [])]
    spans = {}  # the mixers' heights as distances from the inlet, the top of the tube (m)
    for v, c in scenes.items():
        parts = layout(c["geometry"], c["particles"]["diameter"])
        spans[v] = [[parts.tube.length - top, parts.tube.length - bottom] for bottom, top in (m.z_range() for m in parts.mixers)]
    spec = Spec(variants=tuple(names), paper=paper, close_up=radial[0] if radial else None, spans=spans,
                window=tuple(reference["figures"]["steady_window"]),
                heated_zones=tuple(sorted(z for z, bc in thermal["walls"].items() if bc != "adiabatic")),
                specific_heat=reference["particles"]["specific_heat"], inlet_temperature=thermal["inlet_temperature"])  # fmt: skip
    return Planned(inputs=inputs, spec=spec, scenes=scenes)


def run(spec, inputs, outputs, threads):
    """Figs. 14-16 and the table of every variant against the plain tube, in the study's folder."""
    import logging

    from dpht.figures import mixers as fig
    from dpht.util.files import no_nan, staged, write_json

    spec = Spec(**spec)
    with staged(outputs) as out:  # with the CSVs and the single panels beside the figures
        result = fig.study(asdict(spec), inputs, out, log=logging.getLogger("dpht").info)
        write_json(out["summary"], no_nan(result))


STUDY = Study(
    name="mixers",
    section="mixer_study",
    category="Mixers",
    outputs={**{name: Output(f"{name}.png", f"mixers_{name}") for name in FIGURES},
             "table": Output("mixers.csv", "mixers_table"), "markdown": Output("mixers.md"),
             "summary": Output("mixers.json")},  # fmt: skip
    plan=plan,
    run=run,
    description="DPHT paper, Section 6, Figs. 14-16: mixers against the plain tube at one mass flow",
)
