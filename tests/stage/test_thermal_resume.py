"""A thermal run resumed from any of its checkpoints writes the uninterrupted run's file bit for bit.

The run is made with a checkpoint after every frame, a copy kept of the work directory at each,
and then resumed from every one of them in turn (the State and segments of that checkpoint, nothing
else): each resumed run's thermal.h5 (every dataset and attribute) and summary (the timings aside)
must equal those of the run made in one go. On the tiny flowing tube the workflow's tests run
(its LIGGGHTS positions and walls as the example gallery keeps them, docs/examples/data), with the
automatic choice of integrator and each registered integrator forced; on a frozen bed stiff enough
for the implicit integrator to keep its multigrid hierarchy from frame to frame; and on a
travelling slice reusing its DEM record both ways (mirror, wrap). Each resume is a new stage run in
this process (a new setup, integrator and State, from the checkpoint's files only); resumes in a
new process after a kill or a signal are test_thermal_stage.py's.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht import config
from dpht.closures import htc
from dpht.thermal import checkpoint, integrators, modes, stage
from dpht.verification import scenes
from test_thermal_stage import read_all

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / ".test" / "config" / "config.yaml"
DATA = ROOT / "docs" / "examples" / "data"  # the tiny scene's DEM positions (16 frames, 20 ms apart) and walls
RDF = ROOT / "tables" / "rdf" / "shipped" / "eb1eb2bccb04.h5"  # the tiny scene's RDF table

# A slice travelling from z = 0.03 m down to 0.01 m in 11 frames, reusing the first 6 of the DEM
# record, past a wall hot above z = 0.015 m and cooler below.
SLICE = {"inlet_height": 0.03, "distance": 0.02, "velocity": 0.1, "record": 0.1}
SLOPED_WALL = {"heated_wall": {"temperature": "where(z > 0.015, 900.0, 400.0)"}, "adiabatic_wall": "adiabatic",
               "orifice": "adiabatic"}  # fmt: skip
# The last DEM frame held for 12 steps of 30 s (dt G / (m c_p) up to ~40 at 300 K): auto runs multirate
# on the first, then implicit (the geometry reused, no new network), one AMG hierarchy for all.
FROZEN = {"frame": -1, "duration": 360.0, "step": 30.0}
# The tube's 16 frames; the costlier multirate and implicit on every other one (8 frames of 40 ms).
SHORTER = {"multirate": {"frame_stride": 2}, "implicit": {"frame_stride": 2}}
CASES = {
    **{f"tube, {name}": {"integrator": name, **SHORTER.get(name, {})} for name in integrators.CHOICES},
    "frozen bed, auto": {"frozen_bed": FROZEN},
    "frozen bed, implicit": {"frozen_bed": FROZEN, "integrator": "implicit"},
    "slice, mirror": {"walls": SLOPED_WALL, "slice": {**SLICE, "frames": "mirror"}},
    "slice, wrap": {"walls": SLOPED_WALL, "slice": {**SLICE, "frames": "wrap"}},
}


@pytest.fixture(scope="module")
def tube(tmp_path_factory):
    return tiny_tube(tmp_path_factory.mktemp("resume"))


def tiny_tube(folder: Path):
    """(folder, thermal spec, HTC tables by kind) of the tiny scene in ``folder``: its config's
    thermal section with every mode on (as its screening decides) and the gallery's solid fractions
    (the measured near-wall one of its coarse wall is outside the RDF table)."""
    cfg = yaml.safe_load(TINY.read_text())
    cfg["thermal"]["rdf_table"] = str(RDF)
    s = config.thermal_spec(config.variant(config.validate(cfg), "base"))
    s["thermal"].update(modes=dict.fromkeys(modes.NAMES, True), solid_fraction={"bulk": 0.6, "near_wall": 0.5})
    for name in ("positions.h5", "walls.h5"):
        shutil.copy(DATA / name, folder / name)
    tables = {}
    for kind, table in scenes.htc_tables(s).items():
        tables[kind] = folder / f"{kind}.h5"
        htc.save_table(tables[kind], table)
    return folder, s, tables


def _run(tube, thermal: dict, name: str, checkpoints=stage.Checkpoints(), workdir=None) -> Path:
    folder, s, tables = tube
    s = json.loads(json.dumps(s))
    s["thermal"].update(thermal)
    out = folder / f"{name}.h5"
    stage.run(s, folder / "positions.h5", folder / "walls.h5", tables, out, rdf_table=RDF, workdir=workdir,
              checkpoints=checkpoints)  # fmt: skip
    return out


def _differences(files, reference) -> list[str]:
    """What differs between two :func:`read_all` results: datasets with their first differing row,
    attributes, summary entries."""
    (data, attrs, summary), (data0, attrs0, summary0) = files, reference
    found = [f"dataset {k} missing or extra" for k in set(data) ^ set(data0)]
    for name in sorted(set(data) & set(data0)):
        a, b = data[name], data0[name]
        if a.shape != b.shape:
            found.append(f"{name}: shape {a.shape} != {b.shape}")
        elif not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
            rows = np.flatnonzero(np.any((a != b) & ~(np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a != b,
                                         axis=tuple(range(1, a.ndim))))  # fmt: skip
            found.append(f"{name}: rows {rows.tolist()} (max |difference| {np.nanmax(np.abs(a - b.astype(a.dtype))):.3g})")
    found += [f"attribute {k}" for k in sorted(set(attrs) | set(attrs0)) if attrs.get(k) != attrs0.get(k)]
    found += [f"summary {k}: {summary.get(k)!r} != {summary0.get(k)!r}" for k in sorted(set(summary) | set(summary0))
              if summary.get(k) != summary0.get(k)]  # fmt: skip
    return found


@pytest.mark.parametrize("case", CASES)
def test_resumed_from_any_checkpoint_the_run_writes_the_uninterrupted_file(tube, case, monkeypatch):
    thermal = CASES[case]
    name = case.replace(", ", "_").replace(" ", "_")
    reference = read_all(_run(tube, thermal, name))
    # The same run saved after every frame, its work directory kept at each checkpoint.
    kept = tube[0] / f"{name}.kept"
    save = checkpoint.WorkDir.save

    def saving(work, state, segments, seconds):
        save(work, state, segments, seconds)
        shutil.copytree(work.folder, kept / f"{state.count:04d}", ignore=shutil.ignore_patterns(".*"))

    monkeypatch.setattr(checkpoint.WorkDir, "save", saving)
    every = _run(tube, thermal, f"{name}_every", stage.Checkpoints(frames=1))
    monkeypatch.undo()
    assert not _differences(read_all(every), reference)
    ran = {k: v for k, v in reference[2]["integrator"]["frames"].items() if v}
    assert case != "frozen bed, auto" or len(ran) > 1 and "implicit" in ran  # a change of integrator, one hierarchy
    saved = sorted(kept.iterdir())
    with h5py.File(every) as f:
        assert len(saved) == f["time"].size  # after each frame, the last (which only evaluates) included
    failed = {}
    for folder in saved:  # resumed from each
        work = tube[0] / f"{name}_from{folder.name}.work"
        shutil.copytree(folder, work)
        found = _differences(read_all(_run(tube, thermal, f"{name}_from{folder.name}", workdir=work)), reference)
        if found:
            failed[int(folder.name)] = found
    assert not failed, f"resumed after these frames, the run differs: {failed}"
