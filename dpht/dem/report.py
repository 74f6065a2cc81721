"""The DEM run report: mass flow, solid fraction near the wall and in the bulk, passages through the
mixers, all from the gathered positions file (:mod:`dpht.dem.dumps`); no LIGGGHTS involved."""

from __future__ import annotations

import math

import numpy as np

from dpht.dem import dumps
from dpht.dem.params import GRAVITY, DemParams
from dpht.errors import DPHTError

# The report's layout, in the DEM stage's key (dpht.config.dem_spec): what a run reports changes its key.
FORMAT = "dpht-dem-report-2"
SOLID_FRACTION_MARGIN = 2.0  # particle diameters between the sampled bed and the plate, bed top, mixers
PROFILE_BIN = 0.5  # radial bin width of the solid-fraction profile, particle diameters
_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_NODES, _WEIGHTS = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W  # Gauss-Legendre on [0, 1], per smooth piece


def run_summary(
    params: DemParams, settle: dict, flow: dict, stats: dumps.GatherStats, positions: dumps.PositionsFile
) -> dict:
    """The run summary stored in the positions file (JSON-serialisable), from the settle and flow
    stages' states (:mod:`dpht.dem.liggghts`), the gather's statistics and the gathered ``positions``.

    Mass flow: net crossings of the periodic boundary below the orifice times the particle mass, over
    the whole flow and over its second half (the calibration's measure, past the start-up).
    """
    times = (stats.steps - stats.steps[0]) * params.timestep
    half = stats.n_frames // 2
    mass = params.particle_mass

    def rate(first: int) -> float:
        span = times[-1] - times[first]
        return float(mass * (stats.crossings[-1] - stats.crossings[first]) / span) if span > 0 else 0.0

    lost = dict(sorted(stats.lost_first_step.items()))
    return {
        "format": FORMAT,
        "particles": stats.n_particles,
        "particles_target": settle["particles_target"],
        "particles_inserted": settle["particles_inserted"],
        "particle_mass_kg": mass,
        "bed_top_settled_m": settle["bed_top_m"],
        "frames": stats.n_frames,
        "flow_steps": [int(stats.steps[0]), int(stats.steps[-1])],
        "mass_flow_kg_s": rate(0),
        "mass_flow_second_half_kg_s": rate(half),
        "mass_flow_method": (
            "net particle crossings of the periodic boundary z = 0 below the orifice (image flag iz in the "
            "dumps) times the particle mass, over the whole flow phase; also over its second half"
        ),
        "orifice_crossings": int(stats.crossings[-1]),
        # A bed that stops flowing before the end (an orifice or mixer jams) shows no crossing in the end;
        # a driven tube (dem.drive), whose record may be shorter than its transit, by its mean velocity.
        "jammed": _jammed(params, stats, positions),
        "lost_particles": {
            "count": len(lost),
            "ids": list(lost),
            "first_step": {str(k): v for k, v in lost.items()},
        },
        "rayleigh_time_s": params.rayleigh_time,
        "rayleigh_fraction": params.timestep / params.rayleigh_time,
        "rayleigh_fraction_liggghts": settle["rayleigh_fraction_liggghts"],
        "hertz_fraction_max": flow["hertz_fraction_max"],
        "flow_attempts": [attempt["start_step"] for attempt in flow["attempts"]],
        # MPI ranks change the trajectories (summation order, insertion near subdomain borders).
        "ranks": {"settle": settle["ranks"], "flow": [attempt["ranks"] for attempt in flow["attempts"]]},
        "wall_time_s": {
            "settle": settle["wall_time_s"],
            "flow": round(sum(a["wall_time_s"] or 0.0 for a in flow["attempts"]), 2),
        },
        "solid_fraction": solid_fraction_report(params, positions, settle["bed_top_m"]),
        "wall_load": wall_stress_report(params, settle, positions),
        "mixers": mixer_crossings(params, positions),
        "drive": drive_report(params, flow.get("drive_acceleration"), int(stats.steps[half])),
        # Which surface LIGGGHTS collided particles with, per wall zone (the thermal stage uses the same).
        "walls": params.wall_kinds,
    }


