"""The accuracy study's results: error against cost for every setting of every knob.

:func:`evaluate` turns the study's runs (their summaries, thermal and DEM files) into one row per
setting: the wall time of the stages the knob re-runs and the relative errors of the outputs
(:mod:`dpht.accuracy.outputs`) against the knob's reference setting. :func:`recommend` picks the
cheapest setting within the tolerance on the headline outputs, :func:`convergence` the evidence
that the reference itself has converged: the change between successive settings, which should
shrink towards the reference, and from the last two changes a Richardson-style bound of the
reference's own error, change * r / (1 - r) with r the ratio of the last two changes (when r < 1).

Costs (s): a thermal knob costs the thermal stage's wall time (its summary's ``seconds``; the HTC
tables it also rebuilds take well under a second); a DEM knob also the DEM run's (settle + flow,
from the DEM summary); a record length ``f`` costs the settle plus ``f`` of the flow and of the
thermal stage; a slice knob that re-runs the DEM its settle, the fraction of the flow its record
reuses and its own thermal run; a bed knob the parts of the Section 4 stage it affects (its
summary's ``seconds``: Monte Carlo tracing for the rays, the distance-based model's steady and
transient solution for the cutoff).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from pathlib import Path

from dpht.accuracy import knobs, outputs

BED_OUTPUT = {"bed_radiation_cutoff": ("dba", ("steady_s", "transient_s")),
              "bed_rays": ("monte_carlo", ("monte_carlo_s",))}  # fmt: skip


def _json(path) -> dict:
    return json.loads(Path(path).read_text())


# Outputs a setting is judged on, per scene (the tube's and the short scene's: outputs.HEADLINE).
JUDGED = {"bed": ("bed_heat_rate",), "slice": outputs.SLICE_HEADLINE}


def _scene_outputs(spec: dict, inputs: dict, i: int, record: float) -> dict:
    return outputs.headline(inputs[f"{i}_thermal"], inputs[f"{i}_positions"], window=spec["window"],
                            radial_band=spec["radial_band"], specific_heat=spec["specific_heat"],
                            inlet_temperature=spec["inlet_temperature"], record=record)  # fmt: skip


def _cost(knob: knobs.Knob, run: dict, inputs: dict, i: int) -> float:
    if knob.scene == "bed":
        seconds = _json(inputs[f"{i}_study"])["seconds"]
        return sum(seconds[part] for part in BED_OUTPUT[knob.name][1])
    thermal = _json(inputs[f"{i}_thermal_summary"])["seconds"]
    if "dem" not in knob.reruns:
        return thermal
    dem = _json(inputs[f"{i}_dem_summary"])["wall_time_s"]
    f = run["record"]
    if knob.scene == "slice":  # its thermal run reuses the record over the whole travel
        return dem["settle"] + f * dem["flow"] + thermal
    return dem["settle"] + f * (dem["flow"] + thermal)


def evaluate(spec: dict, inputs: dict, progress=print) -> list[dict]:
    """One row per run of ``spec["runs"]`` (:meth:`dpht.plan.Plan.accuracy_spec`): knob, setting,
    cost (s), the outputs and their relative errors against the knob's reference."""
    values, costs = [], []
    read: dict = {}  # (thermal file, record) -> its outputs: runs shared by several knobs are read once
    for i, run in enumerate(spec["runs"]):
        knob = knobs.BY_NAME[run["knob"]]
        if knob.scene == "bed":
            model = _json(inputs[f"{i}_study"])["models"][BED_OUTPUT[knob.name][0]]
            values.append({"rate_W": model["rate_W"]})
        else:
            key = (str(inputs[f"{i}_thermal"]), run["record"] if knob.scene != "slice" else 1.0)
            if key not in read:
                read[key] = (outputs.slice_headline(*(inputs[f"{i}_{k}"] for k in ("positions", "thermal", "walls")))
                             if knob.scene == "slice"
                             else _scene_outputs(spec, inputs, i, run["record"]))  # fmt: skip
            values.append(read[key])
        costs.append(_cost(knob, run, inputs, i))
        progress(f"accuracy: {run['knob']} = {run['label']}: {costs[-1]:.1f} s")
    rows = []
    for i, run in enumerate(spec["runs"]):
        knob = knobs.BY_NAME[run["knob"]]
        ref = next(j for j, r in enumerate(spec["runs"]) if r["knob"] == run["knob"] and r["reference"])
        row = {k: run[k] for k in ("knob", "label", "scene", "default", "reference")}
        row.update(setting=knob.label, cost_s=costs[i])
        if knob.scene == "bed":
            row["errors"] = {"bed_heat_rate": values[i]["rate_W"] / values[ref]["rate_W"] - 1.0}
        else:
            same_dem = run["keys"]["dem"] == spec["runs"][ref]["keys"]["dem"] and knob.name != "record_length"
            inlet = values[ref]["inlet_temperature_K"]
            local = outputs.local_rms(inputs[f"{i}_thermal"], inputs[f"{ref}_thermal"], inlet) if same_dem else None
            if knob.scene == "slice":
                row["errors"] = outputs.slice_errors(values[i], values[ref], local)
            else:
                row["errors"] = outputs.errors(values[i], values[ref], local, steady=knob.name == "record_length")
        row["outputs"] = values[i]
        rows.append(row)
    return rows


def stage_seconds(spec: dict, inputs: dict) -> float:
    """Wall time (s) of the study's distinct stage runs (DEM, thermal, Section 4), from their summaries."""
    seen, total = set(), 0.0
    for i, run in enumerate(spec["runs"]):
        for stage, key in run["keys"].items():
            if key is None or key in seen or stage not in ("dem", "thermal", "radiation_study"):
                continue
            seen.add(key)
            if stage == "dem":
                total += sum(_json(inputs[f"{i}_dem_summary"])["wall_time_s"].values())
            elif stage == "thermal":
                total += _json(inputs[f"{i}_thermal_summary"])["seconds"]
            else:
                total += sum(_json(inputs[f"{i}_study"])["seconds"].values())
    return total


