"""Flat-plate mixer (DPHT paper, Section 6, Fig. 14a): a horizontal plate across the tube with a
circular-segment opening on one side through which the particles pass.

The plate is a solid disk of the tube's radius, ``thickness`` thick, with its top face at ``height``,
minus the segment ``opening`` (a fraction of the cross-section) whose middle lies at azimuth
``orientation`` (degrees from +x towards +y). Its rim lies on the tube wall ("welded"): those faces
are hidden from the particles but keep the solid closed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from dpht.geometry import checks
from dpht.geometry.tube import Tube

TYPE = "flat_plate"
REQUIRED = ("type", "height", "thickness", "opening")
OPTIONAL = ("orientation", "zone")


def segment_angle(fraction: float) -> float:
    """Central angle (rad) of the circular segment covering ``fraction`` of the disk.

    Segment area R^2 (theta - sin theta) / 2 = fraction * pi R^2, solved for theta in (0, 2 pi).
    """
    return brentq(lambda theta: theta - math.sin(theta) - 2.0 * math.pi * fraction, 0.0, 2.0 * math.pi, xtol=1e-15)


@dataclass(frozen=True)
class FlatPlate:
    """A plate with a segment opening; lengths in m, ``orientation`` in degrees."""

    key: str
    zone: str
    radius: float  # the tube's inner radius
    height: float
    thickness: float
    opening: float
    orientation: float

    @classmethod
    def from_config(cls, cfg: dict, key: str, zone: str, tube: Tube) -> FlatPlate:
        """Check one ``geometry.mixers`` item of type flat_plate; GeometryConfigError names ``key.<name>``."""
        checks.keys(cfg, key, REQUIRED, OPTIONAL)
        return cls(
            key,
            zone,
            tube.radius,
            checks.number(cfg["height"], f"{key}.height"),
            checks.positive(cfg["thickness"], f"{key}.thickness"),
            checks.between(cfg["opening"], f"{key}.opening", 0.0, 1.0, "fraction of the tube cross-section"),
            checks.number(cfg.get("orientation", 0.0), f"{key}.orientation", "degrees"),
        )

    @property
    def angle(self) -> float:
        """Central angle (rad) of the open segment."""
        return segment_angle(self.opening)

    @property
    def sagitta(self) -> float:
        """Width (m) of the opening across its chord: the diameter of the largest sphere that fits."""
        return self.radius * (1.0 - math.cos(0.5 * self.angle))

    @property
    def chord(self) -> float:
        return 2.0 * self.radius * math.sin(0.5 * self.angle)

    def z_range(self) -> tuple[float, float]:
        return self.height - self.thickness, self.height

    def passages(self) -> list[tuple[str, str, float]]:
        """(config key, description, width in m) of every passage the particles must get through."""
        return [(f"{self.key}.opening", "opening (segment height)", self.sagitta)]

    def surface_points(self, n: int = 24) -> np.ndarray:
        """Points (P, 3) m on the plate's surface, ``n`` azimuths: its top and bottom faces, its rim
        and its chord face (for checks before gmsh meshes it, see geometry.layout)."""
        r, top, bottom = self.radius, self.height, self.height - self.thickness
        turn = math.radians(self.orientation)
        theta = 2 * np.pi * (np.arange(n) + 0.5) / n
        radius = r * np.sqrt((np.arange(4) + 0.5) / 4)
        t, rr = np.meshgrid(theta, radius)
        faces = [(rr.ravel(), t.ravel(), z) for z in (top, bottom)] + [(np.full(n, r), theta, 0.5 * (top + bottom))]
        points = []
        for rr_, tt, z in faces:
            keep = rr_ * np.cos(tt - turn) < r - self.sagitta  # outside the opening
            points.append(np.column_stack([rr_ * np.cos(tt), rr_ * np.sin(tt), np.full(rr_.size, z)])[keep])
        along = 0.5 * self.chord * np.linspace(-0.9, 0.9, n)
        x, y = r - self.sagitta, along
        points.append(np.column_stack([x * math.cos(turn) - y * math.sin(turn), x * math.sin(turn) + y * math.cos(turn),
                                       np.full(n, 0.5 * (top + bottom))]))  # fmt: skip
        return np.concatenate(points)

    def add_to_model(self) -> list[int]:
        """Add the plate solid to the gmsh OCC model (not synchronised); return its volume tags."""
        import gmsh

        occ = gmsh.model.occ
        r, t = self.radius, self.thickness
        disk = occ.addCylinder(0.0, 0.0, self.height - t, 0.0, 0.0, t, r)
        # The opening: everything beyond the chord, x > r - sagitta, before turning to `orientation`.
        cutter = occ.addBox(r - self.sagitta, -2.0 * r, self.height - 2.0 * t, 2.0 * r, 4.0 * r, 3.0 * t)
        occ.rotate([(3, cutter)], 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, math.radians(self.orientation))
        plate, _ = occ.cut([(3, disk)], [(3, cutter)])
        return [tag for dim, tag in plate if dim == 3]