def drive_report(params: DemParams, record, half_step: int) -> dict | None:
    """The controller of a driven flow (dem.drive; None for an orifice flow): its target, and the net
    body acceleration it applied (m/s^2 downwards, the effective gravity; ``record`` = [[step,
    acceleration averaged over the thermo interval ending there], ...]) over the second half of the
    flow (steps after ``half_step``, as the second-half mass flow), also relative to gravity. Below
    1 g the bed, mixers and orifice pass the flow with less push than gravity gives: a gravity-fed
    tube would pass it too, metered by an orifice below."""
    if not params.driven:
        return None
    record = np.asarray(record or [], dtype=float).reshape(-1, 2)
    second = record[record[:, 0] > half_step, 1]
    mean = float(second.mean()) if second.size else math.nan
    target = ({"mass_flow_kg_s": params.drive_mass_flow} if params.drive_mass_flow is not None
              else {"velocity_m_s": params.drive_velocity})  # fmt: skip
    return {
        **target,
        "time_constant_s": params.drive_time_constant,
        "orifice": params.drive_orifice,
        "acceleration_m_s2": mean,
        "acceleration_over_gravity": mean / GRAVITY,
        "acceleration_max_m_s2": float(second.max()) if second.size else math.nan,
        "method": "net body acceleration (gravity + the controller's force) per unit mass, downwards, averaged "
                  "over each dump interval; mean and largest interval over the second half of the flow",
        "record": record.tolist(),
    }


def wall_stress(params: DemParams, positions: np.ndarray, length: float) -> float:
    """Pa: the mean normal stress of the particles on the tube wall over ``length`` m of it, from
    their Hertz overlaps with the cylinder (:attr:`DemParams.wall_hertz`; at rest the contact
    damping adds nothing). The deck loading a packed slice measures the same (decks/pack.in)."""
    gap = np.hypot(positions[:, 0], positions[:, 1]) + params.radius - params.tube_radius
    force = params.wall_hertz * np.clip(gap, 0.0, None) ** 1.5
    return float(force.sum() / (2.0 * np.pi * params.tube_radius * length))


def wall_stress_report(params: DemParams, settle: dict, positions: dumps.PositionsFile) -> dict | None:
    """A packed slice's load: the target (dem.drive.wall_stress), the settled bed's and the mean over
    the flow's frames, and the box length it was shortened to; None for a poured bed."""
    if not params.packed:
        return None
    length = dumps.axial_length(positions.attrs)
    flowing = [wall_stress(params, frame.positions.astype(np.float64), length) for frame in positions.frames()]
    return {
        "target_Pa": params.wall_stress,
        "settled_Pa": settle.get("wall_stress_Pa", 0.0),
        "flowing_Pa": float(np.mean(flowing)),
        "length_m": length,
        "solid_fraction": positions.n_particles * params.radius**3 * 4.0 / 3.0 / (params.tube_radius**2 * length),
        "method": "Hertz normal forces of the particles' overlaps with the tube cylinder over its area",
    }


def _jammed(params: DemParams, stats: dumps.GatherStats, positions: dumps.PositionsFile) -> bool:
    """Whether the bed stopped flowing in the last quarter of the flow: no crossing of the periodic
    boundary then, or for a driven run (dem.drive; its record may be shorter than one transit) a mean
    downward velocity below half its target (dem.drive.velocity, or dem.drive.mass_flow x length / mass
    of all particles, as the controller holds it: decks._drive)."""
    if stats.n_frames < 2:
        return False
    start = (3 * stats.n_frames) // 4
    if not params.driven:
        return bool(stats.crossings[-1] == stats.crossings[start])
    start = min(start, stats.n_frames - 2)
    first, last = positions.frame(start), positions.frame(stats.n_frames - 1)
    target = (params.drive_velocity if params.drive_velocity is not None
              else params.drive_mass_flow * params.length / (len(last.positions) * params.particle_mass))
    drop = -dumps.axial_step(first.positions[:, 2], last.positions[:, 2], first.image, last.image, params.length)
    span = (stats.steps[-1] - stats.steps[start]) * params.timestep
    return bool(np.nanmean(drop) / span < 0.5 * target)


def mass_flow_check(measured: float, target: float, tolerance: float) -> dict:
    """Compare a measured mass flow (kg/s) with its target; off target beyond the relative tolerance."""
    error = measured / target - 1.0
    return {
        "target_kg_s": target,
        "tolerance": tolerance,
        "measured_kg_s": measured,
        "relative_error": error,
        "off_target": bool(abs(error) > tolerance),
    }


def _lens_area(c: np.ndarray, a: float, s: np.ndarray) -> np.ndarray:
    """Area (m^2) common to the disk of radius ``a`` about the origin and disks of radii ``s`` whose
    centres lie at distances ``c`` from it (arrays of equal shape)."""
    inner = c <= np.abs(a - s)
    outer = c >= a + s
    c_safe = np.where(inner | outer, 1.0, c)
    cos_a = np.clip((c_safe**2 + a**2 - s**2) / (2.0 * c_safe * a), -1.0, 1.0)
    cos_s = np.clip((c_safe**2 + s**2 - a**2) / (2.0 * c_safe * np.maximum(s, 1e-300)), -1.0, 1.0)
    kite = np.sqrt(np.maximum((-c_safe + a + s) * (c_safe + a - s) * (c_safe - a + s) * (c_safe + a + s), 0.0))
    lens = a**2 * np.arccos(cos_a) + s**2 * np.arccos(cos_s) - 0.5 * kite
    return np.where(outer, 0.0, np.where(inner, np.pi * np.minimum(a, s) ** 2, lens))


