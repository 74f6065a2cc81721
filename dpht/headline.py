"""The headline of a design variant: the numbers an engineer sizing a particle heat exchanger reads
first, in ``results/<variant>/headline.md`` and ``headline.csv`` (written by the variant summary
stage beside ``summary.json``, and kept in it under ``headline``).

Every number is a mean over the figures' steady window (``figures.steady_window``), taken from what
the stages wrote, not computed a second time: the engineering figure's profile along the tube and
energy balance (:func:`dpht.figures.scene.engineering_profile`, its ``engineering.csv`` and
``engineering.json``: the wall and mixing-cup bed temperatures per bin, the outlet's mixing-cup
temperature, the mass flow and the balance), the wall heat flux figure's heat per mode
(:func:`dpht.figures.scene.wall_heat_flux`, ``wall_heat_flux.csv``), and the DEM and thermal
summaries (error estimate, wall times).

Definitions (also written into ``headline.md``):

* wall heat Q (W, into the particles): the particle-wall (PW) modes' heat over the heated zones;
  the particle-particle (PP) modes move heat inside the bed and carry none from the wall;
* mean wall-to-bed heat transfer coefficient h_w = Q / (A_w <T_w - T_b>) (W/(m^2 K)), with A_w the
  heated (Dirichlet) wall area and <T_w - T_b> the area-weighted mean, over the heated wall, of the
  difference between the local wall temperature T_w(z) and the local mixing-cup (flow-weighted,
  bulk) bed temperature T_b(z) at the same distance from the inlet (the bins of the engineering
  figure; bins where the bed does not flow downwards have no T_b and are left out of the mean);
* wall Nusselt number Nu_w = h_w d_p / k_g, the particle-diameter convention of moving-bed wall
  heat transfer (Sullivan and Sabersky 1975, Int. J. Heat Mass Transfer 18, 97-107; Schlünder 1984,
  Chem. Eng. Process. 18, 31-53), k_g the gas conductivity at the film temperature
  (<T_w> + <T_b>) / 2 (area means over the heated wall); undefined in a vacuum;
* energy-balance residual: duty + heat from the gas - bed enthalpy rise m_dot (h(T_out) - h(T_in))
  - storage dE/dt, at the DEM run's measured mass flow (relative to the duty), and the same at the
  window's own flow (the thermal stage's energy conservation, round-off);
* error estimate: the thermal run's numerical error of the total wall heat
  (:mod:`dpht.thermal.error_estimate`);
* cost: wall time of the DEM run (settling and flow, LIGGGHTS) and of the thermal run.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.closures import gas, htc
from dpht.errors import DPHTError
from dpht.thermal.modes import MODES, NAMES, PW_MODES


@dataclass(frozen=True)
class Headline:
    """The headline numbers of one design variant (SI units; definitions: module docstring)."""

    variant: str
    window_s: float  # length of the steady window the means are taken over
    wall_heat_W: float  # Q, the PW modes' sum
    wall_heat_by_mode_W: Mapping[str, float]  # PW modes (NaN for a mode that is off)
    modes_on: Mapping[str, bool]  # all six modes
    inlet_temperature_K: float
    outlet_temperature_K: float  # mixing cup
    heated_area_m2: float  # A_w
    wall_temperature_K: float  # <T_w>, area mean over the heated wall
    bed_temperature_K: float  # <T_b>, area mean of the local mixing-cup temperature over the heated wall
    difference_K: float  # <T_w - T_b>
    htc_W_m2K: float  # h_w
    particle_diameter_m: float
    gas_conductivity_W_mK: float  # k_g at the film temperature (NaN in a vacuum)
    nusselt: float  # Nu_w = h_w d_p / k_g
    mass_flow_kg_s: float  # the DEM run's, second half of the flow
    residual_W: float  # energy balance at the DEM's mass flow
    residual_relative: float  # of the duty
    conservation_relative: float  # the same at the window's own flow
    error_relative: float | None  # the run's error estimate of Q, relative (None: no estimate)
    dem_seconds: float  # wall time of LIGGGHTS (settle + flow)
    thermal_seconds: float  # wall time of the thermal run


def wall_to_bed(area, wall_temperature, bed_temperature, heat: float) -> tuple[float, float, float, float, float]:
    """Mean wall-to-bed heat transfer coefficient h_w = Q / (A_w <T_w - T_b>) from per-bin heated
    wall ``area`` (m^2; 0 where a bin has no heated element), ``wall_temperature`` T_w and
    ``bed_temperature`` T_b (K, the local mixing-cup temperature; NaN where undefined) and the wall
    heat ``heat`` Q (W). Returns (h_w, A_w, <T_w>, <T_b>, <T_w - T_b>), the means area-weighted over
    the heated bins with a defined T_b; NaN when there is none."""
    area, t_wall, t_bed = (np.asarray(a, dtype=float) for a in (area, wall_temperature, bed_temperature))
    heated = (area > 0) & np.isfinite(t_wall)
    defined = heated & np.isfinite(t_bed)
    total = float(area[heated].sum())
    if not defined.any():
        return math.nan, total, math.nan, math.nan, math.nan
    weights = area[defined]
    mean_wall, mean_bed = (float(np.average(t[defined], weights=weights)) for t in (t_wall, t_bed))
    difference = mean_wall - mean_bed
    h = heat / (total * difference) if difference != 0 else math.nan
    return h, total, mean_wall, mean_bed, difference


def headline(variant: str, *, area, wall_temperature, bed_temperature, wall_heat_by_mode: Mapping[str, float],
             modes_on: Mapping[str, bool], balance: Mapping[str, float], particle_diameter: float,
             gas_conductivity: Callable[[float], float] | None, error_estimate: Mapping | None,
             dem_seconds: float, thermal_seconds: float) -> Headline:
    """The headline of ``variant`` from the engineering profile's bins (``area``, ``wall_temperature``,
    ``bed_temperature``: see :func:`wall_to_bed`), the window-mean wall heat per PW mode (W), the
    modes that were on, the engineering figure's energy ``balance`` (its ``engineering.json``), the
    particle diameter (m), the gas conductivity k_g(T) (W/(m K); None in a vacuum), the thermal
    run's ``error_estimate`` (its summary's, or None) and the DEM and thermal wall times (s)."""
    unknown = sorted(set(wall_heat_by_mode) - set(PW_MODES))
    if unknown:
        raise DPHTError(f"wall heat of {unknown}: only the particle-wall modes {list(PW_MODES)} carry wall heat")
    by_mode = {m: float(wall_heat_by_mode[m]) if modes_on.get(m) else math.nan for m in PW_MODES}
    q = math.fsum(v for v in by_mode.values() if not math.isnan(v))
    h, total, mean_wall, mean_bed, difference = wall_to_bed(area, wall_temperature, bed_temperature, q)
    film = 0.5 * (mean_wall + mean_bed)
    k_g = float(gas_conductivity(film)) if gas_conductivity is not None and math.isfinite(film) else math.nan
    estimate = (error_estimate or {}).get("wall_heat")
    return Headline(
        variant=variant, window_s=float(balance["window_s"]), wall_heat_W=q, wall_heat_by_mode_W=by_mode,
        modes_on={m: bool(modes_on.get(m, False)) for m in NAMES},
        inlet_temperature_K=float(balance["inlet_temperature_K"]), outlet_temperature_K=float(balance["outlet_temperature_K"]),
        heated_area_m2=total, wall_temperature_K=mean_wall, bed_temperature_K=mean_bed, difference_K=difference,
        htc_W_m2K=h, particle_diameter_m=float(particle_diameter), gas_conductivity_W_mK=k_g,
        nusselt=h * particle_diameter / k_g if k_g > 0 else math.nan,
        mass_flow_kg_s=float(balance["mass_flow_kg_s"]), residual_W=float(balance["residual_W"]),
        residual_relative=float(balance["residual_relative"]),
        conservation_relative=float(balance["residual_window_relative"]),
        error_relative=float(estimate["relative"]) if estimate else None,
        dem_seconds=float(dem_seconds), thermal_seconds=float(thermal_seconds),
    )  # fmt: skip


# --- from the stage outputs ---------------------------------------------------------------------


def _columns(path: Path) -> dict[str, np.ndarray]:
    """The columns of a figure's CSV (:func:`dpht.figures.scene._write_csv`) as float arrays."""
    try:
        with open(path, newline="") as stream:
            rows = list(csv.reader(stream))
    except OSError as err:
        raise DPHTError(f"{path}: cannot read it ({err.strerror}); the figures stage writes it") from None
    if not rows:
        raise DPHTError(f"{path}: empty")
    return {name: np.array([float(row[j]) for row in rows[1:]]) for j, name in enumerate(rows[0])}


