"""Figures in the style of the DPHT paper, drawn from the stage outputs (no workflow logic here).

Inputs: positions ``results/<variant>/dem/positions.h5`` (frames, streamed one at a time), the wall
table ``geometry/walls.h5`` (:func:`dpht.geometry.walls.load_walls`) and the thermal output
``thermal/thermal.h5`` (format ``dpht-thermal-1``; heat rates are W into the particles, the mean
over the interval from a frame to the next; ``/dem_frame`` names the positions frame of each thermal
frame, every n-th one with ``thermal.frame_stride`` n). Tube axis z through x = y = 0, flow towards
-z, inlet at the top: "distance from the inlet" is ``z_top - z``.

Each function writes a PNG (fixed size and DPI; same inputs, same bytes) and returns its path.
Data figures also write the plotted numbers, SI units, next to it: ``<png stem>.csv``, or
``<stem>.<table>.csv`` when there are two tables (:func:`temperature_profiles`: ``axial``,
``radial``; :func:`compare_variants`: ``<stem>.csv`` and ``<stem>.totals.csv``), and numbers that
are no table in ``<stem>.json`` (:func:`engineering`: the energy balance).

Time windows are fractions of the run (:mod:`dpht.figures.windows`), ``(0.5, 1.0)`` = second half
(the steady state); heat rates are averaged over the intervals lying wholly inside, weighted by
their duration (so the last frame's heat rate, whose interval ends after the stored run, is never
used).
"""

from __future__ import annotations

import csv
import json
import os
import textwrap
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import matplotlib.image
from matplotlib.figure import Figure  # Agg canvas without pyplot's global state: headless

from dpht.closures import heat_capacity, htc
from dpht.closures.gas import ATMOSPHERE
from dpht.thermal.modes import solid_fractions
from dpht.util.h5 import open_checked
from dpht.defaults import default
from dpht.dem import dumps
from dpht.dem.dumps import FORMAT as POSITIONS_FORMAT
from dpht.errors import DPHTError
from dpht.figures.windows import check_window, window_frames, window_intervals
from dpht.thermal import integrate
from dpht.thermal.model import wall_temperatures
from dpht.thermal.modes import LABELS as MODE_LABELS, reader
from dpht.thermal.output import FORMAT as THERMAL_FORMAT
from dpht.geometry.walls import load_walls

KELVIN_OFFSET = heat_capacity.CELSIUS  # K at 0 deg C
DPI = 150
STEADY = tuple(default("figures.steady_window"))  # the config's steady window where a caller gives none

_POSITIONS_DATASETS = ("positions", "ids", "time")
_POSITIONS_ATTRS = ("radius", "box_lo", "box_hi")
_THERMAL_DATASETS = ("ids", "time", "temperature", "wall_heat", "element_heat",
                     "energy/particles", "energy/wall", "energy/recycled")
_THERMAL_ATTRS = ("modes", "wall_modes")
MIN_DIFFERENCE = 1.0  # K: |T_w - T_b| below which the local HTC is not defined (engineering_profile)
_FLUX_LABEL = "heat flux into the particles (W/m$^2$)\n> 0: wall heats particles"
_HEATED_SURFACE, _HEATED_LINE = "mistyrose", "red"  # the heated walls in the cross-sections
_COLOUR_BAR_X = 0.83  # the cross-sections' colour bar starts here, a fraction of the window width


# ---------------------------------------------------------------------------------------- input


@contextmanager
def _open(path, kind: str):
    """Open ``path`` read-only and check its layout; ``kind`` is "positions" or "thermal"."""
    path = Path(path)
    expected = POSITIONS_FORMAT if kind == "positions" else THERMAL_FORMAT
    with open_checked(path, expected, f"a {kind} file") as f:
        if not f.attrs.get("complete", True):  # the thermal stage sets it when it finishes
            raise DPHTError(f"{kind} file {path} is incomplete (its run was interrupted)")
        datasets, attrs = ((_POSITIONS_DATASETS, _POSITIONS_ATTRS) if kind == "positions"
                           else (_THERMAL_DATASETS, _THERMAL_ATTRS))
        missing = [n for n in datasets if n not in f] + [f"attribute {a}" for a in attrs if a not in f.attrs]
        if missing:
            raise DPHTError(f"{kind} file {path}: missing {', '.join(missing)}")
        n_frames = f["time"].shape[0]
        if n_frames < (2 if kind == "thermal" else 1):  # a static bed's positions file holds one
            raise DPHTError(f"{kind} file {path}: needs at least {2 if kind == 'thermal' else 1} frames, has {n_frames}")
        if kind == "thermal":
            _check_thermal_shapes(f, path)
        yield f


def _check_thermal_shapes(f, path: Path) -> None:
    n_frames, n_particles, n_modes = f["time"].shape[0], f["ids"].shape[0], len(_wall_modes(f))
    expected = {"temperature": (n_frames, n_particles), "wall_heat": (n_frames, n_modes),
                "energy/particles": (n_frames,), "energy/wall": (n_frames,), "energy/recycled": (n_frames,)}
    wrong = [f"{name} {f[name].shape} (expected {shape})" for name, shape in expected.items() if f[name].shape != shape]
    element = f["element_heat"].shape
    if len(element) != 3 or element[0] != n_frames or element[2] != n_modes:
        wrong.append(f"element_heat {element} (expected ({n_frames}, M, {n_modes}))")
    if wrong:
        raise DPHTError(f"thermal file {path}: wrong shape of {', '.join(wrong)}")


def _wall_modes(f) -> list[str]:
    """Mode names of the last axis of /wall_heat and /element_heat."""
    return [str(m) for m in np.atleast_1d(f.attrs["wall_modes"]).astype(str)]


def _enabled_modes(f) -> set[str]:
    try:
        return set(json.loads(f.attrs["modes"]))
    except (TypeError, ValueError):
        raise DPHTError(f"{f.filename}: attribute modes must be a JSON list of mode names") from None


