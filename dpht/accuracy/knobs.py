"""The registry of numerical knobs of the accuracy study (issue 15): every list of knobs derives from
:data:`KNOBS`.

A knob is a numerical setting that buys accuracy with wall time: its config key(s), the settings
the study tries around the default, the default, a converged reference setting, the scene it is
studied on and the stages a change re-runs. The study varies one knob at a time; every other knob
stays at the scene's base (:data:`SCENES`). The settings fit two shared cores (README, What accuracy
costs); a bigger machine can add finer ones here.

- ``tube``: the config's own scene with every tube knob at its reference, and the DEM dumped
  :data:`FINEST` times as often as the config asks, so that the thermal step is a stride over one
  DEM run (``thermal.frame_stride``). All tube knobs share that one reference run.
- ``short``: the config's scene shortened by ``accuracy.short_scene`` (a variant-like override),
  for the knobs that need their own DEM run each. Joint convergence of every DEM knob is beyond
  two cores (the stiffest affordable modulus is 10,000 times softer than the real one), so each DEM
  knob is compared with its own most refined setting, the others at the default (a reference equal
  to the default asks only whether a cheaper setting would do).
- ``bed``: the Section 4 radiation bed (``radiation_study``), a stage of its own.
- ``slice``: the Watkins travelling slice (the ``watkins.scene`` config, DPHT paper Section 5), its
  outputs those of the Watkins figures (:func:`dpht.accuracy.outputs.slice_headline`). Its base
  is the scene with every slice knob at its default (a reference at 0.66 m of travel costs minutes
  per run, so each knob is compared with its own most refined setting, as the short scene's are),
  the DEM dumped :data:`SLICE_FINEST` times as often (the thermal step is a stride) and, with
  ``slice_record``, run for its longest record while the thermal stage reuses the config's
  (``thermal.slice.record``): the knobs share that one DEM run, and their defaults one thermal run.

``record_length`` changes no config key: a shorter DEM record is the start of the longer one (the
DEM and the thermal stage are causal), so its settings are evaluated on the first fractions of the
tube's reference run. ``slice_record`` is its slice counterpart, but a slice reuses (mirrors) its
record over the whole travel, so each record is a thermal run of its own over the start of the
longest. ``integrator`` compares the integrators of ``thermal.integrator`` against explicit
sub-stepping (the paper's Eq. 1 at its stability limit); knobs without settings are not run.

Pure Python: :mod:`dpht.plan` imports it.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass

from dpht import config
from dpht.errors import ConfigError

# DEM dumps per default thermal step in the tube scene: frame_stride FINEST is the default step.
FINEST = 4
# The same in the slice scene: its runs are 4,800 frames at 0.01 s, so the reference step is half the default.
SLICE_FINEST = 2


@dataclass(frozen=True)
class Knob:
    name: str
    scene: str  # one of SCENES (module docstring)
    keys: tuple[str, ...]  # dotted config keys a setting sets together
    settings: tuple[tuple, ...]  # values of ``keys``, one tuple per setting, cheapest first
    default: tuple  # the config's default (in the scene's terms)
    reference: tuple  # the converged (or most refined affordable) setting
    reruns: tuple[str, ...]  # stages a change re-runs
    label: str  # what the setting is, for tables and figures
    note: str = ""
    # For settings in the scene's own terms (the slice's length in particle diameters): the scene
    # config's setting, and the {dotted key: value} overrides of a setting in a scene config.
    read: Callable[[dict], tuple] | None = None
    write: Callable[[tuple, dict], dict] | None = None

    def overrides(self, setting: tuple, scene: dict) -> dict:
        """The nested config overrides of one setting in the scene config ``scene``."""
        return nested(self.write(setting, scene) if self.write else dict(zip(self.keys, setting)))

    def value_in(self, scene: dict) -> tuple:
        """The setting the scene config ``scene`` has."""
        return self.read(scene) if self.read else tuple(_get(scene, key) for key in self.keys)

    def name_of(self, setting: tuple) -> str:
        """A short label of ``setting``: its first value, or its text and number values for a wall."""
        if isinstance(setting[0], (int, float)):
            return f"{setting[0]:g}"
        return "/".join(f"{v:g}" if isinstance(v, (int, float)) else str(v) for v in setting)


# Young's modulus E (Pa, particles and wall) with the DEM step scaled as E^-1/2, so that the step
# stays the same fraction of the Rayleigh time, and the dumps at the same simulated interval.
def _stiffness(E: float, base_step: float = 1.0e-5, base_dump: int = 1000, base_restart: int = 20000) -> tuple:
    k = round((E / 5.0e6) ** 0.5)
    return (E, E, base_step / k, base_dump * k, base_restart * k)


def _slice_diameters(scene: dict) -> tuple:
    """The slice's length in particle diameters."""
    return (round(scene["geometry"]["tube"]["length"] / scene["particles"]["diameter"], 6),)


