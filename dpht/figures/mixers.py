"""The mixer study (DPHT paper, Section 6): Fig. 14 (the designs, and a close-up of the radial mixer),
Fig. 15 (steady cross-sections on one temperature scale, :func:`dpht.figures.scene.compare_cross_sections`),
Fig. 16 (particle-wall heat flux along the tube, :func:`dpht.figures.scene.compare_variants`) and the
table of every variant against the reference (the first variant, the plain tube).

Table columns (SI units; "relative" = value / reference's - 1), from the runs' own outputs:

- ``wall_heat_W``: particle-wall heat rate into the particles (negative: the wall cools them), the
  duration-weighted mean over the steady window, every wall zone (adiabatic ones carry none);
- ``outlet_temperature_K``: the mixing-cup temperature of the particles leaving through the outlet
  during the window (:mod:`dpht.figures.outlet`), and ``outlet_change_K``, its difference to the
  inlet temperature;
- ``mass_flow_kg_s``: the DEM run's mass flow over the second half of its flow (its summary), and
  ``drive_g``: the net body acceleration of a driven run (dem.drive) in units of gravity;
- ``energy_balance``: mass flow x (h(outlet) - h(inlet)) / wall heat rate, 1 in a steady state;
- ``wall_heat_drift``: how far the window is from steady: the change of the wall heat rate across
  the window (a straight line fitted to it) over its mean, 0 in a steady state;
- ``wall_heat_above_W``, ``wall_heat_alongside_W``, ``wall_heat_below_W``: the wall heat of the wall
  above every variant's mixers, alongside them (from the highest mixer's top to the lowest one's
  bottom) and below them, the same three stretches of wall in every variant (NaN without mixers):
  what a mixer changes downstream apart from the wall it covers;
- ``paper_wall_heat_relative``: the paper's relative wall heat for the variant, where given.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import matplotlib.image
import numpy as np
from matplotlib.figure import Figure

from dpht.errors import DPHTError
from dpht.figures import outlet
from dpht.figures.scene import DPI, KELVIN_OFFSET, compare_cross_sections, compare_variants, wall_heat_between
from dpht.figures.windows import window_frames, window_intervals
from dpht.geometry.walls import load_walls

COLUMNS = ("variant", "wall_heat_W", "wall_heat_relative", "paper_wall_heat_relative", "outlet_temperature_K",
           "outlet_change_K", "outlet_change_relative", "outlet_particles", "mass_flow_kg_s", "mass_flow_relative",
           "drive_g", "energy_balance", "wall_heat_drift", "wall_heat_above_W", "wall_heat_above_relative",
           "wall_heat_alongside_W", "wall_heat_below_W", "wall_heat_below_relative", "particles",
           "dem_wall_time_s", "thermal_wall_time_s")


def fig14(variants, png, *, close_up: str | None = None, zone: str = "mixer", panel_size=(360, 560)) -> Path:
    """The designs side by side, the tube's near half removed (``variants``: ``(name, walls_h5)``), and,
    with ``close_up`` (a variant's name), that variant's ``zone`` framed on its own (DPHT paper, Fig. 14);
    each panel is rendered by :func:`dpht.geometry.picture` and kept as ``<stem>.<name>.png``."""
    from dpht.geometry import picture

    png = Path(png)
    panels = [(name, picture(Path(walls).parent, png.with_name(f"{png.stem}.{name}.png"), window_size=panel_size))
              for name, walls in variants]  # fmt: skip
    if close_up is not None:
        walls = dict(variants)[close_up]
        panels.append((f"{close_up}: close-up",
                       picture(Path(walls).parent, png.with_name(f"{png.stem}.{close_up}.close_up.png"),
                               window_size=(panel_size[1], panel_size[1]), focus=zone)))
    widths = [matplotlib.image.imread(file).shape[1] for _, file in panels]
    fig = Figure(figsize=(2.2 * sum(widths) / panel_size[0], 2.2 * panel_size[1] / panel_size[0]))
    axes = fig.subplots(1, len(panels), width_ratios=widths)
    for ax, (name, file) in zip(np.atleast_1d(axes), panels):
        ax.imshow(matplotlib.image.imread(file))
        ax.set_title(name, fontsize="small")
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(png, dpi=DPI, metadata={"Software": None})
    return png


def _drift(time: np.ndarray, rate: np.ndarray, k: np.ndarray, dt: np.ndarray) -> float:
    """Change of ``rate`` across the window's intervals ``k`` (a least-squares line through the
    interval rates at their midpoints) over its duration-weighted mean; NaN for a single interval."""
    if k.size < 2:
        return math.nan
    mid = time[k] + 0.5 * dt
    slope = np.polyfit(mid, rate, 1)[0]
    mean = float((rate * dt).sum() / dt.sum())
    return float(slope * (time[k[-1] + 1] - time[k[0]]) / mean) if mean != 0 else math.nan


def alongside_mixers(spans: dict) -> tuple[float, float] | None:
    """The wall alongside the mixers of all variants: (highest top, lowest bottom) as distances from the
    inlet [m], from ``spans`` (per variant, its mixers' [lo, hi] distances); None without mixers."""
    ranges = [r for v in spans.values() for r in v]
    return (min(lo for lo, _ in ranges), max(hi for _, hi in ranges)) if ranges else None


def variant_row(name: str, files: dict, *, window, specific_heat, inlet_temperature: float, zones,
                alongside: tuple[float, float] | None) -> dict:
    """One variant's numbers (module docstring) from its ``files``: ``thermal``, ``positions``, ``dem``
    (the DEM summary), ``thermal_summary`` and ``walls``; ``zones``, the heated wall zones, and
    ``alongside`` (:func:`alongside_mixers`) for the wall heat above, alongside and below the mixers."""
    import h5py

    with h5py.File(files["thermal"], "r") as f:
        time = f["time"][...]
        k, dt = window_intervals(time, window)
        rate = f["wall_heat"][...][k].sum(axis=1)
        heat = float((rate * dt).sum() / dt.sum())
    parts = [math.nan] * 3
    if alongside is not None:
        length = float(np.ptp(load_walls(files["walls"]).vertices[..., 2]))  # beyond the lowest mixer: the rest
        parts = wall_heat_between(files["thermal"], files["walls"], [0.0, *alongside, alongside[1] + length],
                                  window=window, zones=zones).tolist()  # fmt: skip
    leaving = outlet.leaving_temperatures(files["thermal"], files["positions"], window_frames(time, window))
    cup = outlet.mixing_cup(leaving, specific_heat) if leaving.size else math.nan
    dem = json.loads(Path(files["dem"]).read_text())
    mass_flow = float(dem["mass_flow_second_half_kg_s"])
    drive = dem.get("drive") or {}
    balance = math.nan
    if leaving.size and heat != 0:
        balance = mass_flow * outlet.enthalpy_difference(cup, inlet_temperature, specific_heat) / heat
    thermal_summary = json.loads(Path(files["thermal_summary"]).read_text())
    return {
        "variant": name,
        "wall_heat_W": heat,
        "outlet_temperature_K": cup,
        "outlet_change_K": cup - inlet_temperature,
        "outlet_particles": int(leaving.size),
        "mass_flow_kg_s": mass_flow,
        "drive_g": drive.get("acceleration_over_gravity", math.nan),
        "energy_balance": balance,
        "wall_heat_drift": _drift(time, rate, k, dt),
        "wall_heat_above_W": parts[0],
        "wall_heat_alongside_W": parts[1],
        "wall_heat_below_W": parts[2],
        "particles": int(dem["particles"]),
        "dem_wall_time_s": float(sum(dem["wall_time_s"].values())),
        "thermal_wall_time_s": float(thermal_summary["seconds"]),
    }


def relative_to_first(rows: list[dict], paper: dict) -> list[dict]:
    """``rows`` with the relative columns against the first row, and the paper's relative wall heat."""
    ref = rows[0]

    def relative(value: float, reference: float) -> float:
        return value / reference - 1.0 if reference != 0 and math.isfinite(reference) else math.nan

    return [{**row,
             "wall_heat_relative": relative(row["wall_heat_W"], ref["wall_heat_W"]),
             "outlet_change_relative": relative(row["outlet_change_K"], ref["outlet_change_K"]),
             "mass_flow_relative": relative(row["mass_flow_kg_s"], ref["mass_flow_kg_s"]),
             "wall_heat_above_relative": relative(row["wall_heat_above_W"], ref["wall_heat_above_W"]),
             "wall_heat_below_relative": relative(row["wall_heat_below_W"], ref["wall_heat_below_W"]),
             "paper_wall_heat_relative": paper.get(row["variant"], 0.0 if row is ref else math.nan)}
            for row in rows]  # fmt: skip


def write_table(rows: list[dict], csv_path, md_path) -> None:
    """The table as CSV (COLUMNS, round-trip floats) and as Markdown (percentages, deg C)."""
    with open(csv_path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(COLUMNS)
        for row in rows:
            writer.writerow([repr(float(row[c])) if isinstance(row[c], float) else row[c] for c in COLUMNS])

    def percent(value: float) -> str:
        return f"{100 * value:+.1f}%" if math.isfinite(value) else ""

    lines = ["| variant | wall heat (W) | relative | paper | above mixers | below mixers | outlet (°C) | "
             "outlet change (K) | relative | mass flow (g/s) | relative | drive (g) | energy balance | drift |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        lines.append(
            f"| {row['variant']} | {row['wall_heat_W']:.4g} | {percent(row['wall_heat_relative'])} | "
            f"{percent(row['paper_wall_heat_relative'])} | {percent(row['wall_heat_above_relative'])} | "
            f"{percent(row['wall_heat_below_relative'])} | {row['outlet_temperature_K'] - KELVIN_OFFSET:.1f} | "
            f"{row['outlet_change_K']:.2f} | {percent(row['outlet_change_relative'])} | "
            f"{1e3 * row['mass_flow_kg_s']:.4g} | {percent(row['mass_flow_relative'])} | {row['drive_g']:.2f} | "
            f"{row['energy_balance']:.3f} | {percent(row['wall_heat_drift'])} |")
    Path(md_path).write_text("\n".join(lines) + "\n")


def study(spec: dict, inputs: dict, outputs: dict, log=print) -> dict:
    """Figs. 14-16 and the table of the mixer study. ``spec``: ``variants`` (in order, the reference
    first), ``paper`` (variant -> relative wall heat), ``window``, ``heated_zones``, ``specific_heat``,
    ``inlet_temperature``, ``close_up`` (a variant with a radial mixer, or None), ``spans`` (per variant,
    its mixers as ranges of distance from the inlet, m); ``inputs``:
    ``<file>_<variant>`` for walls, positions, thermal, dem, thermal_summary (dpht.plan.Plan.mixer_inputs);
    ``outputs``: fig14, fig15, fig16 (PNG), table (CSV), markdown, summary (JSON)."""
    names = list(spec["variants"])
    if len(names) < 2:
        raise DPHTError(f"the mixer study needs at least two variants, got {names}")
    window = tuple(spec["window"])
    files = {v: {f: inputs[f"{f}_{v}"] for f in ("walls", "positions", "thermal", "dem", "thermal_summary")} for v in names}
    fig14([(v, files[v]["walls"]) for v in names], outputs["fig14"], close_up=spec.get("close_up"))
    compare_cross_sections([(v, files[v]["positions"], files[v]["thermal"], files[v]["walls"]) for v in names],
                           outputs["fig15"], window_size=(500, 820))
    compare_variants([(v, files[v]["thermal"], files[v]["walls"]) for v in names], outputs["fig16"], window=window,
                     zones=spec["heated_zones"], spans=spec.get("spans"))
    alongside = alongside_mixers(spec.get("spans") or {})
    rows = [variant_row(v, files[v], window=window, specific_heat=spec["specific_heat"], zones=spec["heated_zones"],
                        inlet_temperature=spec["inlet_temperature"], alongside=alongside) for v in names]  # fmt: skip
    rows = relative_to_first(rows, spec.get("paper", {}))
    write_table(rows, outputs["table"], outputs["markdown"])
    for row in rows:
        log(f"mixers: {row['variant']}: wall heat {row['wall_heat_W']:.4g} W ({100 * row['wall_heat_relative']:+.1f}%), "
            f"outlet {row['outlet_temperature_K'] - KELVIN_OFFSET:.1f} C, mass flow {1e3 * row['mass_flow_kg_s']:.4g} g/s "
            f"({100 * row['mass_flow_relative']:+.1f}%), drive {row['drive_g']:.2f} g, energy balance {row['energy_balance']:.3f}, "
            f"below the mixers {100 * row['wall_heat_below_relative']:+.1f}%, drift in the window {100 * row['wall_heat_drift']:+.1f}%")
    return {"rows": rows, "window": list(window), "variants": names}
