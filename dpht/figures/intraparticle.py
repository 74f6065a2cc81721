"""Figures of resolved intra-particle conduction: the cooled sphere (ParScale Fig. 2), the
convergence of the scheme, and the Biot-number sweep of lumped against resolved particles."""

from __future__ import annotations

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def cooled_sphere(path, times, nodes, profiles, exact, T0: float) -> None:
    """T / T0 against r / a: the resolved nodes (symbols) and the exact series ``exact(x, t)`` (lines)."""
    fig, ax = plt.subplots(figsize=(5.5, 4.0))
    x = np.linspace(0.0, 1.0, 201)
    every = max(1, (len(nodes) - 1) // 10)
    for t, T in zip(times, profiles):
        (line,) = ax.plot(x, exact(x, t) / T0, lw=1.2)
        ax.plot(nodes[::every], T[::every] / T0, "o", ms=4, mfc="none", color=line.get_color(), label=f"t = {t:g} s")
    ax.set_xlabel("r / a")
    ax.set_ylabel("T / T0")
    ax.set_title("Cooled sphere (ParScale Table 1): resolved (o) and Crank's series (lines)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def convergence(path, rows, shells: int, step: float) -> None:
    """Mean relative error against the node spacing and against the time step (log-log), with slopes 4 and 1."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(9.0, 3.8))
    for ax, parameter, slope, label in ((left, "shells", 4, "node spacing a / n"), (right, "step", 1, "time step (s)")):
        picked = [r for r in rows if r["parameter"] == parameter]
        x = np.array([1.0 / r["value"] if parameter == "shells" else r["value"] for r in picked])
        y = np.array([r["mean_relative_error"] for r in picked])
        ax.loglog(x, y, "o-", label="mean relative error")
        ax.loglog(x, [r["max_relative_error"] for r in picked], "s--", ms=4, label="max relative error")
        ax.loglog(x, y[-1] * (x / x[-1]) ** slope, ":", color="grey", label=f"order {slope}")
        ax.axhline(1e-5, color="red", lw=0.8, label="1e-5")
        ax.set_xlabel(label)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.legend(fontsize=8)
    left.set_ylabel("relative error of T")
    left.set_title(f"steps {step:g} and {step / 2:g} s, extrapolated", fontsize=9)
    right.set_title(f"{shells} shells", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def biot_sweep(path, curves: dict, thresholds: dict, gas: dict) -> None:
    """Relative wall-heat difference |lumped - resolved| / resolved against the Biot number, one
    curve per series (``curves``: name -> (Bi, difference); ``thresholds``: name -> {level: Bi or
    None}); ``gas`` the convection of the "gas" series (W/(m2 K), K)."""
    labels = {"stagnant": "stagnant gas (conduction modes)",
              "gas": f"gas stream, h = {gas['coefficient']:g} W/(m2 K) at {gas['gas_temperature']:g} K"}  # fmt: skip
    fig, ax = plt.subplots(figsize=(6.0, 4.3))
    for level in next(iter(thresholds.values())):
        ax.axhline(level, color="grey", lw=0.8, ls=":")
    for number, (name, (biot, difference)) in enumerate(curves.items()):
        (line,) = ax.loglog(biot, difference, "o-", label=labels.get(name, name))
        for level, crossing in thresholds[name].items():
            if crossing is not None:  # the first series' labels below right of the crossing, the others' above left
                ax.plot([crossing], [level], "x", color=line.get_color(), ms=8)
                ax.annotate(f"{level:.0%} at Bi = {crossing:.2g}", (crossing, level), fontsize=7, color=line.get_color(),
                            xytext=(6, -12) if number == 0 else (-78, 5), textcoords="offset points")  # fmt: skip
    ax.axvline(0.1, color="red", lw=0.8, label="ParScale Bi_crit ~ 0.1")
    ax.axvline(0.01, color="orange", lw=0.8, label="ParScale, dense beds ~ 0.01")
    ax.set_xlabel("Biot number Bi = G d_p / (pi d_p^2 k_p)")
    ax.set_ylabel("relative wall-heat difference, lumped vs resolved")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
