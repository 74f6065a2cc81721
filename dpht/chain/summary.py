"""A chain's summary (docs/theory/chain.md): its segments' wall heat and their total, the mixing-cup
temperature at every joint, the books of every hand-over and the outlet temperature, from the
segment runs' summaries (:func:`dpht.stages.segment`: the thermal run's summary with its
``hand_over`` books and its ``outlet``, :meth:`dpht.chain.handover.HandOver.summary`).

The wall heat profile along the tube is the segments' (:func:`dpht.chain.handover.slice_profile`,
:func:`~dpht.chain.handover.resolved_profile`) in flow order: bins about a particle diameter long, W
each at the chain's mass flow.

The balance checks the books against each other: each segment's enthalpy rise, m (h(T_out) -
h(T_in)) with T_in the mixing cup of the field it was handed (the inlet temperature for the first),
against its wall heat; and the chain's, from the inlet temperature to the outlet's mixing cup,
against the total. Enthalpies are the particles' c_p(T) integrated (one table for the chain).
A slice's closes to what its hand-over shift and the gas exchange (``convected``) leave; a resolved
segment's to how steady its window is.
"""

from __future__ import annotations

import math

from dpht.closures import heat_capacity


def summarize(spec: dict, summaries: list[dict], fields: list) -> dict:
    """The summary of the chain of ``spec`` (:attr:`dpht.plan.ChainRuns.spec`) from its segment
    runs' ``summaries`` and hand-over ``fields`` (:class:`dpht.chain.field.Field`), in flow order."""
    inlet = float(spec["inlet_temperature"])
    cups = [f.cup_temperature for f in fields]
    temperatures = [inlet, *cups]
    table = heat_capacity.build(heat_capacity.specific_heat(spec["specific_heat"]), min(temperatures), max(temperatures))

    def h(T):
        return float(table.enthalpy(T))

    flow = float(spec["mass_flow"])
    segments, joints = [], []
    for k, (segment, summary) in enumerate(zip(spec["segments"], summaries)):
        out = summary["outlet"]
        T_in = inlet if k == 0 else cups[k - 1]
        rise = flow * (h(cups[k]) - h(T_in))
        segments.append({"index": k, "kind": segment["kind"], "bottom_m": segment["bottom"], "top_m": segment["top"],
                         "inserts": segment["inserts"], "outlet_plate": segment["outlet"], "key": segment["key"],
                         "dem": segment["dem"], "wall_heat_W": out["wall_heat_W"], "enthalpy_rise_W": rise,
                         "cup_in_K": T_in, "cup_out_K": cups[k], "samples": out["samples"], "steady": out["steady"],
                         "wall_heat_halves_W": out["wall_heat_halves_W"], "cup_halves_K": out["cup_temperature_halves_K"],
                         "upward_crossings": out["upward_crossings"], "filled_cells": out["filled_cells"]})  # fmt: skip
        if k:
            joints.append({"between": [k - 1, k], "z_m": segment["top"], "cup_temperature_K": cups[k - 1],
                           **_books(summary.get("hand_over", {}))})  # fmt: skip
    total = math.fsum(s["wall_heat_W"] for s in segments)
    profile = [{"segment": k, "z_top_m": top, "z_bottom_m": bottom, "wall_heat_W": q}
               for k, summary in enumerate(summaries)
               for top, bottom, q in zip(summary["outlet"]["profile_edges_m"], summary["outlet"]["profile_edges_m"][1:],
                                         summary["outlet"]["profile_W"])]  # fmt: skip
    rise = flow * (h(cups[-1]) - h(inlet))
    return {"mass_flow_kg_s": flow, "inlet_temperature_K": inlet, "outlet_cup_temperature_K": cups[-1],
            "wall_heat_W": total, "enthalpy_rise_W": rise,
            "balance_relative": (rise - total) / abs(total) if total else math.nan,
            "segments": segments, "joints": joints, "profile": profile, "dem_runs": len(set(s["dem"] for s in spec["segments"])),
            "resolved_shapes": spec["shapes"]}  # fmt: skip


def _books(hand_over: dict) -> dict:
    """A receiving segment's books of its hand-over: the initial field's shift and residual, and
    for a resolved segment what entered through its inlet field."""
    initial, inlet = hand_over.get("initial", {}), hand_over.get("inlet", {})
    return {"delta_J_kg": initial.get("correction_J_kg"), "delta_K": initial.get("correction_K"),
            "residual_J_kg": initial.get("residual_J_kg"), "relative_residual": initial.get("relative_residual"),
            "filled_cells": initial.get("filled_cells"), "entered": inlet.get("entered"),
            "entered_deviation_K": inlet.get("entered_deviation_K")}  # fmt: skip
