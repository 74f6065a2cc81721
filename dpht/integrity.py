"""Results of earlier runs checked by their content before the workflow plans its jobs.

Snakemake trusts any output file that exists and is newer than its inputs, and does not make a
missing file again when what was made from it is up to date. So every stage run of the workflow
records what it published in a *manifest* beside its log (``<log stem>.manifest.json``: the size
and SHA-256 of each declared output, and of each input file as it read it; :func:`recorded`).
When the workflow starts (``workflow/rules/common.smk``) :func:`check` reads every manifest under
``results/`` and ``tables/`` and finds

- an output that is missing, cut short or altered (its bytes differ from what its stage published),
- an input a later stage read that is now missing (a deleted intermediate: its manifest may be gone
  with its folder) or altered,

and, for the files of this run's plan, moves a damaged file aside to ``<name>.damaged`` and makes
the file a target of the run (rule ``all``), with one warning naming it: Snakemake then runs its
stage again, and every job downstream of it (their inputs are remade). Files of earlier runs
without a manifest are opened instead (:func:`damage`). Under a dry run (``snakemake -n``) the
check only reports: nothing is moved.

A manifest also records each file's inode, modification and change times (ns) as it was hashed.
The check hashes only a file whose size or one of these differs from its record (SHA-256 costs
about a second per GB): it trusts that a file the kernel reports unchanged holds the recorded
bytes. Writing a file changes its times, and resetting its modification time afterwards
(``touch -d``, ``os.utime``) sets its change time to the present, which no call sets back. What
the kernel does not see is not found this way: bytes changed on the disk under the file system,
a file system restored with its inodes and times, or a write in the same clock tick (a few ms) as
the stage's last one. ``DPHT_HASH_ALL=1`` in the environment (``dpht run --hash-all``) hashes
every file.

The stages that keep a work copy (DEM, thermal) publish it again in seconds when it is valid for
their key; the published file is a copy, never a hard link, so damage to it never reaches the work
copy (:func:`dpht.util.files.publish`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from stat import S_ISREG
from typing import TYPE_CHECKING

import h5py

from dpht.util.files import write_text

if TYPE_CHECKING:  # the stage processes import this module for recorded(), without the plan
    from dpht.plan import Plan

MANIFEST_SUFFIX = ".manifest.json"
MANIFEST_FORMAT = "dpht-manifest-1"
DAMAGED_SUFFIX = ".damaged"
# Files of each stage run that are opened when no manifest records them (results of runs made before
# manifests were written).
CHECKED = {
    "geometry": ("walls.h5", "geometry.json"),
    "dem": ("positions.h5", "summary.json"),
    "pfp": ("",),
    "pfw": ("",),
    "rdf": ("",),
    "screening": ("screening.json",),
    "thermal": ("thermal.h5", "summary.json"),
    "segment": ("thermal.h5", "summary.json", "handover.h5"),
}


HASH_ALL = "DPHT_HASH_ALL"  # environment: "1" hashes every recorded file (module docstring)
_STAT = ("inode", "mtime_ns", "ctime_ns")  # with the size: a file unchanged by the kernel's account


def digest(file) -> str:
    """SHA-256 of the bytes of ``file``."""
    with open(file, "rb") as stream:
        return hashlib.file_digest(stream, "sha256").hexdigest()


def _stat(st: os.stat_result) -> dict:
    return {"inode": st.st_ino, "mtime_ns": st.st_mtime_ns, "ctime_ns": st.st_ctime_ns}


def hash_all() -> bool:
    """Whether the environment asks the check to hash every file (:data:`HASH_ALL`)."""
    return os.environ.get(HASH_ALL) == "1"


def manifest_path(log) -> Path:
    """The manifest of the stage run whose log is ``log``: ``dir/name.log`` -> ``dir/name.manifest.json``."""
    log = Path(log)
    return log.with_name(log.stem + MANIFEST_SUFFIX)


def _files(paths: dict) -> list[str]:
    """The file paths among a rule's named inputs or outputs (a name may hold a list)."""
    found = []
    for value in paths.values():
        found += [str(v) for v in value] if isinstance(value, (list, tuple)) else [str(value)]
    return found


def _record(file) -> dict:
    """Size, SHA-256 and the stat fields of ``file``, those taken before its bytes are read (a
    write while it is hashed leaves a record that the check hashes again)."""
    with open(file, "rb") as stream:
        st = os.fstat(stream.fileno())
        return {"size": st.st_size, "sha256": hashlib.file_digest(stream, "sha256").hexdigest(), **_stat(st)}


def _records(files) -> dict[str, dict]:
    return {f: _record(f) for f in files if os.path.isfile(f)}


