"""Files that are either complete or absent, work directories with a lock, and published results.

A stage's declared outputs (what Snakemake tracks) are written under a temporary name and renamed
when complete, so a file at its final name is never partial, whatever kills the stage. Expensive
results are kept in the stage's work directory (``results/<stage>/<key>/work/``, never a declared
output) and *published* to the declared name as a verified copy: Snakemake deletes the declared outputs
of a job it runs again (an interrupted job, a job whose input changed, a failed job), but the work
copy survives, and the stage publishes it again in a second when it is still valid for its key.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import uuid
from pathlib import Path

from dpht.errors import DPHTError


def partial_path(path) -> Path:
    """A temporary sibling of ``path`` (same folder, same suffix, so writers that look at the
    suffix still work): ``dir/name.ext`` -> ``dir/.name.<random>.part.ext``."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{uuid.uuid4().hex[:8]}.part{path.suffix}")


@contextlib.contextmanager
def replacing(path):
    """``with replacing(p) as tmp:`` write ``tmp``; it replaces ``p`` when the block succeeds and
    is removed when it fails."""
    path = Path(path)
    tmp = partial_path(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (never a half-written file at ``path``)."""
    with replacing(path) as tmp:
        tmp.write_text(text)


@contextlib.contextmanager
def staging(folder):
    """``with staging(d) as tmp:`` write files into the fresh folder ``tmp`` (inside ``d``); when
    the block succeeds each is moved into ``d`` (replacing what is there), else all are removed."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".staging.{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        yield tmp
        for item in sorted(tmp.iterdir()):
            target = folder / item.name
            if item.is_dir():
                shutil.rmtree(target, ignore_errors=True)
            os.replace(item, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def publish(source, target) -> None:
    """Make ``target`` a complete copy of ``source``, atomically, with the current time as
    modification time (Snakemake compares it with its inputs' times). A copy, never a hard link: a
    published file damaged in place must not damage the work copy it is published again from. The
    copy is read back and compared with the source before it takes the target's name."""
    source, target = Path(source), Path(target)
    with replacing(target) as tmp:
        shutil.copyfile(source, tmp)
        if _sha256(tmp) != _sha256(source):
            raise DPHTError(f"copying {source} to {target} gave a different file (a failing disk?); nothing was published")
        os.utime(tmp)


def _sha256(path: Path) -> bytes:
    with open(path, "rb") as stream:
        return hashlib.file_digest(stream, "sha256").digest()


class WorkdirLock:
    """An exclusive lock on a stage's work directory, held while the stage runs. Child processes
    given its ``fd`` (``pass_fds``) hold it too, so an orphaned LIGGGHTS still does."""

    def __init__(self, workdir, name: str, what: str):
        self.path = Path(workdir) / name
        self.what = what

    def __enter__(self) -> "WorkdirLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = self.path.read_text().strip() or "?"
            os.close(self.fd)
            raise DPHTError(
                f"{self.what} work directory {self.path.parent} is in use by another run (lock {self.path}, "
                f"taken by pid {holder}); wait for it, or end that process first"
            ) from None
        os.ftruncate(self.fd, 0)
        os.write(self.fd, str(os.getpid()).encode())
        return self

    def __exit__(self, *exc) -> None:
        os.close(self.fd)


_CLAIMED_LOGS: dict[Path, int] = {}  # lock descriptors of the logs this process writes, held until it exits


def claim_log(path) -> Path:
    """The file this process should log a stage attempt to, given the rule's log ``path``.

    Snakemake removes a job's log when it runs the job again; the log's earlier attempts are kept by
    a hidden hard link beside it (``.<name>.attempts``), from which a removed log is restored, so the
    new attempt is appended after them. Another live process that claimed the same log (a second
    ``snakemake --nolock`` running the same job) holds its lock: this attempt then logs to
    ``<stem>.<pid><suffix>`` beside it instead, never into the other run's log.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.absolute() not in _CLAIMED_LOGS:
        fd = os.open(path.with_name(f".{path.name}.lock"), os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return path.with_name(f"{path.stem}.{os.getpid()}{path.suffix}")
        _CLAIMED_LOGS[path.absolute()] = fd
    history = path.with_name(f".{path.name}.attempts")
    if not path.exists() and history.exists():
        os.link(history, path)  # the earlier attempts, back under the log's name
    else:
        path.touch()
        if history.exists() and os.path.samefile(history, path):
            return path
        with replacing(history) as tmp:
            os.link(path, tmp)
    return path


def no_nan(data):
    """``data`` with NaN floats as None (JSON has no NaN)."""
    if isinstance(data, dict):
        return {k: no_nan(v) for k, v in data.items()}
    if isinstance(data, list):
        return [no_nan(v) for v in data]
    return None if isinstance(data, float) and data != data else data


def write_json(path, data) -> None:
    write_text(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


@contextlib.contextmanager
def staged(outputs: dict):
    """Paths for a stage's outputs (all in one folder) in a staging folder, moved into place
    together with whatever else the stage wrote there once it succeeds (:func:`staging`)."""
    (folder,) = {Path(p).parent for p in outputs.values()}
    with staging(folder) as tmp:
        yield {name: tmp / Path(p).name for name, p in outputs.items()}