def _slice_length(setting: tuple, scene: dict) -> dict:
    """A slice ``setting[0]`` particle diameters long: the heated range scaled with it, the fill
    height (which a driven slice packs over its whole length anyway) kept as far below the top, and
    a DEM run of its own only as long as the record it reuses."""
    tube, d = scene["geometry"]["tube"], scene["particles"]["diameter"]
    length = _digits(setting[0] * d)
    if math.isclose(length, tube["length"], rel_tol=1e-9):
        return {}  # the scene's own: the same stage keys
    return {"geometry.tube.length": length,
            "geometry.tube.heated": [_digits(h * length / tube["length"]) for h in tube["heated"]],
            "dem.fill_height": _digits(scene["dem"]["fill_height"] + length - tube["length"]),
            "dem.flow_time": _slice_record(scene)[0]}  # fmt: skip


def _digits(x: float) -> float:
    """``x`` to 12 digits: 24 x 0.32 mm is 7.68 mm, not 7.680000000000001 (which the heated range's
    check against the length, and the stage keys, would see)."""
    return float(f"{x:.12g}")


def _slice_record(scene: dict) -> tuple:
    """s of DEM record the slice reuses: thermal.slice.record, or all of the DEM's flow."""
    return (scene["thermal"]["slice"].get("record", scene["dem"]["flow_time"]),)


def _step(fraction: float) -> tuple:
    """DEM step (s) ``fraction`` of the default 1e-5 s, dumps at the same simulated interval."""
    return (1.0e-5 * fraction, round(1000 / fraction), round(20000 / fraction))


