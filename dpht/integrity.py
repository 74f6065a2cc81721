"""Damaged results of earlier runs, found before the workflow plans its jobs.

Snakemake trusts any output file that exists and is newer than its inputs. A file cut short or
overwritten after it was written (a full disk while copying results back, an interrupted ``cp``
or ``rsync``, a truncation) would be read by every later job, each failing the same way. So when
the workflow starts (``workflow/rules/common.smk``) every HDF5 and JSON output of the plan's stage
runs that exists is opened; one that cannot be read, or that says it is incomplete, is moved aside
to ``<name>.damaged`` with a warning and made a target of the run, so Snakemake runs its stage again —
the DEM stage then publishes its intact work copy again or re-runs LIGGGHTS
(:func:`dpht.dem.liggghts.run_dem`), and stages downstream reuse their own work copies when the
regenerated file is the very one they read (the thermal stage compares content digests).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py

from dpht.plan import Plan, path

# Files of each stage run that are opened (the rules' outputs; figures are not checked: cheap to
# redo, and written only complete).
CHECKED = {
    "geometry": ("walls.h5", "geometry.json"),
    "dem": ("positions.h5", "summary.json"),
    "pfp": ("",),
    "pfw": ("",),
    "rdf": ("",),
    "screening": ("screening.json",),
    "thermal": ("thermal.h5", "summary.json"),
}
DAMAGED_SUFFIX = ".damaged"


def damage(file: Path) -> str | None:
    """Why ``file`` cannot be used (it cannot be read, or says it is incomplete), or None."""
    try:
        if file.suffix == ".json":
            json.loads(file.read_text())
            return None
        with h5py.File(file, "r") as h5:
            if not h5.attrs.get("complete", True):
                return "it says it is incomplete"
    except (OSError, ValueError) as error:
        if "unable to lock file" in str(error):  # open for writing elsewhere (HDF5 file locking): busy
            return None
        return str(error).splitlines()[0] if str(error) else type(error).__name__
    return None


def set_aside_damaged(plan: Plan, root: Path = Path(".")) -> dict[str, str]:
    """Move every damaged output of ``plan``'s stage runs under ``root`` to ``<name>.damaged``;
    returns {path relative to ``root``: warning} for the files moved. Snakemake does not make a
    missing file again when what was made from it is up to date, so the workflow adds these paths
    to its targets."""
    warnings = {}
    for key, run in plan.runs.items():
        for name in CHECKED.get(run.stage, ()):
            relative = path(run.stage, key, name)
            file = root / relative
            if not file.is_file():
                continue
            reason = damage(file)
            if reason is None:
                continue
            aside = file.with_name(file.name + DAMAGED_SUFFIX)
            os.replace(file, aside)
            warnings[relative] = (
                f"dpht: warning: {relative} is damaged ({reason}); moved to {aside.name}, so this run makes it "
                f"again (stage {run.stage}) and then everything that reads it"
            )
    return warnings
