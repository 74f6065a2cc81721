"""What every figure of the default target `all` writes beside its PNG, and the check of one rendered
figure (tests/workflow/test_workflow.py, tests/workflow/test_watkins.py and tests/workflow/test_quick.py render them from tiny
runs; tests/workflow/test_quick.py checks that this map names every report figure of the workflow).

FIGURE_CSVS maps a figure's name (its PNG's stem) to the CSV files its figure function writes beside
it, each with its header and the columns that may hold no number, with the reason. A figure that
draws no numbers (a rendering of particles or walls) maps to no files. Header entries with
``{pw_mode}`` stand for one column per particle-wall mode (dpht.thermal.modes.PW_MODES, in order).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

from PIL import Image

from dpht.figures.scene import MIN_DIFFERENCE
from dpht.radiation.study import MODELS, PAPER_TABLE_1
from dpht.thermal.modes import PW_MODES

PIXELS = (300, 4000)  # a figure's width and height lie in this range (px)


def _empty(count: str):
    """NaN allowed where the row's ``count`` column is zero (an empty bin: a mean of nothing)."""
    return lambda row, rows: float(row[count]) == 0


@dataclass(frozen=True)
class Table:
    header: tuple[str, ...]
    text: frozenset = frozenset()  # columns of names or flags, not numbers
    # column -> (why it may hold no number, where: (row, rows) -> True where allowed)
    undefined: dict = field(default_factory=dict)

    def columns(self) -> list[str]:
        out = []
        for name in self.header:
            out += [name.format(pw_mode=m) for m in PW_MODES] if "{pw_mode}" in name else [name]
        return out


_EMPTY_BIN = "a bin no wall element (or no particle sample) falls in: a mean of nothing"
_FLUX = Table(("distance_lo_m", "distance_hi_m", "distance_mean_m", "area_m2", "heat_{pw_mode}_W", "heat_total_W",
               "flux_{pw_mode}_W_m2", "flux_total_W_m2"),
              undefined={c: (_EMPTY_BIN, _empty("area_m2")) for c in
                         ("distance_mean_m", *(f"flux_{m}_W_m2" for m in PW_MODES), "flux_total_W_m2")})  # fmt: skip

# compare_variants' CSVs (dpht.figures.scene.compare_variants), also the mixer study's Fig. 16
_VARIANT_TABLES = {
    "csv": Table(("variant", "distance_lo_m", "distance_hi_m", "distance_mean_m", "area_m2", "flux_total_W_m2"),
                 text=frozenset({"variant"}),
                 undefined={c: (_EMPTY_BIN, _empty("area_m2")) for c in ("distance_mean_m", "flux_total_W_m2")}),
    "totals.csv": Table(("variant", "heat_total_W", "relative_to_first"), text=frozenset({"variant"}),
                        undefined={"relative_to_first": ("relative to a first variant with no wall heat",
                                                         lambda row, rows: float(rows[0]["heat_total_W"]) == 0)}),
}


def _variant_tables(stem: str) -> dict[str, Table]:
    return {f"{stem}.{suffix}": table for suffix, table in _VARIANT_TABLES.items()}