def judged(row: dict) -> float:
    """The row's largest headline error (:data:`JUDGED`)."""
    return outputs.worst(row["errors"], JUDGED.get(row["scene"], outputs.HEADLINE))


def recommend(rows: list[dict], tolerance: float) -> list[dict]:
    """Per knob: the cheapest setting whose headline errors stay within ``tolerance`` (relative),
    next to the default and its error and cost. Cheapest in the registry's order (coarser first):
    wall times measured on a shared machine cannot rank settings that differ by a few percent."""
    table = []
    for name in dict.fromkeys(r["knob"] for r in rows):
        mine = [r for r in rows if r["knob"] == name]
        within = [r for r in mine if judged(r) <= tolerance]
        best = within[0]
        default = next((r for r in mine if r["default"]), None)
        table.append({"knob": name, "setting": mine[0]["setting"], "recommended": best["label"],
                      "recommended_cost_s": best["cost_s"], "recommended_error": judged(best),
                      "default": default["label"] if default else "", "default_cost_s": default["cost_s"] if default else math.nan,
                      "default_error": judged(default) if default else math.nan,
                      "reference": next(r["label"] for r in mine if r["reference"])})  # fmt: skip
    return table


def convergence(rows: list[dict]) -> list[dict]:
    """Per knob with at least three settings: the changes of the judged outputs between successive
    settings (towards the reference, the last one), and the bound of the reference's error."""
    table = []
    for name in dict.fromkeys(r["knob"] for r in rows):
        mine = [r for r in rows if r["knob"] == name and r["knob"] != "record_length"]
        if len(mine) < 3:
            continue
        keys = JUDGED.get(mine[0]["scene"], outputs.HEADLINE)
        changes = [max(abs(b["errors"][k] - a["errors"][k]) for k in keys) for a, b in itertools.pairwise(mine)]
        r = changes[-1] / changes[-2] if changes[-2] > 0 else math.nan
        bound = changes[-1] * r / (1 - r) if 0 <= r < 1 else math.nan
        table.append({"knob": name, "changes": changes, "last_ratio": r, "reference_error_bound": bound})
    return table


def write_csv(path, rows: list[dict], columns: list[str]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in rows:
            w.writerow([_cell(row.get(c)) for c in columns])


def _cell(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return ";".join(_cell(x) for x in v)
    return v


# Outputs beside the errors in accuracy.csv: wall heat into the run, the tube's outlet, the slice's rise and tube wall heat.
OUTPUT_COLUMNS = ("wall_heat_J", "outlet_temperature_K", "rise_K", "wall_heat_W")


def flat(rows: list[dict]) -> tuple[list[dict], list[str]]:
    """Rows with their errors as columns ``error_<name>``, and the column names."""
    names = list(dict.fromkeys(k for r in rows for k in r["errors"]))
    out = [{**{k: v for k, v in r.items() if k not in ("errors", "outputs")},
            **{f"error_{k}": r["errors"].get(k, math.nan) for k in names},
            **{k: r["outputs"].get(k) for k in OUTPUT_COLUMNS}, "bed_rate_W": r["outputs"].get("rate_W")} for r in rows]  # fmt: skip
    columns = ["knob", "setting", "label", "scene", "default", "reference", "cost_s", *[f"error_{k}" for k in names],
               *OUTPUT_COLUMNS, "bed_rate_W"]
    return out, columns


def markdown(recommended: list[dict], tolerance: float) -> str:
    lines = [(f"Recommended setting per knob: the cheapest within {tolerance:.1%} of the reference on the headline "
              "outputs (total wall heat, wall heat by mode, outlet temperature rise; the Watkins slice: mean "
              "temperature rise at 0.645 m, wall heat, by mode, and its split by mode overall and at 0.645 m, "
              f"within {100 * tolerance:.2g} percentage points)."), "",
             "| knob | setting | reference | recommended (cost s, error) | default (cost s, error) |",
             "|---|---|---|---|---|"]  # fmt: skip
    for r in recommended:
        lines.append(f"| {r['knob']} | {r['setting']} | {r['reference']} | {r['recommended']} "
                     f"({r['recommended_cost_s']:.1f}, {r['recommended_error']:.2%}) | {r['default']} "
                     f"({r['default_cost_s']:.1f}, {r['default_error']:.2%}) |")  # fmt: skip
    return "\n".join(lines) + "\n"


def run(spec: dict, inputs: dict, out: dict, progress=print) -> dict:
    """Evaluate, recommend, write the CSVs, the Markdown table, the figures and the summary."""
    from dpht.figures import accuracy as figures

    rows = evaluate(spec, inputs, progress)
    recommended = recommend(rows, spec["tolerance"])
    evidence = convergence(rows)
    table, columns = flat(rows)
    write_csv(out["table"], table, columns)
    write_csv(out["recommended"], recommended, list(recommended[0]))
    write_csv(out["convergence"], evidence, ["knob", "changes", "last_ratio", "reference_error_bound"])
    Path(out["markdown"]).write_text(markdown(recommended, spec["tolerance"]))
    figures.knob_curves(rows, out["knobs"], judged)
    figures.pareto(rows, out["pareto"], judged, spec["tolerance"])
    figures.convergence(evidence, out["convergence_figure"])
    summary = {"rows": rows, "recommended": recommended, "convergence": evidence, "tolerance": spec["tolerance"],
               "study_cost_s": stage_seconds(spec, inputs)}
    Path(out["summary"]).write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return summary