def sphere_in_cylinder(rho: np.ndarray, radius: float, a: float) -> np.ndarray:
    """Volume (m^3) of each sphere of ``radius`` centred at distance ``rho`` (m) from the z axis that
    lies inside the cylinder of radius ``a`` about that axis.

    V = 2 * integral_0^r A(z) dz, with A the lens area (:func:`_lens_area`) of the cylinder's cross-
    section and the sphere's slice of radius sqrt(r^2 - z^2). A has kinks where the slice circle
    touches the cylinder's (slice radius |a - rho| or a + rho): the integral is split there and each
    smooth piece integrated by Gauss-Legendre. Spheres wholly inside or outside are exact.
    """
    rho = np.asarray(rho, dtype=float)
    r = float(radius)
    volume = np.where(rho + r <= a, 4.0 / 3.0 * math.pi * r**3, 0.0)
    cut = (np.abs(rho - a) < r) & (a > 0.0)
    c = rho[cut][:, None]
    edges = np.hstack([
        np.zeros_like(c),
        np.sqrt(np.clip(r**2 - (a + c) ** 2, 0.0, None)),
        np.sqrt(np.clip(r**2 - (a - c) ** 2, 0.0, None)),
        np.full_like(c, r),
    ])
    widths = np.diff(edges, axis=1)  # (n, 3) pieces
    z = edges[:, :-1, None] + widths[:, :, None] * _NODES  # (n, 3, nodes)
    area = _lens_area(c[:, :, None], a, np.sqrt(np.clip(r**2 - z**2, 0.0, None)))
    volume[cut] = 2.0 * np.einsum("ij,ijk,k->i", widths, area, _WEIGHTS)
    return volume


def _sample_window(params: DemParams, bed_top: float) -> list[tuple[float, float]]:
    """z intervals (m) sampled for the solid fraction: the bed from the orifice plate to its settled
    top, less the mixers, all with a margin of SOLID_FRACTION_MARGIN particle diameters. A driven
    slice (dem.drive) has no plate and no top in its flow: the whole periodic length."""
    if params.packed:
        return [(0.0, params.length)]
    margin = SOLID_FRACTION_MARGIN * params.diameter
    start, stop = params.orifice_height + margin, bed_top - margin
    intervals = []
    for bottom, top in sorted((m.z_bottom, m.z_top) for m in params.mixers):
        if min(stop, bottom - margin) > start:
            intervals.append((start, min(stop, bottom - margin)))
        start = max(start, top + margin)
    if stop > start:
        intervals.append((start, stop))
    return intervals


def _profile_edges(params: DemParams) -> np.ndarray:
    """Radii (m) of the profile's annuli: PROFILE_BIN diameters wide counted inwards from the wall, so
    that R - d (near-wall band) and R - 2 d (bulk) are edges; the innermost bin may be narrower."""
    step, R = PROFILE_BIN * params.diameter, params.tube_radius
    edges = R - step * np.arange(math.ceil(R / step - 1e-9), -1, -1)
    edges[edges < 1e-9 * R] = 0.0
    return np.unique(edges)


def _annulus_solid(frame: dumps.PositionsFrame, radius: float, edges: np.ndarray, window) -> np.ndarray:
    """Solid volume (m^3) per window interval and annulus (n_intervals, n_annuli) of one frame, from
    the particles whose centres lie in each interval."""
    p = frame.positions[~frame.lost]
    solid = []
    for lo, hi in window:
        inside = (p[:, 2] >= lo) & (p[:, 2] < hi)
        rho = np.hypot(p[inside, 0], p[inside, 1])
        solid.append(np.diff([sphere_in_cylinder(rho, radius, a).sum() for a in edges]))
    return np.array(solid)


