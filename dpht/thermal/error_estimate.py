"""An estimate of a thermal run's own numerical error (issue 15), at a small fraction of its cost.

Pure functions; the thermal stage (:func:`dpht.thermal.stage.estimate_errors`) feeds them. Three
parts, each a relative error of the run's headline outputs (total wall heat, wall heat by mode,
mean outlet temperature rise), summed by magnitude into the estimate:

- **thermal step** (Richardson): a few segments of the run, spread over it, are re-run from the
  run's own state with twice its step (every other frame). The step's error is first order (the
  geometry is held for a frame, DPHT paper Eq. 1 advances explicitly), so the run's error over a
  segment is (coarse - fine) / (2^1 - 1); the segments' error per second of wall heat, times the
  run's length, is the run's. The outlet rise follows the wall heat (in steady flow the heat taken
  from the wall leaves with the particles: Q = m' (h_out - h_in)), so its relative error is taken
  as the wall heat's.
- **tabulation** of the HTC tables: in distance, the table against the closure it tabulates (DPHT
  Eqs. 8-24) at the pair distances the run met in a few of its frames (:func:`tabulation_error`;
  most pairs sit near contact, where the HTC has a kink and linear interpolation is first order,
  so an average over the table would miss it); in temperature (smooth: second order) the table interpolated from every other node
  differs from the skipped nodes by four times the table's own midpoint error, the mean error
  over a cell is 2/3 of the midpoint's, so the mean signed relative error is (coarse - fine) / 6
  over the temperatures met (:func:`table_interpolation_error`). PFW's error enters the wall heat in proportion to PFW's share of it;
  PFP's, which acts through the bed, at most fully (a bound).
- **Monte Carlo** standard error of the RDF entries used (the tables' recorded ``stderr``, at the
  solid fraction the run reads): the relative standard error of the sum of the entries within the
  cutoff, weighted by how many pairs meet each distance (a shell, d^2, between particles; a
  constant near a wall). PW radiation enters by its share of the wall heat, PP radiation at most
  fully (a bound).
"""

from __future__ import annotations

import math

import numpy as np

ORDER = 1  # of the thermal step
RATIO = 2  # coarse step / run's step


def richardson(coarse, fine, ratio: float = RATIO, order: int = ORDER):
    """Error of ``fine`` (fine - exact) from the same output at a ``ratio`` times larger step."""
    return (np.asarray(coarse, float) - np.asarray(fine, float)) / (ratio**order - 1)


def time_step_part(segments, run_seconds: float, wall_heat_by_mode: dict) -> dict:
    """Relative errors of the wall heat (total and per mode) from re-run ``segments``: each a dict
    with ``coarse`` and ``fine`` wall heat per mode (J over the segment, in ``wall_heat_by_mode``'s
    order) and ``seconds`` (its simulated length). ``wall_heat_by_mode``: the run's J per mode."""
    modes = list(wall_heat_by_mode)
    error = sum(richardson(s["coarse"], s["fine"]) for s in segments)
    covered = sum(s["seconds"] for s in segments)
    scaled = error * run_seconds / covered
    total = sum(wall_heat_by_mode.values()) or math.inf  # no wall heat: no relative error of it
    return {"wall_heat": float(scaled.sum() / total), "wall_heat_J": float(scaled.sum()),
            "by_mode": dict(zip(modes, (scaled / total).tolist())), "segments": len(segments),
            "segment_seconds": covered}  # fmt: skip


def table_interpolation_error(values: np.ndarray, rows: np.ndarray | None = None, columns: np.ndarray | None = None,
                              axes=(0, 1)) -> float:
    """Mean signed relative error of bilinear interpolation in a table of ``values`` (distance x
    temperature), over the cells of ``rows`` and ``columns`` (boolean masks of the nodes met; all
    by default), in the directions ``axes`` (0: distance, 1: temperature): from the table
    interpolated from every other node (module docstring)."""
    v = np.asarray(values, float)
    rows = np.ones(v.shape[0], bool) if rows is None else rows
    columns = np.ones(v.shape[1], bool) if columns is None else columns
    total = 0.0
    for axis, mask in ((a, (rows, columns)[a]) for a in axes):
        w = np.moveaxis(v, axis, 0)
        other = columns if axis == 0 else rows
        w = w[:, other]
        if w.shape[0] < 3:
            continue
        mid = 0.5 * (w[:-2:2] + w[2::2]) - w[1:-1:2]
        keep = mask[1:-1:2][: mid.shape[0]]
        if keep.any():
            total += float(np.mean(mid[keep] / w[1:-1:2][keep]) / 6.0)
    return total


def tabulation_error(interpolated: np.ndarray, exact: np.ndarray) -> float:
    """Signed relative error of the sum of a table's interpolates at the pairs met against the sum
    of the closure it tabulates at the same pairs (each pair's heat is its conductance times its
    temperature difference; taken alike, so the sum of conductances stands for the heat)."""
    total = float(np.sum(exact))
    return float(np.sum(interpolated)) / total - 1.0 if total else 0.0


def rdf_relative_stderr(distance: np.ndarray, rdf: np.ndarray, stderr: np.ndarray, cutoff: float, shell: bool) -> float:
    """Relative standard error of the pair-weighted sum of the RDF entries within ``cutoff`` (radii),
    each entry's error independent; ``shell``: weight d^2 (pairs between particles), else 1."""
    inside = distance <= cutoff
    w = distance[inside] ** 2 if shell else np.ones(np.count_nonzero(inside))
    signal = float(np.sum(w * rdf[inside]))
    return float(np.sqrt(np.sum((w * stderr[inside]) ** 2)) / signal) if signal > 0 else 0.0


def combine(parts: dict, wall_heat_by_mode: dict) -> dict:
    """``error_estimate`` of the summary: per headline output the estimate (sum of the magnitudes
    of its parts) and the parts. ``parts``: {"time_step": time_step_part(...) or None, "pfp", "pfw",
    "pp_rdf", "pw_rdf": relative errors of the quantity each reads (tables) or None}."""
    total = sum(wall_heat_by_mode.values())
    share = {m: v / total if total else 0.0 for m, v in wall_heat_by_mode.items()}
    step = parts.get("time_step")
    contributions = {
        "time_step": abs(step["wall_heat"]) if step else 0.0,
        "pfw_table": abs(parts.get("pfw") or 0.0) * abs(share.get("pfw", 0.0)),
        "pfp_table_bound": abs(parts.get("pfp") or 0.0),
        "pw_rdf": abs(parts.get("pw_rdf") or 0.0) * abs(share.get("pw_radiation", 0.0)),
        "pp_rdf_bound": abs(parts.get("pp_rdf") or 0.0),
    }
    wall = math.fsum(contributions.values())
    by_mode = {m: (abs(step["by_mode"][m]) if step else 0.0) for m in wall_heat_by_mode}
    by_mode["pfw"] = by_mode.get("pfw", 0.0) + contributions["pfw_table"]
    by_mode["pw_radiation"] = by_mode.get("pw_radiation", 0.0) + contributions["pw_rdf"]
    return {
        "wall_heat": {"relative": wall, "J": wall * abs(total), "parts": contributions},
        "wall_heat_by_mode": {"relative_to_total": by_mode},
        "outlet_temperature": {"relative_to_rise": wall, "note": "as the wall heat (steady energy balance)"},
        "inputs": {k: v for k, v in parts.items() if k != "time_step"},
        "time_step": step,
    }
