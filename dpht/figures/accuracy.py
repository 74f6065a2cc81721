"""Figures of the accuracy study (:mod:`dpht.accuracy.study`): error against cost per knob, the
Pareto figure of every setting, and the reference's convergence evidence."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

from dpht.figures.scene import _save

FLOOR = 1e-6  # relative errors below this are drawn at it (a log axis has no zero)


def _by_knob(rows: list[dict]) -> dict:
    grouped: dict[str, list[dict]] = {}
    for r in rows:
        grouped.setdefault(r["knob"], []).append(r)
    return grouped


def knob_curves(rows: list[dict], png, judged) -> None:
    """One panel per knob: largest headline error (relative) against cost (s), settings labelled,
    the default ringed and the reference drawn as a square at the floor."""
    grouped = _by_knob(rows)
    n = len(grouped)
    cols = min(4, n)
    nrows = math.ceil(n / cols)
    fig = Figure(figsize=(3.4 * cols, 2.9 * nrows))
    axes = np.atleast_1d(fig.subplots(nrows, cols)).ravel()
    for ax, (name, mine) in zip(axes, grouped.items()):
        cost = [r["cost_s"] for r in mine]
        error = [max(judged(r), FLOOR) for r in mine]
        ax.plot(cost, error, marker="o", color="tab:blue")
        for r, c, e in zip(mine, cost, error):
            ax.annotate(r["label"], (c, e), fontsize=7, xytext=(3, 3), textcoords="offset points")
            if r["default"]:
                ax.plot(c, e, marker="o", markersize=11, fillstyle="none", color="tab:red")
            if r["reference"]:
                ax.plot(c, e, marker="s", color="black")
        ax.set(xscale="log", yscale="log", title=name, xlabel="wall time (s)", ylabel="headline error")
        # Labels at 1, 2 and 5 times powers of ten: matplotlib's own labelled every minor tick of a
        # narrow cost range, on top of each other.
        ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.title.set_fontsize(9)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle("error against cost, one knob at a time (red ring: default; square: reference)", fontsize="small")
    fig.tight_layout()
    _save(fig, png)


def pareto(rows: list[dict], png, judged, tolerance: float) -> None:
    """Every setting but the references: headline error against wall time, one marker per knob,
    the tolerance as a line."""
    fig = Figure(figsize=(7.5, 5.0))
    ax = fig.subplots()
    markers = "osD^v<>pPX*h"
    for (name, mine), marker in zip(_by_knob(rows).items(), markers * 4):
        shown = [r for r in mine if not r["reference"]]
        if shown:
            ax.plot([r["cost_s"] for r in shown], [max(judged(r), FLOOR) for r in shown], marker, label=name,
                    linestyle="none", alpha=0.8)  # fmt: skip
    ax.axhline(tolerance, color="grey", linestyle="--", linewidth=1)
    ax.text(ax.get_xlim()[0], tolerance, f" {tolerance:.1%}", va="bottom", fontsize=8, color="grey")
    ax.set(xscale="log", yscale="log", xlabel="wall time of the stages the knob re-runs (s)",
           ylabel="largest headline error (relative; splits absolute)", title="accuracy against cost, every setting")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    _save(fig, png)


def convergence(evidence: list[dict], png) -> None:
    """Changes between successive settings towards each reference: they shrink where it converged."""
    fig = Figure(figsize=(7.5, 5.0))
    ax = fig.subplots()
    for row in evidence:
        changes = np.maximum(np.asarray(row["changes"], float), FLOOR)
        ax.plot(np.arange(1, changes.size + 1) - changes.size, changes, marker="o", label=row["knob"])
    ax.set(yscale="log", xlabel="step towards the reference (0: last step, into the reference)",
           ylabel="change of the headline outputs (relative)", title="convergence of the references")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    _save(fig, png)