def _companions(outputs: list[str], since: float) -> list[str]:
    """Files a stage wrote beside its declared outputs since ``since`` (a figure's CSV and JSON, the
    geometry's zone STLs): in the outputs' folders, not hidden, not logs nor manifests. Not in the
    shared table folders (tables/), where other runs write."""
    found = set()
    for folder in {os.path.dirname(f) for f in outputs}:
        if Path(folder).parts[:1] == ("tables",) or not os.path.isdir(folder):
            continue
        for entry in os.scandir(folder):
            name = entry.name
            if (entry.is_file(follow_symlinks=False) and not name.startswith(".") and entry.stat().st_mtime >= since
                    and not name.endswith((".log", MANIFEST_SUFFIX, DAMAGED_SUFFIX))):  # fmt: skip
                found.add(os.path.join(folder, name))
    return sorted(found - set(outputs))


@contextlib.contextmanager
def recorded(stage: str, log, inputs: dict, outputs: dict):
    """``with recorded(...):`` run a stage; once it has succeeded its manifest (next to ``log``)
    records its declared outputs, the files it wrote beside them and the inputs as they were when it
    started. The manifest of an earlier run is removed first, so a failed run leaves none that
    names files it did not write."""
    manifest = manifest_path(log)
    manifest.unlink(missing_ok=True)
    read = _records(_files(inputs))
    since = time.time() - 1.0  # file times may be coarser than the clock
    yield
    written = _files(outputs)
    record = {"format": MANIFEST_FORMAT, "stage": stage, "inputs": read, "outputs": _records(written),
              "companions": _records(_companions(written, since))}  # fmt: skip
    write_text(manifest, json.dumps(record, indent=1, sort_keys=True) + "\n")


def damage(file: Path) -> str | None:
    """Why ``file`` cannot be used (it cannot be read, or says it is incomplete), or None; for
    files no manifest records."""
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


def _difference(file: Path, record: dict, hashes: dict, trust_stat: bool) -> str | None:
    """How ``file`` differs from its ``record`` (size and SHA-256), or None. With ``trust_stat`` a
    file whose size and stat fields are those recorded is not hashed (module docstring); ``hashes``
    keeps the check's digests, each file hashed once."""
    try:
        st = file.stat()
    except OSError:
        return "missing"
    if not S_ISREG(st.st_mode):
        return "missing"
    if st.st_size < record["size"]:
        return f"cut short ({st.st_size} of {record['size']} bytes)"
    if st.st_size == record["size"] and trust_stat and all(record.get(k) == v for k, v in _stat(st).items()):
        return None
    if st.st_size != record["size"]:
        return "altered (its bytes differ from those its stage recorded)"
    if file not in hashes:
        hashes[file] = digest(file)
    if hashes[file] != record["sha256"]:
        return "altered (its bytes differ from those its stage recorded)"
    return None


@dataclass(frozen=True)
class Finding:
    """A file of an earlier run that cannot be trusted, and why."""

    file: str  # as the manifests name it: relative to the working directory, or absolute
    problem: str  # "missing", "cut short (...)", "altered (...)", or why it cannot be read
    read_by: str | None = None  # the stage run (its manifest's name) that read the missing file
    made_from: str | None = None  # for an output made from a source file that changed since: that file
    remake: str | None = None  # for a file written beside a declared output: that output, made again

    def warning(self, remade: bool, dry_run: bool) -> str:
        if self.made_from:
            what = f"{self.file} was made from {self.made_from}, which has changed since"
        elif self.problem == "missing":
            what = f"{self.file} is missing" + (f" (read by the run of {self.read_by})" if self.read_by else "")
        else:
            what = f"{self.file} is damaged: {self.problem}"
        if not remade:
            return f"dpht: warning: {what}; not a file of this run's plan, left as it is"
        again = f"it and {self.remake}" if self.remake else "it"
        if dry_run:
            return f"dpht: warning: {what}; a run (not a dry run) makes {again} again, and everything that reads it"
        aside = "" if self.problem == "missing" else f"; moved to {Path(self.file).name}{DAMAGED_SUFFIX}"
        return f"dpht: warning: {what}{aside}; this run makes {again} again, and then everything that reads it"


def _manifests(root: Path) -> list[tuple[Path, dict]]:
    found = []
    for folder in ("results", "tables"):
        for manifest in sorted((root / folder).rglob(f"*{MANIFEST_SUFFIX}")):
            if "work" in manifest.relative_to(root).parts:
                continue
            try:
                record = json.loads(manifest.read_text())
            except (OSError, ValueError):
                continue  # its outputs are then opened like those of runs without a manifest
            if record.get("format") == MANIFEST_FORMAT:
                found.append((manifest, record))
    return found