def from_outputs(variant: str, *, engineering_png, wall_heat_flux_png, thermal_h5, dem_summary: Mapping,
                 thermal_summary: Mapping) -> Headline:
    """The headline of ``variant`` from its figures (the CSV and JSON beside ``engineering_png`` and
    ``wall_heat_flux_png``), the run's config sections and enabled modes recorded in ``thermal_h5``
    (attributes ``spec`` and ``modes``), and the DEM and thermal summaries."""
    engineering, flux = Path(engineering_png), Path(wall_heat_flux_png)
    profile = _columns(engineering.with_suffix(".csv"))
    heat = _columns(flux.with_suffix(".csv"))
    balance = json.loads(engineering.with_suffix(".json").read_text())
    with h5py.File(thermal_h5, "r") as f:
        spec, enabled = json.loads(f.attrs["spec"]), set(json.loads(f.attrs["modes"]))
    thermal = spec["thermal"]
    conductivity = (lambda T: float(gas.conductivity(thermal["gas"], T))) if htc.gas_conducts(thermal) else None
    return headline(
        variant, area=profile["dirichlet_area_m2"], wall_temperature=profile["wall_temperature_K"],
        bed_temperature=profile["bed_temperature_K"],
        wall_heat_by_mode={m: float(heat[f"heat_{m}_W"].sum()) for m in PW_MODES if f"heat_{m}_W" in heat},
        modes_on={m: m in enabled for m in NAMES}, balance=balance, particle_diameter=spec["particles"]["diameter"],
        gas_conductivity=conductivity, error_estimate=thermal_summary.get("error_estimate"),
        dem_seconds=sum(dem_summary["wall_time_s"].values()), thermal_seconds=thermal_summary["seconds"],
    )  # fmt: skip