def solid_fraction_report(params: DemParams, positions: dumps.PositionsFile, bed_top: float) -> dict | None:
    """Solid fraction of the bed near the wall and in the bulk, settled (first frame), flowing
    (mean over the second half of the frames, as the second-half mass flow) and per frame (so a
    reader can take the mean and spread over the frames it uses: the thermal stage does).

    Estimator: in coaxial annuli over the sample window (:func:`_sample_window`), the volume of the
    particles (exact sphere-cylinder intersections, so a sphere straddling an edge is shared) over
    the annulus volume. Particles count by centre height: at the window's ends as many spheres stick
    out as stick in, on average. Near-wall band: the outer particle diameter, R - d < rho < R;
    bulk: rho < R - 2 d, clear of the wall's first two particle layers. Pooled over the window, and
    per window interval (mixers split the window; one that throttles the flow leaves the bed below
    it loose). None without a window.
    """
    window = _sample_window(params, bed_top)
    if not window:
        return None
    edges = _profile_edges(params)
    heights = np.array([hi - lo for lo, hi in window])
    shells = np.pi * np.diff(edges**2)[None, :] * heights[:, None]  # (n_intervals, n_annuli) m^3
    half = positions.n_frames // 2
    solid = np.array([_annulus_solid(f, params.radius, edges, window) for f in positions.frames()])  # (frames, intervals, annuli)
    settled, flowing = solid[0], solid[half:].mean(axis=0)
    d, R = params.diameter, params.tube_radius
    tol = 1e-9 * R
    wall, bulk = edges[:-1] >= R - d - tol, edges[1:] <= R - 2.0 * d + tol

    def regions(solid: np.ndarray, volume: np.ndarray) -> dict:
        return {
            name: float(solid[mask].sum() / volume[mask].sum()) if mask.any() else None
            for name, mask in (("bulk", bulk), ("near_wall", wall))
        }

    per_frame = [regions(frame.sum(axis=0), shells.sum(axis=0)) for frame in solid]

    return {
        "estimator": (
            "particle volume (exact sphere-cylinder intersections) in coaxial annuli over the sample window, "
            "divided by the annulus volume; particles counted by centre height"
        ),
        "z_window_m": [list(interval) for interval in window],
        "near_wall_band_m": [R - d, R],
        "bulk_radius_m": max(0.0, R - 2.0 * d),
        "settled": regions(settled.sum(axis=0), shells.sum(axis=0)),
        "flowing": {**regions(flowing.sum(axis=0), shells.sum(axis=0)), "frames": [half, positions.n_frames - 1]},
        "per_frame": {name: [value[name] for value in per_frame] for name in ("bulk", "near_wall")},
        "by_interval": [
            {"z_m": list(z), "settled": regions(settled[k], shells[k]), "flowing": regions(flowing[k], shells[k])}
            for k, z in enumerate(window)
        ],
        "profile": {
            "r_edges_m": edges.tolist(),
            "settled": (settled.sum(axis=0) / shells.sum(axis=0)).tolist(),
            "flowing": (flowing.sum(axis=0) / shells.sum(axis=0)).tolist(),
        },
    }


def measured_solid_fraction(summary: dict, region: str, source: str) -> float:
    """The flowing bed's solid fraction in ``region`` ("bulk" or "near_wall") of a DEM run summary
    (:func:`solid_fraction_report`, ``solid_fraction.flowing``); ``source`` names the summary in
    errors (a run without a sample window has none)."""
    value = ((summary.get("solid_fraction") or {}).get("flowing") or {}).get(region)
    if not isinstance(value, (int, float)):
        raise DPHTError(
            f"{source}: the DEM run measured no {region} solid fraction (solid_fraction.flowing.{region}; "
            "a bed too shallow for the sample window, or a summary older than report format "
            f"{FORMAT!r}); give thermal.solid_fraction.{region} as a number"
        )
    return float(value)


def solid_fraction_over(summary: dict, frames) -> dict:
    """Mean and standard deviation of the per-frame solid fractions of a DEM run summary over the
    positions-file frames ``frames``, per region; {} for a summary without them."""
    per_frame = (summary.get("solid_fraction") or {}).get("per_frame") or {}
    out = {}
    for region, series in per_frame.items():
        values = np.array([series[k] for k in frames], dtype=float)
        if values.size and np.all(np.isfinite(values)):
            out[region] = {"mean": float(values.mean()), "std": float(values.std())}
    return out


def _net_crossings(first: dumps.PositionsFrame, last: dumps.PositionsFrame, level: float, length: float) -> int:
    """Net number of downward passages through the plane z = level (mod the periodic length) between
    two frames, over the particles present in both: from the unwrapped heights z + iz L."""
    both = ~(first.lost | last.lost)
    above = [np.floor((f.positions[both, 2] + f.image[both, 2] * length - level) / length) for f in (first, last)]
    return int(np.sum(above[0] - above[1]))


def mixer_crossings(params: DemParams, positions: dumps.PositionsFile) -> list[dict]:
    """Per mixer: net particle passages through the plane of its lowest point over the flow, i.e. how
    many particles got through it (compare with the orifice crossings)."""
    first, last = positions.frame(0), positions.frame(-1)
    return [
        {
            "key": m.key,
            "zone": m.zone,
            "z_range_m": [m.z_bottom, m.z_top],
            "crossings": _net_crossings(first, last, m.z_bottom, params.length),
        }
        for m in params.mixers
    ]