KNOBS: tuple[Knob, ...] = (
    Knob("thermal_step", "tube", ("thermal.frame_stride",), ((16,), (8,), (4,), (2,), (1,)), (FINEST,), (1,),
         ("thermal",), "DEM frames per thermal step (1 frame = 1/4 of the default step)"),
    # Cheapest first on the tube, which is not stiff (config/accuracy_quick.yaml: auto 0.84 s = explicit's,
    # multirate 1.57 s, implicit 2.94 s per run); on a stiff scene implicit is the cheapest, and auto picks it.
    Knob("integrator", "tube", ("thermal.integrator",), (("auto",), ("multirate",), ("implicit",), ("explicit",)),
         ("auto",), ("explicit",), ("thermal",), "thermal integrator (the reference: explicit sub-stepping)"),
    Knob("radiation_cutoff", "tube", ("thermal.radiation_cutoff",), ((3.0,), (5.0,), (7.0,), (10.0,)), (7.0,), (10.0,),
         ("thermal",), "radiation cutoff (particle radii)"),
    Knob("pfp_cutoff", "tube", ("thermal.pfp_cutoff",), ((2.5,), (3.0,), (3.5,), (4.0,)), (3.0,), (4.0,),
         ("pfp", "thermal"), "PFP cutoff (radii, centre-centre)"),
    Knob("pfw_cutoff", "tube", ("thermal.pfw_cutoff",), ((1.25,), (1.5,), (2.0,), (2.5,)), (1.5,), (2.5,),
         ("pfw", "thermal"), "PFW cutoff (radii, centre-wall)"),
    Knob("htc_distances", "tube", ("thermal.htc_table.distances",), ((50,), (100,), (200,), (400,), (800,)), (400,),
         (800,), ("pfp", "pfw", "thermal"), "HTC table distances"),
    Knob("htc_temperatures", "tube", ("thermal.htc_table.temperatures",), ((8,), (16,), (32,), (64,), (128,)), (64,),
         (128,), ("pfp", "pfw", "thermal"), "HTC table temperatures"),
    Knob("record_length", "tube", (), ((0.25,), (0.5,), (0.75,), (1.0,)), (1.0,), (1.0,), ("dem", "thermal"),
         "fraction of the DEM record used", note="the first fractions of the reference run (module docstring)"),
    Knob("youngs_modulus", "short",
         ("particles.youngs_modulus_dem", "wall.youngs_modulus_dem", "dem.timestep", "dem.dump_interval",
          "dem.restart_interval"),
         (_stiffness(5.0e6), _stiffness(2.0e7)), _stiffness(5.0e6), _stiffness(2.0e7),
         ("dem", "thermal"), "DEM Young's modulus (Pa), step scaled as E^-1/2",
         note="the stiffest run here; 5e8 Pa needs a 10x smaller step (10x the DEM time): not affordable on 2 cores"),
    Knob("dem_timestep", "short", ("dem.timestep", "dem.dump_interval", "dem.restart_interval"),
         (_step(1.0), _step(0.5)), _step(1.0), _step(0.5), ("dem", "thermal"), "DEM time step (s)"),
    Knob("wall_facets", "short", ("dem.tube_wall", "geometry.mesh_size"),
         (("primitive", 0.5), ("mesh", 0.5)), ("primitive", 0.5), ("primitive", 0.5),
         ("geometry", "dem", "thermal"), "tube wall in LIGGGHTS (gmsh facets of 0.5 diameters or the exact cylinder)",
         note="reference = default: whether the gmsh tube in LIGGGHTS changes the answer"),
    Knob("bed_radiation_cutoff", "bed", ("radiation_study.radiation_cutoff",), ((3.0,), (5.0,), (7.0,), (7.9,)),
         (7.0,), (7.9,), ("radiation_study",), "radiation cutoff of the distance-based model (radii)",
         note="7.9 radii: the widest the 4,000-particle bed allows (its periodic width must be 3 cutoffs)"),
    Knob("bed_rays", "bed", ("radiation_study.rays",), ((4000,), (8000,), (16000,)), (16000,), (16000,),
         ("radiation_study",), "Monte Carlo rays per particle (the RDF entries' statistics)",
         note="reference = default; its own standard error is in the Section 4 summary"),
    Knob("slice_thermal_step", "slice", ("thermal.frame_stride",), ((4,), (2,), (1,)), (SLICE_FINEST,), (1,),
         ("thermal",), "DEM frames per thermal step (2: the Watkins scene's own step)",
         note="4 is the paper's 0.02 s check", read=lambda c: (SLICE_FINEST * c["thermal"]["frame_stride"],)),
    Knob("slice_record", "slice", ("thermal.slice.record",), ((0.02,), (0.1,), (0.3,)), (0.02,), (0.3,),
         ("dem", "thermal"), "DEM record reused over the travel (s of driven flow, mirrored)",
         note="the start of the longest record (thermal.slice.record)", read=_slice_record),
    Knob("slice_length", "slice", ("geometry.tube.length", "geometry.tube.heated", "dem.fill_height"),
         ((9,), (16,), (24,)), (16,), (24,), ("geometry", "dem", "thermal"), "slice length (particle diameters)",
         note="9: the shortest the 7-radius radiation cutoff allows (2.5 cutoffs)", read=_slice_diameters,
         write=_slice_length),
)

BY_NAME = {k.name: k for k in KNOBS}
NAMES = tuple(BY_NAME)
SCENES = ("tube", "short", "bed", "slice")


def runnable(knob: Knob) -> bool:
    """Whether the study runs ``knob``: it has settings."""
    return bool(knob.settings)


def nested(flat: dict) -> dict:
    """{"a.b": 1} -> {"a": {"b": 1}}."""
    out: dict = {}
    for key, value in flat.items():
        *path, last = key.split(".")
        node = out
        for part in path:
            node = node.setdefault(part, {})
        node[last] = value
    return out