# --- the files ----------------------------------------------------------------------------------


def rows(h: Headline) -> list[tuple[str, str, float | None, str]]:
    """(column of headline.csv, quantity, value, unit) in the order of the files."""
    by_side = {m.name: m.side for m in MODES}
    out = [("wall_heat_W", "wall heat Q (PW modes, into the particles)", h.wall_heat_W, "W")]
    for mode in NAMES:  # the six modes: PW ones carry the wall heat, PP ones none
        value = h.wall_heat_by_mode_W[mode] if by_side[mode] == "pw" else None
        state = "on" if h.modes_on[mode] else "off"
        out.append((f"wall_heat_{mode}_W", f"  {mode} ({state}{', no wall heat: particle-particle' if value is None else ''})",
                    value, "W"))  # fmt: skip
    out += [
        ("inlet_temperature_K", "inlet temperature", h.inlet_temperature_K, "K"),
        ("outlet_temperature_K", "outlet temperature, mixing cup", h.outlet_temperature_K, "K"),
        ("mass_flow_kg_s", "mass flow (DEM, second half of the flow)", h.mass_flow_kg_s, "kg/s"),
        ("heated_area_m2", "heated wall area A_w", h.heated_area_m2, "m2"),
        ("wall_temperature_K", "mean wall temperature <T_w>", h.wall_temperature_K, "K"),
        ("bed_temperature_K", "mean bed temperature <T_b> (local mixing cup)", h.bed_temperature_K, "K"),
        ("difference_K", "mean difference <T_w - T_b>", h.difference_K, "K"),
        ("htc_W_m2K", "wall-to-bed HTC h_w = Q / (A_w <T_w - T_b>)", h.htc_W_m2K, "W/(m2 K)"),
        ("nusselt", "wall Nusselt number Nu_w = h_w d_p / k_g", h.nusselt, "-"),
        ("particle_diameter_m", "particle diameter d_p", h.particle_diameter_m, "m"),
        ("gas_conductivity_W_mK", "gas conductivity k_g at the film temperature", h.gas_conductivity_W_mK, "W/(m K)"),
        ("residual_W", "energy-balance residual at the DEM mass flow", h.residual_W, "W"),
        ("residual_relative", "  relative to the wall heat", h.residual_relative, "-"),
        ("conservation_relative", "  at the window's own flow (energy conservation)", h.conservation_relative, "-"),
        ("error_relative", "numerical error estimate of the wall heat, relative", h.error_relative, "-"),
        ("dem_seconds", "cost: DEM wall time (settle + flow)", h.dem_seconds, "s"),
        ("thermal_seconds", "cost: thermal wall time", h.thermal_seconds, "s"),
        ("window_s", "steady window the means are over", h.window_s, "s"),
    ]
    return out