def findings(plan: Plan, root: Path = Path("."), hash_all: bool = False) -> list[Finding]:
    """Every file of an earlier run under ``root`` that is missing, cut short, altered or cannot be
    read, by the manifests of the stage runs (the newest record of a file counts), and by opening
    the stage runs' files of ``plan`` that no manifest records. The outputs of a run one of whose
    source files (a file no stage writes: a shipped table, a file the config names) has changed
    since it read it are found too. Only files whose stat changed are hashed, unless ``hash_all``."""
    from dpht.plan import path

    manifests = sorted(_manifests(root), key=lambda m: m[0].stat().st_mtime)
    published = {file: what for _, record in manifests for file, what in record["outputs"].items()}
    found, seen, hashes = [], set(), {}

    def difference(file: str, record: dict) -> str | None:
        return _difference(root / file, record, hashes, trust_stat=not hash_all)

    def add(finding: Finding) -> None:
        if finding.file not in seen:
            seen.add(finding.file)
            found.append(finding)

    for manifest, record in manifests:
        run = str(manifest.relative_to(root)).removesuffix(MANIFEST_SUFFIX)
        for file, what in record["inputs"].items():
            if file in published and (root / file).is_file():
                continue  # its producer's record tells (a new run of it may have changed it, rightly)
            if (problem := difference(file, what)) is None:
                continue
            if file in published or problem == "missing" or _made_by(plan, file):
                add(Finding(file, problem, read_by=run))  # a result: made again, then this run again
            else:
                for output in record["outputs"]:
                    add(Finding(output, "made from a changed file", made_from=file))
    for file, what in published.items():
        if (problem := difference(file, what)) is not None:
            add(Finding(file, problem))
    for _, record in manifests:
        for file, what in record.get("companions", {}).items():
            if (problem := difference(file, what)) is not None:
                add(Finding(file, problem, remake=next(iter(record["outputs"]), None)))
    for run in plan.runs.values():
        for name in CHECKED.get(run.stage, ()):
            file = path(run.stage, run.key, name)
            if file not in published and (root / file).is_file() and (reason := damage(root / file)) is not None:
                add(Finding(file, reason))
    return found


def _made_by(plan: Plan, file: str, targets=None) -> bool:
    """Whether a job of ``plan`` makes ``file`` (a path relative to the working directory);
    ``targets``: ``plan.targets()``, if known."""
    parts = Path(file).parts
    if Path(file).is_absolute() or not parts:
        return False  # a shipped table or a file the config names: a source, not a result
    if parts[0] == "tables":
        return Path(file).stem in plan.runs
    if parts[0] == "results" and len(parts) > 2 and parts[2] in plan.runs:
        return True
    return file in (plan.targets() if targets is None else targets) or (parts[0] == "results" and len(parts) > 2 and parts[1] == plan.name)


def dry_run(workflow) -> bool:
    """Whether Snakemake was asked for a dry run (``-n``). ``workflow.dryrun`` is known only once
    the jobs run, after the Snakefile is read, so the command line is read too."""
    if workflow.dryrun:
        return True
    import sys

    from snakemake.cli import get_argument_parser

    try:
        return bool(get_argument_parser().parse_known_args(sys.argv[1:])[0].dryrun)
    except (SystemExit, AttributeError):  # not the snakemake command (the API, a test)
        return False


def check(plan: Plan, root: Path = Path("."), dry_run: bool = False,
          hash_all: bool = False) -> tuple[list[str], list[str]]:  # fmt: skip
    """The files of ``plan`` to make again (targets for rule ``all``) and one warning per file of
    :func:`findings` that the plan makes, or that is damaged. The plan's damaged files are moved to
    ``<name>.damaged`` first, unless ``dry_run`` (then nothing is changed)."""
    targets, warnings, made = [], [], set(plan.targets())
    for finding in findings(plan, root, hash_all):
        target = finding.remake or finding.file
        remade = _made_by(plan, target, made)
        if not remade and finding.problem == "missing":
            continue  # a result of another configuration, deleted: none of this run's business
        warnings.append(finding.warning(remade, dry_run))
        if not remade:
            continue
        file = root / finding.file
        if not dry_run and file.is_file():
            os.replace(file, file.with_name(file.name + DAMAGED_SUFFIX))
        if not dry_run and finding.remake:  # intact, but made again with what is beside it
            (root / finding.remake).unlink(missing_ok=True)
        if target not in targets:
            targets.append(target)
    return targets, warnings