FIGURE_CSVS: dict[str, dict[str, Table]] = {
    # the geometry rule's picture of the walls, and the particle renderings (pyvista): no numbers
    "geometry": {},
    "cross_section": {},
    "cross_sections": {},
    # per variant (dpht.plan.FIGURES)
    "wall_heat_flux": {"wall_heat_flux.csv": _FLUX},
    "wall_heat_history": {"wall_heat_history.csv": Table(
        ("time_start_s", "time_end_s", "heat_{pw_mode}_W", "heat_total_W", "residual_W"))},
    "temperature_profiles": {
        "temperature_profiles.axial.csv": Table(
            ("z_lo_m", "z_hi_m", "z_mean_m", "distance_mean_m", "samples", "temperature_K"),
            undefined={c: (_EMPTY_BIN, _empty("samples")) for c in ("z_mean_m", "distance_mean_m", "temperature_K")}),
        "temperature_profiles.radial.csv": Table(
            ("r_lo_m", "r_hi_m", "r_mean_m", "samples", "temperature_K"),
            undefined={c: (_EMPTY_BIN, _empty("samples")) for c in ("r_mean_m", "temperature_K")}),
    },
    "engineering": {"engineering.csv": Table(
        ("distance_lo_m", "distance_hi_m", "distance_mean_m", "dirichlet_area_m2", "heat_W", "flux_W_m2",
         "wall_temperature_K", "bed_temperature_K", "mass_flow_kg_s", "htc_W_m2K"),
        undefined={**{c: (_EMPTY_BIN, _empty("dirichlet_area_m2")) for c in ("distance_mean_m", "flux_W_m2", "wall_temperature_K")},
                   **{c: ("a bin no particle flows through (no mixing cup), or the wall within MIN_DIFFERENCE of the "
                          "bed (h undefined) or adiabatic there",
                          lambda row, rows: float(row["mass_flow_kg_s"]) <= 0 or float(row["dirichlet_area_m2"]) == 0
                          or not abs(float(row["wall_temperature_K"]) - float(row["bed_temperature_K"])) >= MIN_DIFFERENCE)
                      for c in ("bed_temperature_K", "htc_W_m2K")}})},
    "htc_curves": {"htc_curves.csv": Table(("kind", "temperature_K", "distance_over_R", "htc_W_K"), text=frozenset({"kind"}))},
    # compare_variants
    "variants": _variant_tables("variants"),
    # the mixer study (DPHT paper, Section 6, dpht.plan.MIXER_FIGURES): the designs and the cross-sections
    # (renderings), the wall heat flux per variant (compare_variants)
    "fig14": {},
    "fig15": {},
    "fig16": _variant_tables("fig16"),
    # radiation_study (DPHT paper, Section 4): the transient drawn, and Table 1 beside it
    "fig9": {
        "history.csv": Table(("time_s", *(f"{m}_{q}" for m in MODELS for q in ("hot_out_W", "cold_in_W", "generation_W")))),
        "table.csv": Table(
            ("model", "hot_out_W", "cold_in_W", "rate_W", "rate_W_per_m2", "error", "generation_W", "free_residual",
             "transient_vs_steady_K", "generation_per_rate", "paper_rate_W", "paper_rate_W_per_m2", "paper_error",
             "paper_generation_W"),
            text=frozenset({"model"}),
            undefined={column: ("the paper's Table 1 has no such number: Musser's model did not converge there, and "
                                "the Monte Carlo model is the reference of the errors",
                                lambda row, rows, key=key: PAPER_TABLE_1[row["model"]][key] is None)
                       for column, key in (("paper_rate_W", "rate_W"), ("paper_rate_W_per_m2", "rate_W"),
                                           ("paper_error", "error"))}),
    },
    # intraparticle_study (issue 13, ParScale)
    "biot_sweep": {"biot_sweep.csv": Table(
        ("series", "diameter_m", "conductivity_W_mK", "biot_max", "biot_median", "wall_energy_lumped_J",
         "wall_energy_resolved_J", "relative_difference", "substeps_lumped", "substeps_resolved", "particles"),
        text=frozenset({"series"}))},
    "cooled_sphere": {"cooled_sphere.csv": Table(("t", "r_over_a", "T"))},
    "cooled_sphere_convergence": {"cooled_sphere_convergence.csv": Table(
        ("parameter", "value", "mean_relative_error", "max_relative_error", "observed_order"), text=frozenset({"parameter"}),
        undefined={"observed_order": ("the coarsest setting of each parameter has no coarser one to compare with",
                                      lambda row, rows: row is next(r for r in rows if r["parameter"] == row["parameter"]))})},
    # Watkins (DPHT paper, Section 5, dpht.plan.WATKINS_FIGURES) and the reduction check
    "fig11": {"fig11.csv": Table(("distance_m", "wall_temperature_K", "mean_particle_temperature_K"))},
    "fig12": {
        "fig12.radial.csv": Table(("r_lo_m", "r_hi_m", "temperature_K"),
                                  undefined={"temperature_K": ("a radial bin no particle centre reaches in the last frame "
                                                               "(the outermost, within a radius of the wall)", None)}),
        "fig12.map.csv": Table(("distance_m", *(f"T_r{j}_K" for j in range(12))),
                               undefined={f"T_r{j}_K": ("a radial bin no particle centre reaches in that frame", None)
                                          for j in range(12)}),
    },
    "fig13": {
        "fig13.csv": Table(("distance_lo_m", "distance_hi_m", "flux_{pw_mode}_W_m2", "flux_total_W_m2")),
        "fig13.split.csv": Table(("mode", "overall_percent", "paper_overall_percent", "at_0.645m_percent",
                                  "paper_at_0.645m_percent"), text=frozenset({"mode"})),
    },
    "reduction": {
        "reduction.csv": Table(("z_lo_m", "z_hi_m", "distance_m", "rise_full_K", "rise_slice_K",
                                *(f"heat_{m}_{run}_W" for m in PW_MODES for run in ("full", "slice")))),
        "reduction.summary.csv": Table(("quantity", "value"), text=frozenset({"quantity"})),
    },
}


def missing(name: str) -> str:
    return (f"figure {name!r} has no entry in FIGURE_CSVS (tests/figure_files.py): add the CSV files its figure "
            f"function writes beside the PNG, their header and the columns that may hold no number")


def check_figure(png: Path) -> None:
    """The PNG exists with a sane size, and each CSV beside it (FIGURE_CSVS) has its header and
    only finite numbers, but where its table allows none."""
    png = Path(png)
    assert png.stem in FIGURE_CSVS, missing(png.stem)
    assert png.is_file(), f"{png}: not written"
    with Image.open(png) as image:
        width, height = image.size
    assert PIXELS[0] <= width <= PIXELS[1] and PIXELS[0] <= height <= PIXELS[1], f"{png}: {width} x {height} px"
    for name, table in FIGURE_CSVS[png.stem].items():
        path = png.with_name(name)
        with open(path, newline="") as stream:
            reader = csv.DictReader(stream)
            rows = list(reader)
        assert reader.fieldnames == table.columns(), f"{path}: header {reader.fieldnames}, expected {table.columns()}"
        assert rows, f"{path}: no rows"
        for k, row in enumerate(rows):
            for column, text in row.items():
                if column in table.text:
                    continue
                value = float(text) if text not in ("", "None") else math.nan
                if math.isfinite(value):
                    continue
                reason, where = table.undefined.get(column, (None, None))
                assert reason is not None and (where is None or where(row, rows)), (
                    f"{path}: row {k + 1}, {column} = {text!r} is not a finite number"
                    + ("" if reason is None else f" (allowed only where: {reason})"))