def scene_base(cfg: dict, scene: str, watkins: dict | None = None) -> dict:
    """Overrides that make ``scene``'s base (module docstring) of its config: ``cfg`` (the first
    variant's) or, for the slice, the Watkins scene's ``watkins``."""
    if scene == "tube":
        base = {"dem": {"dump_interval": _finest_dump(cfg, FINEST)}}
        for knob in selected(cfg, watkins):
            if knob.scene == "tube":
                config.merge(base, knob.overrides(knob.reference, cfg))
        return base
    if scene == "short":
        return copy.deepcopy(cfg["accuracy"]["short_scene"])
    if scene == "slice":
        base = {"dem": {"dump_interval": _finest_dump(watkins, SLICE_FINEST)},
                "thermal": {"frame_stride": SLICE_FINEST * watkins["thermal"]["frame_stride"]}}  # fmt: skip
        if BY_NAME["slice_record"] in selected(cfg, watkins):  # one DEM run for every record
            base["dem"]["flow_time"] = max(s[0] for s in BY_NAME["slice_record"].settings)
            base["thermal"]["slice"] = {"record": _slice_record(watkins)[0]}
        return base
    return {}


def _finest_dump(cfg: dict, finest: int) -> int:
    interval = cfg["dem"]["dump_interval"]
    if interval % finest:
        raise ConfigError(f"dem.dump_interval: {interval} is not a multiple of {finest}; the accuracy study "
                                 f"dumps the DEM {finest} times as often for its thermal-step knob")
    return interval // finest


def selected(cfg: dict, watkins: dict | None = None) -> list[Knob]:
    """The knobs ``accuracy.knobs`` selects (all by default), runnable ones only; the slice's
    (checked against the Watkins scene ``watkins``) only with a Watkins scene."""
    named = cfg["accuracy"].get("knobs")
    names = named or list(NAMES)
    unknown = sorted(set(names) - set(NAMES))
    if unknown:
        raise ConfigError(f"accuracy.knobs: unknown knob(s) {unknown}; knobs: {', '.join(NAMES)}")
    knobs = [BY_NAME[n] for n in names if runnable(BY_NAME[n])]
    if watkins is None:
        if named and any(k.scene == "slice" for k in knobs):
            raise ConfigError(f"accuracy.knobs: {', '.join(k.name for k in knobs if k.scene == 'slice')} need the "
                              "Watkins scene (the config's watkins section)")
        knobs = [k for k in knobs if k.scene != "slice"]
    for knob in knobs:  # absolute settings are around the scene's own
        if knob.scene in ("short", "slice"):
            scene = watkins if knob.scene == "slice" else config.merge(copy.deepcopy(cfg), cfg["accuracy"]["short_scene"])
            actual = knob.value_in(scene)
            if actual != knob.default:
                raise ConfigError(f"accuracy.knobs: {knob.name} varies {', '.join(knob.keys)} around {knob.default}, "
                                  f"but the {knob.scene} scene has {actual}; leave it out of accuracy.knobs")
    return knobs


def _get(cfg: dict, key: str):
    for part in key.split("."):
        cfg = cfg[part]
    return cfg


def settings(cfg: dict, watkins: dict | None = None) -> list[dict]:
    """Every run of the study: {knob, setting (index), label, scene, overrides, reference (bool),
    default (bool), record}; the overrides are of the scene's config (``cfg``, the first variant's,
    or the Watkins scene's ``watkins`` for the slice): its base with the setting merged. ``record``
    is the fraction of the DEM run's flow the setting uses: for ``record_length`` the fraction of
    the reference run it is evaluated on, for a slice the record it reuses."""
    runs = []
    for knob in selected(cfg, watkins):
        scene = watkins if knob.scene == "slice" else cfg
        base = scene_base(cfg, knob.scene, watkins)
        for index, setting in enumerate(knob.settings):
            overrides = config.merge(copy.deepcopy(base), knob.overrides(setting, config.merge(copy.deepcopy(scene), base)))
            record = setting[0] if knob.name == "record_length" else 1.0
            if knob.scene == "slice":
                merged = config.merge(copy.deepcopy(scene), overrides)
                record = _slice_record(merged)[0] / merged["dem"]["flow_time"]
            runs.append({"knob": knob.name, "setting": index, "label": knob.name_of(setting), "value": list(setting),
                         "scene": knob.scene, "overrides": overrides, "reference": setting == knob.reference,
                         "default": setting == knob.default, "record": record})  # fmt: skip
    return runs
