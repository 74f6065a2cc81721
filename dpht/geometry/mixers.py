"""The ``geometry.mixers`` list: one checked object per mixer, and the checks that involve several
parts (passage widths against the particle size, vertical clearances between mixers, the orifice
plate and the periodic boundaries).

Every mixer is a closed solid inside the tube, occupying a z range [bottom, top]; its surface
triangles form the wall zone named by its ``zone`` key (default ``mixer``; mixers sharing a name
share the zone). Types (:data:`TYPES`): ``flat_plate`` and ``radial`` (the DPHT paper's), and
``stl``, a closed solid from the user's own CAD (:mod:`dpht.geometry.stl_mixer`).
"""

from __future__ import annotations

import re

from dpht.geometry.errors import GeometryConfigError

from dpht.geometry import plate, radial, stl_mixer
from dpht.geometry.plate import FlatPlate
from dpht.geometry.radial import RadialMixer
from dpht.geometry.stl_mixer import StlMixer
from dpht.geometry.tube import ADIABATIC, HEATED, ORIFICE, Tube

KEY = "geometry.mixers"
DEFAULT_ZONE = "mixer"
Mixer = FlatPlate | RadialMixer | StlMixer
TYPES = {plate.TYPE: FlatPlate, radial.TYPE: RadialMixer, stl_mixer.TYPE: StlMixer}
_ZONE_NAME = re.compile(r"[a-z][a-z0-9_]*")


def _zone(cfg: dict, key: str) -> str:
    zone = cfg.get("zone", DEFAULT_ZONE)
    if not isinstance(zone, str) or not _ZONE_NAME.fullmatch(zone) or zone in (HEATED, ADIABATIC, ORIFICE):
        raise GeometryConfigError(
            f"{key}.zone must be a lower-case name ([a-z][a-z0-9_]*) other than the tube zones "
            f"{[HEATED, ADIABATIC, ORIFICE]}, got {zone!r}"
        )
    return zone


def _check_spacing(mixers: list[Mixer], tube: Tube, gap: float) -> None:
    """Mixers lie inside (0, length) and leave at least ``gap`` (m) of height free between any two
    parts stacked along the axis (mixers and orifice plate), counting across the periodic boundary."""
    for mixer in mixers:
        bottom, top = mixer.z_range()
        if not (0.0 < bottom and top < tube.length):
            raise GeometryConfigError(
                f"{mixer.key}.height: the mixer spans z = [{bottom:.4g}, {top:.4g}] m, which must lie inside "
                f"the periodic domain (0, {tube.length}) m"
            )
    parts = sorted([(m.z_range(), m.key) for m in mixers] + [((tube.orifice_height,) * 2, "the orifice plate")])
    for i, ((_, top), lower) in enumerate(parts):
        (bottom, _), upper = parts[(i + 1) % len(parts)]
        clearance = bottom - top + (tube.length if i == len(parts) - 1 else 0.0)  # the last wraps around
        if clearance < gap:
            culprit = upper if upper.startswith(KEY) else lower
            raise GeometryConfigError(
                f"{culprit}.height: {lower} (top at z = {top:.4g} m) and {upper} (bottom at z = {bottom:.4g} m) "
                f"overlap or leave less than geometry.min_passage particle diameters ({gap:.4g} m) between them"
            )


def mixers_from_config(items, tube: Tube, particle_diameter: float, min_passage: float) -> list[Mixer]:
    """Check the ``geometry.mixers`` list (None or empty: no mixers) and return the mixers in order.

    Every passage a particle must take (plate opening, funnel outlet, small-tube bores, gaps) must be
    at least ``min_passage`` particle diameters wide; GeometryConfigError names the key to change.
    """
    if items is None:
        return []
    if not isinstance(items, list):
        raise GeometryConfigError(f"{KEY} must be a list of mappings, got {type(items).__name__}")
    mixers = []
    for index, cfg in enumerate(items):
        key = f"{KEY}[{index}]"
        kind = cfg.get("type") if isinstance(cfg, dict) else None
        if kind not in TYPES:
            raise GeometryConfigError(f"{key}.type must be one of {sorted(TYPES)}, got {kind!r}")
        mixers.append(TYPES[kind].from_config(cfg, key, _zone(cfg, key), tube))
    narrowest = min_passage * particle_diameter
    for mixer in mixers:
        for name, what, width in mixer.passages():
            if width < narrowest:
                raise GeometryConfigError(
                    f"{name}: the {what} is {width:.4g} m wide, less than geometry.min_passage = {min_passage} "
                    f"particle diameters ({narrowest:.4g} m)"
                )
    _check_spacing(mixers, tube, narrowest)
    return mixers