def _stream_mean(dataset, intervals: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Duration-weighted mean over ``intervals`` of ``dataset[k]``, one frame in memory at a time."""
    total = np.zeros(dataset.shape[1:])
    for k, w in zip(intervals, weights):
        total += w * dataset[k].astype(np.float64)
    return total / weights.sum()


def _write_csv(path: Path, columns: dict[str, Sequence]) -> Path:
    """Columns of equal length to ``path``; floats written with round-trip precision."""
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(columns)
        for row in zip(*columns.values()):
            writer.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in row])
    return path


def _save(fig: Figure, png) -> Path:
    png = Path(png)
    fig.savefig(png, dpi=DPI, metadata={"Software": None})
    return png


# --------------------------------------------------------------------------------- binning


def _edges(bins, low: float, high: float, default_width: float, name: str) -> np.ndarray:
    """Bin edges: ``bins`` edges as given, or that many equal bins, or ``None`` for bins of about
    ``default_width`` over [low, high]."""
    if bins is None or isinstance(bins, (int, np.integer)):
        if high <= low:
            raise DPHTError(f"{name}: the data span no length to bin ({low:g} m to {high:g} m); give edges")
        n = bins if bins is not None else max(1, int(round((high - low) / default_width)))
        if n < 1:
            raise DPHTError(f"{name} must be a positive number of bins or increasing edges, got {bins!r}")
        return np.linspace(low, high, n + 1)
    edges = np.asarray(bins, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0):
        raise DPHTError(f"{name} must be a positive number of bins or increasing edges [m], got {bins!r}")
    return edges


def _bin_index(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin of each value, the last bin closed on the right; -1 outside the edges."""
    index = np.searchsorted(edges, values, side="right") - 1
    index[values == edges[-1]] = edges.size - 2
    index[(values < edges[0]) | (values > edges[-1])] = -1
    return index


def _bin_sums(index: np.ndarray, n_bins: int, *weights: np.ndarray) -> list[np.ndarray]:
    inside = index >= 0
    return [np.bincount(index[inside], w[inside], minlength=n_bins) for w in weights]


def _divide(numerator: np.ndarray, denominator: np.ndarray) -> np.ndarray:
    """numerator / denominator, NaN where the denominator is zero (an empty bin)."""
    out = np.full(np.broadcast_shapes(numerator.shape, denominator.shape), np.nan)
    np.divide(numerator, denominator, out=out, where=denominator != 0)
    return out


def _flux_profile(thermal_h5, walls_h5, window, bins, zones) -> dict:
    """Window-mean particle-wall heat flux [W/m^2] per mode, binned along the tube (see
    :func:`wall_heat_flux`)."""
    walls = load_walls(walls_h5)
    with _open(thermal_h5, "thermal") as f:
        modes, enabled = _wall_modes(f), _enabled_modes(f)
        if f["element_heat"].shape[1] != len(walls):
            raise DPHTError(f"{thermal_h5}: element_heat has {f['element_heat'].shape[1]} wall elements, "
                            f"the wall table {walls_h5} {len(walls)}")
        k, dt = window_intervals(f["time"][...], window)
        element_heat = _stream_mean(f["element_heat"], k, dt)  # (M, modes) W
        wall_heat = np.average(f["wall_heat"][...][k], axis=0, weights=dt)
    if zones is None:  # Dirichlet zones; adiabatic elements carry exactly zero heat
        zones = [z for i, z in enumerate(walls.zone_names) if np.any(element_heat[walls.zone == i] != 0)]
        if not zones:
            raise DPHTError(f"{thermal_h5}: no wall element exchanges heat in window {tuple(window)}")
    unknown = sorted(set(zones) - set(walls.zone_names))
    if unknown:
        raise DPHTError(f"{walls_h5}: no wall zone(s) {unknown}; the zones are {list(walls.zone_names)}")
    selected = np.zeros(len(walls), bool)
    for zone in zones:
        selected |= walls.zone_mask(zone)

    z_top = walls.vertices[..., 2].max()  # the inlet
    distance = z_top - walls.centroid[selected, 2]
    vertex_distance = z_top - walls.vertices[selected][..., 2]
    extent = np.median(np.ptp(vertex_distance, axis=1))
    low, high = vertex_distance.min(), vertex_distance.max()
    edges = _edges(bins, low, high, 4.0 * extent if extent > 0 else high - low, "bins")
    index = _bin_index(distance, edges)
    area = walls.area[selected]
    heat = element_heat[selected]
    area_bin, moment = _bin_sums(index, edges.size - 1, area, area * distance)
    heat_bin = np.column_stack(_bin_sums(index, edges.size - 1, *heat.T))
    return {
        "edges": edges,
        "distance": _divide(moment, area_bin),  # area-weighted mean distance of each bin
        "area": area_bin,
        "heat": heat_bin,  # (bins, modes) W
        "flux": _divide(heat_bin, area_bin[:, None]),
        "modes": modes,
        "enabled": [m for m in modes if m in enabled],
        "wall_heat": wall_heat,  # (modes,) W, all elements
        "walls": walls,
        "selected": selected,  # (M,) bool, the binned elements
        "index": index,  # bin of each selected element
        "inlet": z_top,  # m, z of the top of the walls
    }


def wall_heat_between(thermal_h5, walls_h5, edges, *, window, zones: Sequence[str] | None = None) -> np.ndarray:
    """Window-mean particle-wall heat rate [W, into the particles] of the wall elements whose centroid
    lies between consecutive ``edges`` (increasing distances from the inlet, m); ``window`` and
    ``zones`` as for :func:`wall_heat_flux`."""
    return _flux_profile(thermal_h5, walls_h5, window, edges, zones)["heat"].sum(axis=1)


# --------------------------------------------------------------------------------- figures


def cross_section(positions_h5, thermal_h5, walls_h5, png, *, frame: int = -1, slab: float | None = None,
                  z_scale: float = 1.0, clim: tuple[float, float] | None = None,
                  window_size: tuple[int, int] = (800, 1200), heated_zones: Sequence[str] | None = None) -> Path:
    """Particles with centres in the slab |y| < ``slab`` [m] (default: one particle radius) at
    ``frame``, drawn as sphere sprites of the particle diameter coloured by temperature (deg C),
    with the walls cut by the slab (grey) and their outline in the plane y = 0 (dark grey); viewed
    along +y, z up, parallel projection (DPHT paper, Figs. 12a and 15). The walls of
    ``heated_zones`` (default: the zones the run's ``thermal.walls`` gives a temperature) are drawn
    in red, and a scale bar under the colour bar gives horizontal lengths in mm.

    ``z_scale`` < 1 compresses the vertical direction for long tubes (the sprites keep their
    horizontal size, so they overlap vertically; the time line says so); ``clim`` fixes the colour
    range (deg C) so that several variants can be compared; ``window_size`` is (width, height) in pixels.
    """
    walls = load_walls(walls_h5)
    with _open(positions_h5, "positions") as fp, _open(thermal_h5, "thermal") as ft:
        dem_frames = _check_aligned(positions_h5, fp, thermal_h5, ft)
        n_frames = dem_frames.size
        if not -n_frames <= frame < n_frames:
            raise DPHTError(f"frame {frame} out of range for {n_frames} frames in {thermal_h5}")
        frame %= n_frames
        radius = float(fp.attrs["radius"])
        x = fp["positions"][dem_frames[frame]].astype(np.float64)
        temperature = ft["temperature"][frame].astype(np.float64)
        time = float(ft["time"][frame])
        if heated_zones is None:  # files written without the run's config mark none
            conditions = json.loads(ft.attrs.get("spec", "{}")).get("thermal", {}).get("walls", {})
            heated_zones = [z for z, c in conditions.items() if c != "adiabatic" and z in walls.zone_names]
    heated = np.zeros(len(walls), bool)
    for zone in heated_zones:
        heated |= walls.zone_mask(zone)
    slab = radius if slab is None else float(slab)
    if not slab > 0 or not z_scale > 0:
        raise DPHTError(f"slab and z_scale must be positive, got slab={slab!r}, z_scale={z_scale!r}")
    shown = (np.abs(x[:, 1]) < slab) & np.isfinite(temperature)
    if not shown.any():
        raise DPHTError(f"{positions_h5}: no particle within |y| < {slab:g} m at frame {frame}")

    # Off-screen rendering without an X server; VTK reads this when it creates the render window
    # (so it also works if vtk was imported earlier), and a user's own choice is kept.
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    centres = pv.PolyData(x[shown])
    centres["T (°C)"] = temperature[shown] - KELVIN_OFFSET
    m = len(walls)
    faces = np.column_stack([np.full(m, 3), np.arange(3 * m).reshape(m, 3)]).ravel()
    wall_mesh = pv.PolyData(walls.vertices.reshape(-1, 3), faces)
    wall_mesh.cell_data["heated"] = heated.astype(np.uint8)  # carried into the clip and the slice
    lo, hi = walls.vertices.reshape(-1, 3).min(axis=0), walls.vertices.reshape(-1, 3).max(axis=0)
    in_slab = wall_mesh.clip_box(bounds=(lo[0], hi[0], -slab, slab, lo[2], hi[2]), invert=False)
    # The section outline, cut just off y = 0 (mesh seams often lie on it and cut into nothing) and
    # moved halfway to the camera: sphere sprites write depths well in front of their centres (VTK
    # imposters), and would hide an outline lying just in front of the slab.
    distance = 10.0 * np.ptp(np.concatenate([lo, hi]))  # camera to focal point, m
    outline = wall_mesh.slice(normal="y", origin=(0.0, 1e-7 * distance, 0.0))
    outline = outline.translate((0.0, -0.5 * distance, 0.0))
    focus, half_height = _view(lo, hi, z_scale, window_size)

    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.set_background("white")
    plotter.add_mesh(
        centres, scalars="T (°C)", cmap="turbo", clim=clim, render_points_as_spheres=True,
        point_size=max(1.0, radius * window_size[1] / half_height),  # diameter in pixels
        scalar_bar_args={"title": "T (°C)", "vertical": True, "color": "black", "fmt": "%.0f",
                         "position_x": _COLOUR_BAR_X, "position_y": 0.1, "width": 0.07, "height": 0.8},
    )
    for part, (surface, line, width) in ((0, ("lightgrey", "dimgrey", 3)), (1, (_HEATED_SURFACE, _HEATED_LINE, 5))):
        for mesh, style in ((in_slab, {"color": surface}), (outline, {"color": line, "line_width": width, "lighting": False})):
            cells = np.flatnonzero(mesh.cell_data["heated"] == part) if mesh.n_cells else []
            if len(cells):
                plotter.add_mesh(mesh.extract_cells(cells), **style)
    heights = "" if z_scale == 1 else f", heights × {z_scale:g}"  # the scale bar holds across only
    notes = [(f"t = {time:.3g} s{heights}", "black")] + ([("red: heated wall", _HEATED_LINE)] if heated.any() else [])
    for row, (text, colour) in enumerate(notes):
        note = plotter.add_text(text, position=(10, window_size[1] - 40 - 30 * row), font_size=10, color=colour)
        note.prop.background_color, note.prop.background_opacity = "white", 0.8  # legible over a wide tube
    _scale_bar(plotter, focus, half_height, window_size, hi[0] - lo[0], -0.5 * distance, z_scale)
    plotter.set_scale(zscale=z_scale, reset_camera=False, render=False)  # scales about z = 0
    camera = plotter.camera
    camera.focal_point = tuple(focus)
    camera.position = tuple(focus - [0.0, distance, 0.0])
    camera.up = (0.0, 0.0, 1.0)
    camera.parallel_projection = True
    camera.parallel_scale = half_height
    plotter.reset_camera_clipping_range()
    png = Path(png)
    plotter.screenshot(str(png))
    plotter.close()
    return png


def _scale_bar(plotter, focus: np.ndarray, half_height: float, window_size, wall_width: float, y: float,
               z_scale: float) -> None:
    """A horizontal bar of a round length in mm (1, 2 or 5 x 10^n) under the colour bar, no longer
    than half the walls' width or than the colour bar's column, with its length written above it;
    drawn at depth ``y`` (m, in front of the particles) in the parallel view of :func:`_view`."""
    import pyvista as pv

    width_px, height_px = window_size
    per_pixel = 2.0 * half_height / height_px  # m
    left = focus[0] - 0.5 * width_px * per_pixel + _COLOUR_BAR_X * width_px * per_pixel
    longest = min(0.5 * wall_width, (0.97 - _COLOUR_BAR_X) * width_px * per_pixel)
    decade = 10.0 ** np.floor(np.log10(longest))
    length = decade * max(f for f in (1.0, 2.0, 5.0) if f * decade <= longest)
    z = (focus[2] - half_height + 0.04 * height_px * per_pixel) / z_scale  # rendered at z * z_scale
    plotter.add_mesh(pv.Line((left, y, z), (left + length, y, z)), color="black", line_width=4, lighting=False)
    plotter.add_text(f"{length * 1e3:g} mm", position=(_COLOUR_BAR_X * width_px, 0.04 * height_px + 6), font_size=9,
                     color="black")


def _view(lo: np.ndarray, hi: np.ndarray, z_scale: float, window_size) -> tuple[np.ndarray, float]:
    """Focal point and parallel scale (half the visible height, m) that fit the wall bounds, z
    scaled, into the part of the window left of the colour bar."""
    plot_fraction = 0.78  # of the window width; the colour bar takes the rest
    width_px, height_px = window_size
    width, height = hi[0] - lo[0], (hi[2] - lo[2]) * z_scale
    half_height = 0.54 * max(height, width * height_px / (width_px * plot_fraction))
    visible_width = 2.0 * half_height * width_px / height_px
    focus = np.array([0.5 * (lo[0] + hi[0]) + 0.5 * (1.0 - plot_fraction) * visible_width, 0.0,
                      0.5 * (lo[2] + hi[2]) * z_scale])
    return focus, half_height


def _check_aligned(positions_h5, fp, thermal_h5, ft) -> np.ndarray:
    """The positions frame of each thermal frame (``/dem_frame``), checked: the particles must be
    the same, and the frames' times equal."""
    n_frames, n_particles = ft["temperature"].shape
    n_dem = fp["positions"].shape[0]
    if fp["positions"].shape[1] != n_particles or not np.array_equal(fp["ids"][...], ft["ids"][...]):
        raise DPHTError(
            f"{thermal_h5} (temperature {ft['temperature'].shape}) is not aligned with {positions_h5} "
            f"(positions {fp['positions'].shape}): the particle ids must match"
        )
    if "dem_frame" in ft:
        frames = ft["dem_frame"][...]
        if frames.shape != (n_frames,) or frames.dtype.kind not in "iu" or np.any((frames < 0) | (frames >= n_dem)):
            raise DPHTError(f"{thermal_h5}: /dem_frame must give, for each of its {n_frames} frames, "
                            f"a frame of {positions_h5} (0..{n_dem - 1})")
    elif n_frames == n_dem:  # written before /dem_frame was recorded, every positions frame
        frames = np.arange(n_frames)
    else:
        raise DPHTError(
            f"{thermal_h5} has {n_frames} frames, {positions_h5} {n_dem}, and it does not record which "
            "positions frames it used (it was written by an older version): re-run its thermal stage "
            "(snakemake --cores 2 --forcerun thermal)"
        )
    frozen = "frozen_bed" in json.loads(ft.attrs.get("spec", "{}")).get("thermal", {})  # one frame held: its own times
    if not frozen and not np.allclose(fp["time"][...][frames], ft["time"][...], rtol=1e-9, atol=0):
        raise DPHTError(f"{thermal_h5} and {positions_h5} have different times at the same frames")
    return frames


def wall_heat_flux(thermal_h5, walls_h5, png, *, window=STEADY, bins=None,
                   zones: Sequence[str] | None = None) -> Path:
    """Particle-wall heat flux [W/m^2, into the particles] per mode and in total versus distance
    from the inlet [m], averaged over ``window`` (DPHT paper, Fig. 13).

    Element heats are summed per bin of centroid distance from the inlet and divided by the wall
    area of those elements. ``zones``: the wall zones binned, by default every zone exchanging heat
    in the window (the Dirichlet zones: adiabatic elements carry exactly zero heat). ``bins``: edges
    in distance from the inlet [m], a number of equal bins, or ``None`` for bins of about four
    element heights. Writes ``<stem>.csv``: bin edges, area-weighted mean distance, area [m^2],
    heat [W] and flux [W/m^2] per mode and in total.
    """
    profile = _flux_profile(thermal_h5, walls_h5, window, bins, zones)
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.subplots()
    for j, mode in enumerate(profile["modes"]):
        if mode in profile["enabled"]:
            ax.plot(profile["distance"], profile["flux"][:, j], marker=".", label=MODE_LABELS.get(mode, mode))
    total = _divide(profile["heat"].sum(axis=1), profile["area"])
    ax.plot(profile["distance"], total, color="black", marker=".", label="total")
    ax.axhline(0.0, color="grey", lw=0.5)
    ax.set(xlabel="distance from inlet (m)", ylabel=_FLUX_LABEL,
           title=f"particle-wall heat flux, mean over {_window_text(window)} of the run")
    ax.legend(frameon=False)
    fig.tight_layout()

    edges = profile["edges"]
    columns = {"distance_lo_m": edges[:-1], "distance_hi_m": edges[1:],
               "distance_mean_m": profile["distance"], "area_m2": profile["area"]}
    for j, mode in enumerate(profile["modes"]):
        columns[f"heat_{mode}_W"] = profile["heat"][:, j]
    columns["heat_total_W"] = profile["heat"].sum(axis=1)
    for j, mode in enumerate(profile["modes"]):
        columns[f"flux_{mode}_W_m2"] = profile["flux"][:, j]
    columns["flux_total_W_m2"] = total
    png = _save(fig, png)
    _write_csv(png.with_suffix(".csv"), columns)
    return png


def _window_text(window) -> str:
    a, b = check_window(window)
    return f"{a:.0%}–{b:.0%}"


def wall_heat_history(thermal_h5, png) -> Path:
    """Particle-wall heat rate [W, into the particles] per mode and in total versus time, and the
    energy-balance residual dE_particles/dt - Q_wall - dE_recycled/dt - dE_convected/dt [W] on a
    second axis (zero when the thermal stage conserves energy). Heat rates are interval means, drawn as steps.
    Writes ``<stem>.csv`` with one row per interval.
    """
    with _open(thermal_h5, "thermal") as f:
        modes, enabled = _wall_modes(f), _enabled_modes(f)
        time = f["time"][...]
        heat = f["wall_heat"][...][:-1]  # the last frame's interval lies beyond the run
        particles, recycled = f["energy/particles"][...], f["energy/recycled"][...]
        estimate = json.loads(f.attrs["summary"]).get("error_estimate") if "summary" in f.attrs else None
        # files written before particle-gas convection existed have no /energy/convected
        convected = f["energy/convected"][...] if "energy/convected" in f else np.zeros_like(particles)
    dt = np.diff(time)
    if np.any(dt <= 0):
        raise DPHTError(f"{thermal_h5}: frame times must increase")
    total = heat.sum(axis=1)
    residual = (np.diff(particles) - np.diff(recycled) - np.diff(convected)) / dt - total

    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.subplots()
    for j, mode in enumerate(modes):
        if mode in enabled:
            ax.stairs(heat[:, j], time, baseline=None, label=MODE_LABELS.get(mode, mode))
    ax.stairs(total, time, baseline=None, color="black", label="total")
    ax.axhline(0.0, color="grey", lw=0.5)
    ax.set(xlabel="time (s)", ylabel="heat rate into the particles (W)")
    fig.suptitle("particle-wall heat rate")
    if estimate:  # under the title, wrapped to the figure's width
        ax.set_title(textwrap.fill(error_estimate_text(estimate), 105), fontsize="x-small", loc="left")
    twin = ax.twinx()
    twin.stairs(residual, time, baseline=None, color="tab:red", linestyle="--", label="energy-balance residual")
    # Symmetric limits no narrower than 0.1% of the heat rate, so that round-off reads as zero.
    scale = max(1.1 * np.nanmax(np.abs(residual)), 1e-3 * np.nanmax(np.abs(heat)), np.finfo(float).tiny)
    twin.set_ylim(-scale, scale)
    twin.set_ylabel("energy-balance residual (W)", color="tab:red")
    twin.tick_params(axis="y", colors="tab:red")
    handles = ax.get_legend_handles_labels()
    extra = twin.get_legend_handles_labels()
    # Below the axes, where it can cover neither the heat rates nor the residual line.
    fig.legend(handles[0] + extra[0], handles[1] + extra[1], loc="outside lower center", ncols=3, frameon=False,
               fontsize="small")

    columns = {"time_start_s": time[:-1], "time_end_s": time[1:]}
    columns.update({f"heat_{mode}_W": heat[:, j] for j, mode in enumerate(modes)})
    columns.update(heat_total_W=total, residual_W=residual)
    png = _save(fig, png)
    _write_csv(png.with_suffix(".csv"), columns)
    return png


def error_estimate_text(estimate: dict) -> str:
    """One line on the run's numerical error estimate (the thermal summary's ``error_estimate``)."""
    wall = estimate["wall_heat"]
    parts = ", ".join(f"{name.replace('_', ' ')} {100 * v:.2g}%" for name, v in wall["parts"].items() if v)
    cost = estimate.get("cost_fraction")
    return (f"numerical error of the total wall heat: {100 * wall['relative']:.2g}% ({parts or 'no part'}); "
            f"estimated in {estimate['seconds']:.1f} s" + (f" ({100 * cost:.0f}% of the run)" if cost is not None else ""))


def profile_sums(positions_h5, thermal_h5, window=STEADY, axial_bins=None, radial_band=None, radial_bins=None):
    """The sums behind :func:`temperature_profiles` (same arguments and defaults): bin edges in z
    and r (m), the radial band (m), the axial and radial sums (rows: samples, sum of the coordinate,
    sum of T) over the window's frames, and the inlet height (m, top of the domain)."""
    with _open(positions_h5, "positions") as fp, _open(thermal_h5, "thermal") as ft:
        dem_frames = _check_aligned(positions_h5, fp, thermal_h5, ft)
        radius = float(fp.attrs["radius"])
        box_lo, box_hi = np.asarray(fp.attrs["box_lo"], float), np.asarray(fp.attrs["box_hi"], float)
        z_edges = _edges(axial_bins, box_lo[2], box_hi[2], 2.0 * radius, "axial_bins")
        band = _band(radial_band, box_lo[2], box_hi[2])
        r_max = min(-box_lo[0], box_hi[0], -box_lo[1], box_hi[1])
        r_edges = _edges(radial_bins, 0.0, r_max, radius, "radial_bins")
        axial = np.zeros((3, z_edges.size - 1))  # samples, sum z, sum T
        radial = np.zeros((3, r_edges.size - 1))  # samples, sum r, sum T
        for k in window_frames(ft["time"][...], window):
            x = fp["positions"][dem_frames[k]].astype(np.float64)
            temperature = ft["temperature"][k].astype(np.float64)
            alive = np.isfinite(temperature)
            x, temperature = x[alive], temperature[alive]
            axial += _bin_sums(_bin_index(x[:, 2], z_edges), z_edges.size - 1,
                               np.ones_like(temperature), x[:, 2], temperature)
            in_band = (x[:, 2] >= band[0]) & (x[:, 2] <= band[1])
            r = np.hypot(x[in_band, 0], x[in_band, 1])
            radial += _bin_sums(_bin_index(r, r_edges), r_edges.size - 1,
                                np.ones_like(r), r, temperature[in_band])
    if radial[0].sum() == 0:
        raise DPHTError(f"{positions_h5}: no particle in radial_band {tuple(band)} m during the window")
    return z_edges, r_edges, band, axial, radial, box_hi[2]


def temperature_profiles(positions_h5, thermal_h5, png, *, window=STEADY, axial_bins=None,
                         radial_band: tuple[float, float] | None = None, radial_bins=None) -> Path:
    """Mean particle temperature versus distance from the inlet (DPHT paper, Fig. 11) and the radial
    profile in the band ``radial_band`` = (z_low, z_high) [m] near the outlet (Fig. 12b), averaged
    over all particle samples in the frames of ``window``; lost particles (NaN) are left out.

    Defaults: axial bins of one particle diameter over the domain height; radial band the bottom
    tenth of the domain; radial bins of one particle radius out to the smallest half-width of the
    domain. Writes ``<stem>.axial.csv`` and ``<stem>.radial.csv`` (sample counts, sample-mean
    coordinate, mean temperature in K).
    """
    z_edges, r_edges, band, axial, radial, inlet = profile_sums(positions_h5, thermal_h5, window, axial_bins, radial_band,
                                                               radial_bins)
    z_mean, t_axial = _divide(axial[1], axial[0]), _divide(axial[2], axial[0])
    r_mean, t_radial = _divide(radial[1], radial[0]), _divide(radial[2], radial[0])

    fig = Figure(figsize=(9.6, 4.0))
    ax_z, ax_r = fig.subplots(1, 2)
    ax_z.plot(inlet - z_mean, t_axial - KELVIN_OFFSET, marker=".", color="tab:red")
    ax_z.set(xlabel="distance from inlet (m)", ylabel="mean particle temperature (°C)",
             title="(a) mean temperature along the tube")
    ax_r.plot(1e3 * r_mean, t_radial - KELVIN_OFFSET, marker="o", color="tab:red")
    ax_r.set(xlabel="radial position (mm)", ylabel="mean particle temperature (°C)",
             title=f"(b) radial profile, z = {band[0]:.3g}–{band[1]:.3g} m")
    fig.suptitle(f"time-averaged over {_window_text(window)} of the run", fontsize="small")
    fig.tight_layout()

    png = _save(fig, png)
    _write_csv(png.with_suffix(".axial.csv"), {
        "z_lo_m": z_edges[:-1], "z_hi_m": z_edges[1:], "z_mean_m": z_mean,
        "distance_mean_m": inlet - z_mean, "samples": axial[0].astype(int), "temperature_K": t_axial})
    _write_csv(png.with_suffix(".radial.csv"), {
        "r_lo_m": r_edges[:-1], "r_hi_m": r_edges[1:], "r_mean_m": r_mean,
        "samples": radial[0].astype(int), "temperature_K": t_radial})
    return png


def _band(band, z_lo: float, z_hi: float) -> tuple[float, float]:
    """The radial-profile band [m]: as given, or the bottom tenth of the domain."""
    if band is None:
        return z_lo, z_lo + 0.1 * (z_hi - z_lo)
    try:
        low, high = (float(b) for b in band)
    except (TypeError, ValueError):
        raise DPHTError(f"radial_band must be (z_low, z_high) in m, got {band!r}") from None
    if not low < high:
        raise DPHTError(f"radial_band must have z_low < z_high (m), got {band!r}")
    return low, high


def engineering_profile(positions_h5, thermal_h5, walls_h5, *, window=STEADY, bins=None,
                        zones: Sequence[str] | None = None, min_difference: float = MIN_DIFFERENCE) -> dict:
    """The engineering outputs along the tube and the energy balance, over ``window`` (the numbers
    of :func:`engineering`; ``bins`` and ``zones`` as for :func:`wall_heat_flux`, whose bins these are).

    Per bin of distance from the inlet (m):

    - ``flux`` q(z) (W/m², into the particles): the window-mean heat of the bin's wall elements over
      the area ``area`` (m²) of its Dirichlet elements (adiabatic elements carry no heat; with the
      default zones these are all of its elements, so q is :func:`wall_heat_flux`'s total);
    - ``wall_temperature`` T_w(z) (K): area-weighted mean temperature of the bin's Dirichlet
      elements, from the run's ``thermal.walls`` expressions evaluated as the thermal stage does
      (:func:`dpht.thermal.model.wall_temperatures`);
    - ``bed_temperature`` T_b(z) (K): the bed's mixing-cup (bulk) temperature, the temperature of
      the mean specific enthalpy of the particles in the bin weighted by their downward axial mass
      flux, T_b = h^-1(sum_i m v_i h_i / sum_i m v_i). It is the temperature a cup catching the
      bin's flow would mix to, the one whose change times the mass flow is the heat the flow
      carries, so h below is defined with it as for a fluid in a duct (a plain mean would weigh the
      slow, hot particles at the wall as much as the fast core); for a plug flow (equal v_i) it is
      the temperature of the mean enthalpy, for constant c_p the mean temperature. Each interval of
      the window gives one sample of every particle: its position and temperature at the interval's
      start (a row of thermal.h5 holds the state at the start of its interval, after the resets at
      the inlet) and v_i its unwrapped axial displacement over the interval (image flags, or the
      nearest periodic image without them) over the interval's length; samples are weighted by the
      interval's length, so the weights are the downward displacements. NaN where the net flux is
      not downwards;
    - ``mass_flow`` (kg/s): the bin's time-mean axial mass flux sum_i m v_i over the bin's height,
      the mass flow through the bin (the same all along a steady column);
    - ``htc`` h(z) = q / (T_w - T_b) (W/(m² K)), the local wall-to-bed heat transfer coefficient
      over the heated (Dirichlet) length; NaN where |T_w - T_b| < ``min_difference`` (K, where it
      would be a ratio of noise), and where a bin has no Dirichlet element or no flow.

    ``balance`` (W: means over the window's intervals): ``duty_W`` the wall heat rate into the
    particles (/wall_heat); ``rise_W`` = m_dot (h(T_out) - h(T_in)), the bed's enthalpy rise, with
    m_dot the DEM run's measured mass flow (its summary's ``mass_flow_second_half_kg_s``, past the
    start-up), T_in the inlet temperature and T_out the outlet's mixing-cup temperature: that of
    the mean specific enthalpy of the particles leaving through the outlet (crossing the recycled
    boundary downwards) as they leave, h(T_out) = h(T_in) + (enthalpy the thermal stage removed
    resetting them, /energy/recycled) / (their mass): the stored rows hold each interval's start,
    so this bookkeeping is the only exact record of their state at the crossing; ``storage_W`` the
    rate of change of the particles' enthalpy (/energy/particles); ``gas_W`` the heat from the gas
    (/energy/convected, 0 without convection); ``residual_W`` = duty + gas - rise - storage and
    ``residual_relative`` = residual / duty. The same at the window's own mass flow, the leaving
    particles' mass over the window (``*_window``): that residual is the thermal stage's energy
    conservation (round-off); the first adds how far the window's flow is from the DEM's mean.
    """
    if not min_difference > 0:
        raise DPHTError(f"min_difference must be a positive temperature difference (K), got {min_difference!r}")
    profile = _flux_profile(thermal_h5, walls_h5, window, bins, zones)
    walls, selected, index, inlet = profile["walls"], profile["selected"], profile["index"], profile["inlet"]
    edges = profile["edges"]
    n_bins = edges.size - 1
    with _open(positions_h5, "positions") as fp, _open(thermal_h5, "thermal") as ft:
        dem_frames = _check_aligned(positions_h5, fp, thermal_h5, ft)
        spec = _run_spec(ft, thermal_h5)
        moving = [key for key in ("slice", "frozen_bed") if key in spec["thermal"]]
        if moving:
            raise DPHTError(f"{thermal_h5}: the engineering outputs need a bed flowing past fixed walls; this run "
                            f"has thermal.{moving[0]} (a travelling slice's are in the Watkins figures)")
        mass_flow_dem = json.loads(fp.attrs.get("summary", "{}")).get("mass_flow_second_half_kg_s")
        if mass_flow_dem is None:
            raise DPHTError(f"{positions_h5}: its DEM summary has no mass_flow_second_half_kg_s (the measured mass flow)")
        intervals, lengths = window_intervals(ft["time"][...], window)
        span = float(lengths.sum())  # s; the intervals are consecutive
        inlet_temperature = float(ft.attrs["inlet_temperature"])
        particles = spec["particles"]
        mass = particles["density"] * 4.0 / 3.0 * np.pi * (particles["diameter"] / 2.0) ** 3  # kg, as the thermal stage
        temperature = ft["temperature"]
        low = min(inlet_temperature, *(np.nanmin(temperature[k]) for k in intervals))
        high = max(inlet_temperature, *(np.nanmax(temperature[k]) for k in intervals))
        table = heat_capacity.build(heat_capacity.specific_heat(particles["specific_heat"]), low, high)
        box_lo, box_hi = np.asarray(fp.attrs["box_lo"], float), np.asarray(fp.attrs["box_hi"], float)
        # The axis across which the thermal stage resets particles (dpht.thermal.stage.recycle).
        recycled = bool(np.asarray(fp.attrs.get("recycled", np.zeros(3, bool)), bool)[2])
        images = fp["image"] if "image" in fp else None
        flux_sums = np.zeros((2, n_bins))  # sum of m (-dz) (kg m), sum of m (-dz) h (J m)
        leaving = 0  # particles
        for k in intervals:
            a, b = int(dem_frames[k]), int(dem_frames[k + 1])
            x0, x1 = fp["positions"][a].astype(np.float64), fp["positions"][b].astype(np.float64)
            i0, i1 = (images[a], images[b]) if images is not None else (None, None)
            if recycled:
                leaving += int(np.count_nonzero(integrate.wrapped(i0, i1, x0, x1, box_lo, box_hi, 2)))
            down = -dumps.axial_step(x0[:, 2], x1[:, 2], i0, i1, box_hi[2] - box_lo[2])  # m
            state = temperature[k].astype(np.float64)
            alive = np.isfinite(state) & np.isfinite(down)
            flux_sums += _bin_sums(_bin_index(inlet - x0[alive, 2], edges), n_bins, mass * down[alive],
                                   mass * down[alive] * table.enthalpy(state[alive]))
        first, last = intervals[0], intervals[-1] + 1
        energy = {name: (float(ft[f"energy/{name}"][last]) - float(ft[f"energy/{name}"][first])) / span
                  for name in ("particles", "recycled", "convected") if f"energy/{name}" in ft}  # W

    # Along the tube.
    element_temperature = wall_temperatures(walls, spec["thermal"]["walls"])[selected]  # K, NaN: adiabatic
    dirichlet = np.isfinite(element_temperature)
    area = np.where(dirichlet, walls.area[selected], 0.0)
    area_bin, area_temperature = _bin_sums(index, n_bins, area, area * np.nan_to_num(element_temperature))
    heat = profile["heat"].sum(axis=1)
    flux = _divide(heat, area_bin)
    wall_temperature = _divide(area_temperature, area_bin)
    flowing = flux_sums[0] > 0
    bed_temperature = np.full(n_bins, np.nan)
    bed_temperature[flowing] = table.temperature(flux_sums[1][flowing] / flux_sums[0][flowing])
    difference = wall_temperature - bed_temperature
    htc = np.full(n_bins, np.nan)
    defined = np.abs(difference) >= min_difference  # False where NaN
    htc[defined] = flux[defined] / difference[defined]

    # Energy balance over the window.
    rise_per_kg = -energy["recycled"] * span / (mass * leaving) if leaving else np.nan  # J/kg, h(T_out) - h(T_in)
    outlet = float(table.temperature(table.enthalpy(inlet_temperature) + rise_per_kg)) if leaving else np.nan
    duty = float(profile["wall_heat"].sum())
    storage, gas = energy["particles"], energy.get("convected", 0.0)
    balance = {"window_s": span, "duty_W": duty, "gas_W": gas, "storage_W": storage,
               "inlet_temperature_K": inlet_temperature, "outlet_temperature_K": outlet, "outlet_particles": leaving}
    for suffix, mass_flow in (("", float(mass_flow_dem)), ("_window", mass * leaving / span)):
        rise = mass_flow * rise_per_kg
        residual = duty + gas - rise - storage
        balance.update({f"mass_flow{suffix}_kg_s": mass_flow, f"rise{suffix}_W": rise, f"residual{suffix}_W": residual,
                        f"residual{suffix}_relative": residual / duty if duty else np.nan})
    return {"edges": edges, "distance": profile["distance"], "area": area_bin, "heat": heat, "flux": flux,
            "wall_temperature": wall_temperature, "bed_temperature": bed_temperature,
            "mass_flow": _divide(flux_sums[0], span * np.diff(edges)), "htc": htc, "balance": balance}


def _run_spec(f, path) -> dict:
    """The config sections the thermal run was made with (attribute ``spec``)."""
    try:
        return json.loads(f.attrs["spec"])
    except KeyError:
        raise DPHTError(f"thermal file {path} does not record its run's config (attribute spec): it was written by "
                        "an older version; re-run its thermal stage (snakemake --cores 2 --forcerun thermal)") from None


def engineering(positions_h5, thermal_h5, walls_h5, png, *, window=STEADY, bins=None,
                zones: Sequence[str] | None = None, min_difference: float = MIN_DIFFERENCE) -> Path:
    """What users of moving-bed heat exchangers read next to the figures, over ``window``: (a) the
    wall temperature and the bed's mixing-cup temperature along the tube, (b) the local wall-to-bed
    heat transfer coefficient h(z), (c) the energy balance: wall duty against the bed's enthalpy
    rise at the DEM's mass flow and the bed's storage (definitions: :func:`engineering_profile`,
    whose arguments these are).

    Writes ``<stem>.csv`` (one row per bin: distance_lo_m, distance_hi_m, distance_mean_m,
    dirichlet_area_m2, heat_W, flux_W_m2, wall_temperature_K, bed_temperature_K, mass_flow_kg_s,
    htc_W_m2K) and ``<stem>.json`` (the energy balance, :func:`engineering_profile`'s ``balance``).
    """
    p = engineering_profile(positions_h5, thermal_h5, walls_h5, window=window, bins=bins, zones=zones,
                            min_difference=min_difference)
    balance = p["balance"]
    fig = Figure(figsize=(12.8, 4.4))
    ax_t, ax_h, ax_e = fig.subplots(1, 3, width_ratios=(1.2, 1.2, 1.0))
    # Two scales: the bed may warm by a few K under a wall hundreds of K hotter.
    ax_t.plot(p["distance"], p["wall_temperature"] - KELVIN_OFFSET, marker=".", color="tab:red", label="wall $T_w$ (left)")
    ax_t.set(xlabel="distance from inlet (m)", title="(a) wall and bed temperature")
    ax_t.set_ylabel("wall temperature (°C)", color="tab:red")
    low, high = np.nanmin(p["wall_temperature"]), np.nanmax(p["wall_temperature"])
    pad = max(0.1 * (high - low), 1.0)  # K; a uniform wall is a flat line, not round-off magnified
    ax_t.set_ylim(low - pad - KELVIN_OFFSET, high + pad - KELVIN_OFFSET)
    ax_b = ax_t.twinx()
    ax_b.plot(p["distance"], p["bed_temperature"] - KELVIN_OFFSET, marker=".", color="tab:blue",
              label="bed, mixing cup $T_b$")
    ax_b.axhline(balance["inlet_temperature_K"] - KELVIN_OFFSET, color="grey", ls="--", lw=1, label="inlet")
    ax_b.axhline(balance["outlet_temperature_K"] - KELVIN_OFFSET, color="tab:blue", ls=":", lw=1,
                 label="outlet, mixing cup")
    ax_b.set_ylabel("bed temperature (°C)", color="tab:blue")
    ax_b.margins(y=0.35)  # room for the legend below the bed's curve
    handles, labels = (a + b for a, b in zip(ax_t.get_legend_handles_labels(), ax_b.get_legend_handles_labels()))
    ax_b.legend(handles, labels, frameon=False, fontsize="small", loc="lower right")
    ax_h.plot(p["distance"], p["htc"], marker="o", color="black")
    ax_h.set(xlabel="distance from inlet (m)", ylabel="h = q / ($T_w$ − $T_b$)  (W/(m$^2$ K))",
             title="(b) local wall-to-bed heat transfer coefficient")
    terms = [("wall\nduty", balance["duty_W"], "tab:red")]
    if balance["gas_W"]:
        terms.append(("from gas", balance["gas_W"], "tab:orange"))
    terms += [("bed rise\n$\\dot m\\,\\Delta h$", balance["rise_W"], "tab:blue"),
              ("storage\ndE/dt", balance["storage_W"], "tab:green"), ("residual", balance["residual_W"], "grey")]
    names, values, colours = zip(*terms)
    bars = ax_e.bar(names, values, color=colours)
    ax_e.bar_label(bars, labels=[f"{v:.3g} W" for v in values], fontsize="small")
    ax_e.axhline(0.0, color="grey", lw=0.5)
    ax_e.margins(y=0.2)
    ax_e.tick_params(axis="x", labelsize="small")
    ax_e.set(ylabel="heat rate (W)", title="(c) energy balance")
    ax_e.set_xlabel(f"residual = duty − rise − storage: {100 * balance['residual_relative']:+.2g}% of the duty\n"
                    f"at $\\dot m$ = {1e3 * balance['mass_flow_kg_s']:.2f} g/s (DEM); "
                    f"{100 * balance['residual_window_relative']:+.1g}% at the window's {1e3 * balance['mass_flow_window_kg_s']:.2f} g/s",
                    fontsize="x-small")
    fig.suptitle(f"mean over {_window_text(window)} of the run", fontsize="small")
    fig.tight_layout()

    png = _save(fig, png)
    edges = p["edges"]
    _write_csv(png.with_suffix(".csv"), {
        "distance_lo_m": edges[:-1], "distance_hi_m": edges[1:], "distance_mean_m": p["distance"],
        "dirichlet_area_m2": p["area"], "heat_W": p["heat"], "flux_W_m2": p["flux"],
        "wall_temperature_K": p["wall_temperature"], "bed_temperature_K": p["bed_temperature"],
        "mass_flow_kg_s": p["mass_flow"], "htc_W_m2K": p["htc"]})
    png.with_suffix(".json").write_text(json.dumps(balance, indent=1, sort_keys=True) + "\n")
    return png


def htc_curves(png, *, radius: float, k_solid, solid_fraction, gas="air", pressure=ATMOSPHERE, accommodation=None,
               temperatures: Sequence[float] = (300, 500, 700, 900, 1100, 1273)) -> Path:
    """PFP conductance [W/K] (the paper's "heat transfer coefficient" of a pair) versus centre
    distance d_ij/R (DPHT paper, Fig. 4) and PFW versus centre-to-wall distance d_iw/R (Fig. 6) at each of ``temperatures`` [K], over the
    same gaps (d_ij from 1.9R, slight overlap, to 3.5R; d_iw half that), from :mod:`dpht.closures.htc`.
    ``k_solid`` is a number or a conductivity table (then each curve uses k_s at its temperature);
    ``solid_fraction`` a number or ``{bulk, near_wall}`` (PFP uses bulk, PFW near_wall); ``gas``,
    the gas ``pressure`` [Pa] and ``accommodation`` as for :func:`dpht.closures.htc.pfp`.
    Writes ``<stem>.csv`` (kind, temperature_K, distance_over_R, htc_W_K).
    """
    temperatures = np.asarray(temperatures, dtype=float)
    if temperatures.ndim != 1 or temperatures.size == 0:
        raise DPHTError(f"temperatures must be a non-empty list of K, got {temperatures!r}")
    scaled = {"pfp": np.linspace(1.9, 3.5, 161), "pfw": np.linspace(0.95, 1.75, 161)}
    functions = {"pfp": htc.pfp, "pfw": htc.pfw}
    phi = solid_fractions(solid_fraction)
    phi_of = {kind: phi[reader("htc", kind).region] for kind in scaled}
    fig = Figure(figsize=(9.6, 4.0))
    axes = dict(zip(scaled, fig.subplots(1, 2)))
    rows = {"kind": [], "temperature_K": [], "distance_over_R": [], "htc_W_K": []}
    for kind, d_over_r in scaled.items():
        for temperature in temperatures:
            k = float(htc.solid_conductivity(k_solid, temperature))
            values = functions[kind](d_over_r * radius, temperature, radius=radius, k_solid=k,
                                     solid_fraction=phi_of[kind], gas=gas, pressure=pressure,
                                     accommodation=accommodation)  # fmt: skip
            axes[kind].plot(d_over_r, values, label=f"{temperature:g} K")
            rows["kind"] += [kind] * d_over_r.size
            rows["temperature_K"] += [float(temperature)] * d_over_r.size
            rows["distance_over_R"] += d_over_r.tolist()
            rows["htc_W_K"] += values.tolist()
    # A conductance (heat rate per kelvin of one particle pair), not a coefficient per area.
    axes["pfp"].set(xlabel="centre distance $d_{ij}/R$", ylabel="conductance $H_{ij}$ (W/K)",
                    title="(a) particle-fluid-particle (Fig. 4)")
    axes["pfw"].set(xlabel="centre-to-wall distance $d_{iw}/R$", ylabel="conductance $H_{iw}$ (W/K)",
                    title="(b) particle-fluid-wall (Fig. 6)")
    axes["pfp"].legend(frameon=False, fontsize="small")
    k_text = "table" if isinstance(k_solid, Mapping) else f"{k_solid:g} W/(m K)"
    phi_text = f"{phi['bulk']:g}" if phi["bulk"] == phi["near_wall"] else f"{phi['bulk']:g} (PFP), {phi['near_wall']:g} (PFW)"
    p_text = pressure if isinstance(pressure, str) else f"{pressure:g} Pa"
    fig.suptitle(f"R = {radius:g} m, $k_s$ = {k_text}, $\\alpha_s$ = {phi_text}, "
                 f"gas: {gas if isinstance(gas, str) else 'user table'} at {p_text}", fontsize="small")
    fig.tight_layout()
    png = _save(fig, png)
    _write_csv(png.with_suffix(".csv"), rows)
    return png


def compare_variants(variants: Sequence[tuple[str, str | Path, str | Path]], png, *, window=STEADY,
                     bins=None, zones: Sequence[str] | None = None,
                     spans: Mapping[str, Sequence[tuple[float, float]]] | None = None) -> Path:
    """Total particle-wall heat flux [W/m^2, into the particles] along the tube for each
    ``(name, thermal_h5, walls_h5)`` variant (DPHT paper, Fig. 16) and a bar of each variant's
    window-mean total wall heat rate [W], labelled relative to the first variant. ``window``,
    ``bins`` and ``zones`` as for :func:`wall_heat_flux`, applied to every variant; ``spans``:
    per variant name, ranges of distance from the inlet [m] (its mixers) shaded in its colour.
    Writes ``<stem>.csv`` (binned flux per variant) and ``<stem>.totals.csv``.
    """
    if not variants or any(len(v) != 3 for v in variants):
        raise DPHTError(f"variants must be a non-empty list of (name, thermal_h5, walls_h5), got {variants!r}")
    names = [str(v[0]) for v in variants]
    if len(set(names)) != len(names):
        raise DPHTError(f"variant names must be distinct, got {names}")
    profiles = [_flux_profile(thermal, walls, window, bins, zones) for _, thermal, walls in variants]
    totals = np.array([p["wall_heat"].sum() for p in profiles])

    fig = Figure(figsize=(9.6, 4.0))
    ax_flux, ax_bar = fig.subplots(1, 2, width_ratios=(2, 1))
    rows = {"variant": [], "distance_lo_m": [], "distance_hi_m": [], "distance_mean_m": [], "area_m2": [],
            "flux_total_W_m2": []}
    for k, (name, p) in enumerate(zip(names, profiles)):
        flux = _divide(p["heat"].sum(axis=1), p["area"])
        ax_flux.plot(p["distance"], flux, marker=".", label=name, color=f"C{k}")
        for j, (lo, hi) in enumerate((spans or {}).get(name, ())):  # one legend entry for a variant's mixers
            ax_flux.axvspan(lo, hi, color=f"C{k}", alpha=0.12, lw=0, label=f"{name}: mixers" if j == 0 else None)
        rows["variant"] += [name] * flux.size
        rows["distance_lo_m"] += p["edges"][:-1].tolist()
        rows["distance_hi_m"] += p["edges"][1:].tolist()
        rows["distance_mean_m"] += p["distance"].tolist()
        rows["area_m2"] += p["area"].tolist()
        rows["flux_total_W_m2"] += flux.tolist()
    ax_flux.axhline(0.0, color="grey", lw=0.5)
    ax_flux.set(xlabel="distance from inlet (m)", ylabel=_FLUX_LABEL, title="(a) particle-wall heat flux")
    ax_flux.legend(frameon=False)
    relative = totals / totals[0] - 1.0 if totals[0] != 0 else np.full(totals.size, np.nan)
    bars = ax_bar.bar(names, totals, color=[f"C{i}" for i in range(len(names))])
    labels = [f"{t:.3g} W" + ("" if i == 0 else f"\n{r:+.1%}") for i, (t, r) in enumerate(zip(totals, relative))]
    ax_bar.bar_label(bars, labels=labels, fontsize="small")
    ax_bar.axhline(0.0, color="grey", lw=0.5)
    ax_bar.set(ylabel="total heat rate into the particles (W)", title="(b) total wall heat")
    ax_bar.margins(y=0.2)
    fig.suptitle(f"mean over {_window_text(window)} of each run", fontsize="small")
    fig.tight_layout()
    png = _save(fig, png)
    _write_csv(png.with_suffix(".csv"), rows)
    _write_csv(png.with_suffix(".totals.csv"),
               {"variant": names, "heat_total_W": totals, "relative_to_first": relative})
    return png


def compare_cross_sections(variants: Sequence[tuple[str, str | Path, str | Path, str | Path]], png, *,
                           frame: int = -1, window_size: tuple[int, int] = (500, 1200)) -> Path:
    """Cross-sections of several ``(name, positions_h5, thermal_h5, walls_h5)`` variants side by
    side on one colour scale (DPHT paper, Fig. 15), each rendered by :func:`cross_section`.

    The single renders are kept as ``<stem>.<name>.png``.
    """
    if not variants or any(len(v) != 4 for v in variants):
        raise DPHTError(f"variants must be a non-empty list of (name, positions_h5, thermal_h5, walls_h5), got {variants!r}")
    png = Path(png)
    low, high = np.inf, -np.inf
    for _, _, thermal, _ in variants:
        with _open(thermal, "thermal") as f:
            T = f["temperature"][frame]
        low, high = min(low, np.nanmin(T)), max(high, np.nanmax(T))
    clim = (low - KELVIN_OFFSET, high - KELVIN_OFFSET)
    singles = [
        cross_section(positions, thermal, walls, png.with_name(f"{png.stem}.{name}.png"), frame=frame, clim=clim,
                      window_size=window_size)
        for name, positions, thermal, walls in variants
    ]
    fig = Figure(figsize=(2.4 * len(singles), 2.4 * window_size[1] / window_size[0]))
    for k, ((name, *_), single) in enumerate(zip(variants, singles)):
        ax = fig.add_subplot(1, len(singles), k + 1)
        ax.imshow(matplotlib.image.imread(single))
        ax.set_title(name)
        ax.axis("off")
    fig.tight_layout()
    return _save(fig, png)
