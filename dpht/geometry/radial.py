"""Radial mixer (DPHT paper, Section 6, Fig. 14b): a funnel that guides the particles near the wall
to the centre, plus small inclined tubes that carry particles from near the axis to the wall.

Layout (z up, flow towards -z; lengths in m, angles in degrees from the horizontal):

* Funnel: a conical shell whose upper surface runs from the rim (radius R_in = inlet_diameter/2,
  at z = ``height``, the top of the mixer) down to the outlet (radius r_out = outlet_diameter/2)
  at slope ``angle``. Its profile is a parallelogram with vertical sides, so the wall is
  ``wall_thickness`` thick normal to the cone (vertical offset dz = thickness / cos(angle)). With
  R_in = the tube radius the rim lies on the tube wall (welded); a smaller R_in leaves an annular
  gap that the particles must be able to pass.
* Small tubes: ``n_tubes`` straight tubes of inner diameter ``tube_diameter`` and the same wall
  thickness, equally spaced in azimuth starting at ``orientation``, inclined at ``inclination``
  and pointing outwards-down. Both ends are cut horizontally: the inlet at the funnel rim level,
  centred ``tube_inlet_radius`` from the axis (inside the funnel, so it collects particles near the
  axis), and the outlet where the bore touches the tube wall, below the funnel's underside, so
  these particles leave next to the wall. The tube walls cross and fuse with the funnel wall; the
  bores are cut through it. Parts beyond the tube wall are clipped off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dpht.geometry.errors import GeometryConfigError

from dpht.geometry import checks
from dpht.geometry.tube import Tube

TYPE = "radial"
REQUIRED = ("type", "height", "outlet_diameter", "angle", "wall_thickness", "n_tubes")
TUBE_KEYS = ("tube_diameter", "inclination", "tube_inlet_radius")
OPTIONAL = ("inlet_diameter", "orientation", "zone", *TUBE_KEYS)


@dataclass(frozen=True)
class RadialMixer:
    """Funnel + small tubes; lengths in m, angles in radians (converted from the config's degrees)."""

    key: str
    zone: str
    tube_radius: float
    height: float
    inlet_radius: float
    outlet_radius: float
    angle: float
    wall_thickness: float
    n_tubes: int
    bore_radius: float = 0.0
    inclination: float = 0.0
    tube_inlet_radius: float = 0.0
    orientation: float = 0.0

    @classmethod
    def from_config(cls, cfg: dict, key: str, zone: str, tube: Tube) -> RadialMixer:
        """Check one ``geometry.mixers`` item of type radial; GeometryConfigError names ``key.<name>``."""
        checks.keys(cfg, key, REQUIRED, OPTIONAL)
        n_tubes = checks.count(cfg["n_tubes"], f"{key}.n_tubes")
        missing = [name for name in TUBE_KEYS if name not in cfg]
        if n_tubes and missing:
            raise GeometryConfigError(f"{key}: n_tubes = {n_tubes} needs {missing}")
        degrees = "degrees from the horizontal"
        small = {}  # the small tubes' keys may stay in a config whose n_tubes is 0 (variants only override)
        if not missing:
            small = {
                "bore_radius": 0.5 * checks.positive(cfg["tube_diameter"], f"{key}.tube_diameter"),
                "inclination": math.radians(
                    checks.between(cfg["inclination"], f"{key}.inclination", 0.0, 90.0, degrees)),
                "tube_inlet_radius": checks.positive(cfg["tube_inlet_radius"], f"{key}.tube_inlet_radius"),
            }
        mixer = cls(
            key,
            zone,
            tube.radius,
            checks.number(cfg["height"], f"{key}.height"),
            0.5 * checks.positive(cfg.get("inlet_diameter", tube.inner_diameter), f"{key}.inlet_diameter"),
            0.5 * checks.positive(cfg["outlet_diameter"], f"{key}.outlet_diameter"),
            math.radians(checks.between(cfg["angle"], f"{key}.angle", 0.0, 90.0, degrees)),
            checks.positive(cfg["wall_thickness"], f"{key}.wall_thickness"),
            n_tubes,
            orientation=math.radians(checks.number(cfg.get("orientation", 0.0), f"{key}.orientation", "degrees")),
            **small,
        )
        mixer._check_layout()
        return mixer

    # --- derived dimensions (m) -------------------------------------------------------------
    @property
    def dz(self) -> float:
        """Vertical thickness of the funnel wall."""
        return self.wall_thickness / math.cos(self.angle)

    @property
    def funnel_bottom(self) -> float:
        """z of the funnel's lowest point, the bottom edge of its outlet (the upper cone ends dz higher)."""
        upper = self.height - (self.inlet_radius - self.outlet_radius) * math.tan(self.angle)
        return upper - self.dz

    def funnel_underside(self, r: float) -> float:
        """z of the funnel's lower surface at radius r (outlet radius <= r <= inlet radius)."""
        return self.height - self.dz - (self.inlet_radius - r) * math.tan(self.angle)

    @property
    def outer_radius(self) -> float:
        """Outer radius of the small tubes."""
        return self.bore_radius + self.wall_thickness

    @property
    def outlet_centre(self) -> float:
        """Distance from the axis of a small tube's outlet centre: its bore touches the tube wall."""
        return self.tube_radius - self.bore_radius / math.sin(self.inclination)

    @property
    def tube_bottom(self) -> float:
        """z of the small tubes' outlets."""
        return self.height - (self.outlet_centre - self.tube_inlet_radius) * math.tan(self.inclination)

    def azimuths(self) -> np.ndarray:
        """Azimuths (rad) of the small tubes."""
        return self.orientation + 2.0 * math.pi * np.arange(self.n_tubes) / self.n_tubes

    def tube_axis(self, azimuth: float) -> tuple[np.ndarray, np.ndarray]:
        """Inlet and outlet centres (3,) of the small tube at ``azimuth``, on its axis."""
        radial = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
        inlet = self.tube_inlet_radius * radial + [0.0, 0.0, self.height]
        outlet = self.outlet_centre * radial + [0.0, 0.0, self.tube_bottom]
        return inlet, outlet

    def z_range(self) -> tuple[float, float]:
        bottom = min(self.funnel_bottom, self.tube_bottom) if self.n_tubes else self.funnel_bottom
        return bottom, self.height

    # --- checks -------------------------------------------------------------------------------
    def passages(self) -> list[tuple[str, str, float]]:
        """(config key, description, width in m) of every passage the particles must get through."""
        key = self.key
        found = [(f"{key}.outlet_diameter", "funnel outlet", 2.0 * self.outlet_radius)]
        if self.inlet_radius < self.tube_radius:
            found.append((f"{key}.inlet_diameter", "annular gap between funnel rim and tube wall",
                          self.tube_radius - self.inlet_radius))
        if self.n_tubes:
            found.append((f"{key}.tube_diameter", "small-tube bore", 2.0 * self.bore_radius))
        if self.n_tubes >= 2:
            # Horizontal sections of the tube walls at the inlet level are ellipses with semi-axes
            # a (radial) and b (tangential); the opening around the axis has radius r_in - a.
            a, b = self.outer_radius / math.sin(self.inclination), self.outer_radius
            found.append((f"{key}.tube_inlet_radius", "opening between the small-tube inlets at the axis",
                          2.0 * (self.tube_inlet_radius - a)))
        if self.n_tubes >= 3:
            # Neighbouring inlets are mirror images in the bisecting plane, so their gap is twice the
            # distance from one ellipse to that plane: centre offset minus the support function.
            s, c = math.sin(math.pi / self.n_tubes), math.cos(math.pi / self.n_tubes)
            found.append((f"{key}.tube_inlet_radius", "gap between neighbouring small-tube inlets",
                          2.0 * (self.tube_inlet_radius * s - math.hypot(a * s, b * c))))
        return found

    def _check_layout(self) -> None:
        key = self.key
        if self.inlet_radius > self.tube_radius:
            raise GeometryConfigError(f"{key}.inlet_diameter ({2 * self.inlet_radius} m) exceeds the tube's inner diameter")
        if self.outlet_radius >= self.inlet_radius:
            raise GeometryConfigError(f"{key}.outlet_diameter must be smaller than inlet_diameter ({2 * self.inlet_radius} m)")
        if not self.n_tubes:
            return
        inlet_reach = self.tube_inlet_radius + self.outer_radius / math.sin(self.inclination)
        if inlet_reach >= self.inlet_radius:
            raise GeometryConfigError(
                f"{key}.tube_inlet_radius: the small-tube inlets reach r = {inlet_reach:.4g} m, outside the "
                f"funnel rim (r = {self.inlet_radius:.4g} m); move them towards the axis or make the tubes thinner"
            )
        if self.tube_inlet_radius >= self.outlet_centre:
            raise GeometryConfigError(
                f"{key}.tube_inlet_radius ({self.tube_inlet_radius} m) must be smaller than the radius of the "
                f"outlet centres ({self.outlet_centre:.4g} m) so that the tubes lead outwards"
            )
        bore_inner = self.tube_radius - 2.0 * self.bore_radius / math.sin(self.inclination)
        if bore_inner < self.inlet_radius and (
            bore_inner <= self.outlet_radius or self.tube_bottom >= self.funnel_underside(bore_inner)
        ):
            raise GeometryConfigError(
                f"{key}.inclination: the small-tube outlets (z = {self.tube_bottom:.4g} m, reaching in to "
                f"r = {bore_inner:.4g} m) are not below the funnel; steepen the tubes or flatten the funnel"
            )
        # The tube walls must stay out of the funnel's outlet bore (r < r_out) where the funnel has a wall.
        funnel_top_of_outlet = self.funnel_bottom + self.dz
        top = min(funnel_top_of_outlet, self.height)
        if top >= max(self.funnel_bottom, self.tube_bottom):
            reach = (self.outlet_centre - (top - self.tube_bottom) / math.tan(self.inclination)
                     - self.outer_radius / math.sin(self.inclination))
            if reach < self.outlet_radius:
                raise GeometryConfigError(
                    f"{key}.inclination: the small tubes cut into the funnel outlet (they reach r = {reach:.4g} m "
                    f"< {self.outlet_radius:.4g} m at z = {top:.4g} m)"
                )

    def surface_points(self, n: int = 24) -> np.ndarray:
        """Points (P, 3) m on the mixer's surface, ``n`` azimuths: the funnel's upper and lower cones
        (less where the small tubes' bores pierce them) and outlet bore, and the small tubes' outer
        walls between inlet and outlet (for checks before gmsh meshes it, see geometry.layout; the
        tubes' points inside the fused funnel wall are kept: they lie within a wall thickness of
        the surface)."""
        theta = 2 * np.pi * (np.arange(n) + 0.5) / n
        r = self.outlet_radius + (self.inlet_radius - self.outlet_radius) * (np.arange(6) + 0.5) / 6
        t, rr = np.meshgrid(theta, r)
        upper = self.height - (self.inlet_radius - rr) * math.tan(self.angle)
        cones = np.concatenate([np.column_stack([(rr * np.cos(t)).ravel(), (rr * np.sin(t)).ravel(), z.ravel()])
                                for z in (upper, upper - self.dz)])  # fmt: skip
        bore = np.column_stack([self.outlet_radius * np.cos(theta), self.outlet_radius * np.sin(theta),
                                np.full(n, self.funnel_bottom + 0.5 * self.dz)])  # fmt: skip
        axes = [self.tube_axis(azimuth) for azimuth in (self.azimuths() if self.n_tubes else ())]
        for inlet, outlet in axes:
            axis = (outlet - inlet) / np.linalg.norm(outlet - inlet)
            offset = cones - inlet
            cones = cones[np.linalg.norm(offset - np.outer(offset @ axis, axis), axis=1) > self.bore_radius]
        points = [cones, bore]
        psi = 2 * np.pi * np.arange(8) / 8
        for azimuth, (inlet, outlet) in zip(self.azimuths(), axes):
            axis = (outlet - inlet) / np.linalg.norm(outlet - inlet)
            u = np.array([-math.sin(azimuth), math.cos(azimuth), 0.0])
            v = np.cross(axis, u)
            along = inlet + np.linspace(0.1, 0.9, 6)[:, None] * (outlet - inlet)
            ring = self.outer_radius * (np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * v)
            wall = (along[:, None, :] + ring[None]).reshape(-1, 3)
            inside = ((wall[:, 2] >= self.tube_bottom) & (wall[:, 2] <= self.height)
                      & (np.hypot(wall[:, 0], wall[:, 1]) <= self.tube_radius))  # the cuts and the clip
            points.append(wall[inside])
        return np.concatenate(points)

    # --- CAD ----------------------------------------------------------------------------------
    def add_to_model(self) -> list[int]:
        """Add the mixer solid to the gmsh OCC model (not synchronised); return its volume tags."""
        import gmsh

        occ = gmsh.model.occ
        r_in, r_out, z_top, dz = self.inlet_radius, self.outlet_radius, self.height, self.dz
        z_low = self.funnel_bottom
        corners = [(r_in, z_top), (r_out, z_low + dz), (r_out, z_low), (r_in, z_top - dz)]
        points = [occ.addPoint(r, 0.0, z) for r, z in corners]
        lines = [occ.addLine(points[i], points[(i + 1) % 4]) for i in range(4)]
        profile = occ.addPlaneSurface([occ.addCurveLoop(lines)])
        funnel = [dt for dt in occ.revolve([(2, profile)], 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0 * math.pi) if dt[0] == 3]
        if not self.n_tubes:
            return [tag for _, tag in funnel]
        walls, bores = [], []
        for azimuth in self.azimuths():
            inlet, outlet = self.tube_axis(azimuth)
            axis = (outlet - inlet) / np.linalg.norm(outlet - inlet)
            for radius, solids in ((self.outer_radius, walls), (self.bore_radius, bores)):
                # Extend past both cut planes far enough that the slanted end disks clear them.
                reach = (radius * math.cos(self.inclination) + self.wall_thickness) / math.sin(self.inclination)
                start, end = inlet - reach * axis, outlet + reach * axis
                solids.append((3, occ.addCylinder(*start, *(end - start), radius)))
        bottom = self.tube_bottom
        clip = occ.addCylinder(0.0, 0.0, bottom, 0.0, 0.0, z_top - bottom, self.tube_radius)
        walls, _ = occ.intersect(walls, [(3, clip)])
        body, _ = occ.fuse(funnel, walls)
        body, _ = occ.cut(body, bores)
        return [tag for dim, tag in body if dim == 3]
