"""The segments of a chain (docs/theory/chain.md), from a scene's ``chain`` section and its geometry.

The tube of the scene (``geometry.tube``, its inserts ``geometry.mixers`` at their heights) is cut
along the flow, from ``chain.inlet_height`` down to the orifice plate, into:

- **resolved** segments: every insert with ``margin_above`` particle diameters of plain tube above
  it and ``margin_below`` below (inserts whose resolved stretches overlap share one segment), and,
  with ``outlet_margin`` > 0, the orifice plate with that much tube above it: a full DEM of the
  stretch at the scene's mass flow, recycled, fed at its top by the field of the segment above;
- **slices**: the plain stretches between them, each a travelling slice of ``slice_length``
  diameters (the Watkins reduction, :mod:`dpht.thermal.slice`) carried over the stretch, started
  from the field of the segment above. A plain stretch is cut where the heated range of
  ``geometry.tube.heated`` begins or ends (a slice's wall is one zone: heated or adiabatic all the
  way) and at the heights ``chain.cuts`` names (joints of slice to slice, whose hand-over costs
  what the field does not carry).

Segments are in flow order (top first, z decreasing). Two resolved segments of the same
:meth:`Segment.shape` (the same inserts at the same places relative to the segment, the same
length) are one DEM run wherever they appear: N identical mixers in series cost one mixer DEM.
Positions are m along the tube's z (the geometry's: the orifice plate at ``orifice_height``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from dpht.errors import ConfigError
from dpht.geometry.layout import layout

SLICE, RESOLVED = "slice", "resolved"
JOINT_TOLERANCE = 1e-9  # m: a cut this close to a stretch's end is that end (no slice of round-off length)


@dataclass(frozen=True)
class FieldGrid:
    """The hand-over field's resolution (``chain.field``): equal-area rings x sectors."""

    rings: int
    sectors: int


@dataclass(frozen=True)
class Insert:
    """An insert of the tube: its index in ``geometry.mixers`` and the heights (m) it spans."""

    index: int
    bottom: float
    top: float


@dataclass(frozen=True)
class Segment:
    """One segment: its kind (SLICE or RESOLVED), its ends (m, z) and, for a resolved one, the
    inserts in it, ``outlet`` when it holds the orifice plate."""

    kind: str
    bottom: float  # m
    top: float  # m
    inserts: tuple[Insert, ...] = ()
    outlet: bool = False

    @property
    def length(self) -> float:
        """m along the tube."""
        return self.top - self.bottom

    def shape(self, geometry: dict) -> str:
        """What a resolved segment's DEM depends on along the tube, as a canonical JSON string: its
        length, its inserts' configs (``height`` left out) with the heights they span measured from
        its bottom (m, rounded to a nanometre), and whether it holds the plate. Equal shapes at
        equal flows share one DEM run."""
        mixers = []
        for insert in self.inserts:
            mixer = {k: v for k, v in geometry["mixers"][insert.index].items() if k != "height"}
            mixer["span"] = [round(insert.bottom - self.bottom, 9), round(insert.top - self.bottom, 9)]
            mixers.append(mixer)
        return json.dumps({"length": round(self.length, 9), "mixers": mixers, "outlet": self.outlet}, sort_keys=True)


@dataclass(frozen=True)
class Chain:
    """A scene's tube as segments (module docstring): ``segments`` in flow order, the slices'
    length (m), the field's grid and the tube's inlet and outlet heights (m)."""

    segments: tuple[Segment, ...]
    slice_length: float  # m
    field: FieldGrid
    inlet: float  # m, z where the particles enter (the top of the first segment)
    outlet: float  # m, z of the orifice plate (the bottom of the last)

    @classmethod
    def of(cls, cfg: dict) -> Chain:
        """The chain of a scene's merged config (its ``chain`` section, schema defaults filled);
        ConfigError naming the key when the section does not fit the geometry."""
        c, d = cfg["chain"], cfg["particles"]["diameter"]
        parts = layout(cfg["geometry"], d)
        tube = parts.tube
        outlet = float(cfg["geometry"]["tube"]["orifice_height"])
        inlet = float(c.get("inlet_height", tube.length))
        if not outlet < inlet <= tube.length:
            raise ConfigError(f"chain.inlet_height: {inlet} m is not within the tube above its orifice plate "
                              f"({outlet} m < z <= geometry.tube.length = {tube.length} m)")  # fmt: skip
        above, below = c["margin_above"] * d, c["margin_below"] * d
        spans = []  # (bottom, top, inserts, outlet) of the resolved stretches, before merging
        for i, mixer in enumerate(parts.mixers):
            bottom, top = mixer.z_range()
            if top > inlet:
                raise ConfigError(f"geometry.mixers[{i}]: reaches z = {top:.6g} m, above chain.inlet_height = {inlet:.6g} m "
                                  "(every insert must lie below where the particles enter)")  # fmt: skip
            spans.append((max(bottom - below, outlet), min(top + above, inlet), (Insert(i, bottom, top),), False))
        if c["outlet_margin"] > 0:
            spans.append((outlet, min(outlet + c["outlet_margin"] * d, inlet), (), True))
        resolved = []
        for span in sorted(spans, key=lambda s: (-s[1], -s[0])):  # top first
            if resolved and span[1] >= resolved[-1][0]:  # overlaps (or touches) the one above: one segment
                b, t, ins, out = resolved[-1]
                resolved[-1] = (min(b, span[0]), t, tuple(sorted(ins + span[2], key=lambda m: -m.top)), out or span[3])
            else:
                resolved.append(span)
        joints = sorted({*map(float, cfg["geometry"]["tube"]["heated"]), *map(float, c["cuts"])}, reverse=True)
        for k, cut in enumerate(map(float, c["cuts"])):
            if not outlet < cut < inlet:
                raise ConfigError(f"chain.cuts[{k}]: {cut} m is not between the orifice plate ({outlet} m) and "
                                  f"chain.inlet_height ({inlet} m)")  # fmt: skip

        def plain(top: float, bottom: float) -> list[Segment]:  # slices from top down to bottom, cut at the joints
            ends = [top, *(j for j in joints if bottom + JOINT_TOLERANCE < j < top - JOINT_TOLERANCE), bottom]
            return [Segment(SLICE, b, t) for t, b in zip(ends, ends[1:])]

        segments, z = [], inlet
        for bottom, top, inserts, has_outlet in resolved:
            if top < z:
                segments += plain(z, top)
            segments.append(Segment(RESOLVED, bottom, top, inserts, has_outlet))
            z = bottom
        if z > outlet:
            segments += plain(z, outlet)
        field = FieldGrid(int(c["field"]["rings"]), int(c["field"]["sectors"]))
        return cls(tuple(segments), c["slice_length"] * d, field, inlet, outlet)

    def shapes(self, geometry: dict) -> dict[str, list[int]]:
        """Each distinct resolved segment's :meth:`Segment.shape` -> the indices of the segments of
        that shape (the DEM runs the chain needs, and where each is used)."""
        found: dict[str, list[int]] = {}
        for k, s in enumerate(self.segments):
            if s.kind == RESOLVED:
                found.setdefault(s.shape(geometry), []).append(k)
        return found
