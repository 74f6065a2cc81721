"""The screening check (``snakemake --cores 2 screening_check``): what the effects a scene screened
out would have changed.

Each check scene — the first variant of ``screening_check.scene`` (``default``) and every scene of
``screening_check.scenes`` (overrides of it, as a variant's) — runs twice: as configured, its
``auto`` switches decided by :mod:`dpht.thermal.effects`, and with every switch left at ``auto``
set on, i.e. every effect the screening switched off switched back on (the plan registers both,
:func:`dpht.thermal.effects.all_on`, :mod:`dpht.studies.screening_check`; they share every stage but the thermal one). The
change of the headline outputs between the two (:mod:`dpht.accuracy.outputs`: total wall heat,
relative; mixing-cup outlet temperature, relative to its rise above the inlet) is what the
screening cost; its claim is that this stays below the scene's ``thermal.screening_threshold``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from dpht.accuracy.outputs import errors, headline
from dpht.accuracy.study import write_csv
from dpht.thermal import effects

COLUMNS = ["scene", "temperatures_K", "off", "by", "wall_heat_J", "wall_heat_all_on_J", "change_wall_heat",
           "outlet_K", "outlet_all_on_K", "change_outlet", "threshold", "holds"]  # fmt: skip


def evaluate(spec: dict, inputs: dict) -> list[dict]:
    """One row per check scene (``spec["scenes"]``; its files in ``inputs`` as ``<i>_<run>_<file>``)."""
    rows = []
    for i, scene in enumerate(spec["scenes"]):
        outputs = {}
        for run in ("auto", "all"):
            outputs[run] = headline(inputs[f"{i}_{run}_thermal"], inputs[f"{i}_{run}_positions"], window=scene["window"],
                                    radial_band=scene["radial_band"], specific_heat=scene["specific_heat"],
                                    inlet_temperature=scene["inlet_temperature"])  # fmt: skip
        decided = json.loads(Path(inputs[f"{i}_auto_summary"]).read_text())["effects"]
        off = [d for d in decided if not d["on"] and d["effect"] in effects.SCREENED and d["setting"] == effects.AUTO]
        change = errors(outputs["auto"], outputs["all"])
        worst = max(abs(change["wall_heat"]), abs(change["outlet_temperature"]) if math.isfinite(change["outlet_temperature"]) else 0.0)
        rows.append({
            "scene": scene["name"],
            "temperatures_K": f"{scene['temperatures'][0]:.0f}-{scene['temperatures'][1]:.0f}",
            "off": [d["effect"] for d in off] or ["none"],
            "by": [d["by"] for d in off],
            "wall_heat_J": outputs["auto"]["wall_heat_J"],
            "wall_heat_all_on_J": outputs["all"]["wall_heat_J"],
            "change_wall_heat": change["wall_heat"],
            "outlet_K": outputs["auto"]["outlet_temperature_K"],
            "outlet_all_on_K": outputs["all"]["outlet_temperature_K"],
            "change_outlet": change["outlet_temperature"],
            "threshold": scene["threshold"],
            "holds": bool(worst < scene["threshold"]),
            "reasons": {d["effect"]: d["reason"] for d in off},
        })  # fmt: skip
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["What switching the screened-out effects back on changes: total wall heat (relative) and the "
             "mixing-cup outlet temperature (relative to its rise above the inlet).", "",
             "| scene | T (K) | screened out | wall heat | outlet | threshold | holds |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        lines.append(f"| {r['scene']} | {r['temperatures_K']} | {', '.join(r['off'])} | {r['change_wall_heat']:+.3%} | "
                     f"{r['change_outlet']:+.3%} | {r['threshold']:.0%} | {'yes' if r['holds'] else 'NO'} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def run(spec: dict, inputs: dict, out: dict) -> list[dict]:
    """Evaluate the check scenes; write the table (CSV, Markdown) and the summary."""
    rows = evaluate(spec, inputs)
    write_csv(out["table"], rows, COLUMNS)
    Path(out["markdown"]).write_text(markdown(rows))
    Path(out["summary"]).write_text(json.dumps({"rows": rows}, indent=2, sort_keys=True) + "\n")
    return rows