def csv_text(h: Headline) -> str:
    """headline.csv: a header and one row (``variant`` and the columns of :func:`rows`), so the
    files of several variants stack into one table; floats with round-trip precision."""
    table = rows(h)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["variant", *(column for column, *_ in table)])
    writer.writerow([h.variant, *("" if value is None else repr(float(value)) for _, _, value, _ in table)])
    return text.getvalue()


DEFINITIONS = """\
Means over the steady window (`figures.steady_window`), from the engineering and wall heat flux figures.

- Wall heat Q: heat from the heated wall into the particles by the particle-wall modes; the
  particle-particle modes move heat inside the bed and carry none from the wall.
- h_w = Q / (A_w <T_w - T_b>): A_w the heated (Dirichlet) wall area, <T_w - T_b> the area-weighted
  mean over the heated wall of the local wall temperature minus the bed's local mixing-cup
  (flow-weighted) temperature at the same distance from the inlet.
- Nu_w = h_w d_p / k_g (particle-diameter wall Nusselt number of moving-bed heat transfer, Sullivan
  and Sabersky 1975), k_g the gas conductivity at the film temperature (<T_w> + <T_b>) / 2.
- Outlet temperature: mixing cup of the particles leaving through the outlet.
- Energy-balance residual: duty + gas - m_dot (h(T_out) - h(T_in)) - storage, at the DEM's mass
  flow; at the window's own flow it is the thermal stage's energy conservation.
- Error estimate: the thermal run's estimate of the numerical error of Q (time step, tables).
"""


def _number(value: float | None, unit: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if unit == "-" and abs(value) < 1 and value != 0:
        return f"{value:.3g}" if abs(value) >= 0.01 else f"{value:.2e}"
    return f"{value:.4g}"


def markdown(h: Headline) -> str:
    """headline.md: a table of :func:`rows` and the definitions."""
    lines = [f"# Headline: {h.variant}", "", "| quantity | value | unit |", "|---|---:|---|"]
    for _, name, value, unit in rows(h):  # an indented quantity is a part or a measure of the one above
        name = "&nbsp;&nbsp;" + name.strip() if name.startswith("  ") else name
        lines.append(f"| {name} | {_number(value, unit)} | {unit} |")
    return "\n".join(lines) + "\n\n" + DEFINITIONS


def record(h: Headline) -> dict:
    """The headline as JSON-ready data (NaN as None)."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else
                {m: None if isinstance(x, float) and math.isnan(x) else x for m, x in v.items()} if isinstance(v, Mapping) else v)
            for k, v in asdict(h).items()}  # fmt: skip
