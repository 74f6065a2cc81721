"""Opening the project's own HDF5 files: one check of existence, readability and format tag.

Every file the project writes carries a root attribute ``format = "dpht-<kind>-<version>"``; a
writer bumps the version when its layout changes, so a file from an older (or newer) version of the
project is told apart from a foreign or damaged one, and the message says what to do.
"""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np

from dpht.errors import DPHTError

_TAG = re.compile(r"(?P<kind>.+)-(?P<version>\d+)")


def format_problem(found, fmt: str, what: str) -> str | None:
    """Why a file whose format tag is ``found`` (None: no tag) is not ``what`` of format ``fmt``, or
    None when it is."""
    if isinstance(found, bytes):
        found = found.decode(errors="replace")
    if found == fmt:
        return None
    if found is None:
        return f"not {what}: it has no format tag (expected {fmt!r}), so it was not written by dpht"
    have, want = _TAG.fullmatch(str(found)), _TAG.fullmatch(fmt)
    if have and want and have["kind"] == want["kind"]:
        older = int(have["version"]) < int(want["version"])
        advice = ("re-run the stage that wrote it (delete the file, then run the workflow again)" if older
                  else "use the dpht version that wrote it, or update dpht")  # fmt: skip
        return (f"written by an {'older' if older else 'newer'} version of dpht (format {str(found)!r}; this "
                f"version reads {fmt!r}): {advice}")  # fmt: skip
    return f"not {what} (format {str(found)[:60]!r}, expected {fmt!r})"


def open_checked(path, fmt: str, what: str) -> h5py.File:
    """Open ``path`` read-only as ``what`` (e.g. "an HTC table") with format tag ``fmt``.

    A missing file, a file that is not HDF5, one of another format or of another version of the same
    format raises DPHTError naming the file and what was expected. Use the result as a context manager.
    """
    path = Path(path)
    if not path.is_file():
        raise DPHTError(f"{path} does not exist (expected {what})")
    try:
        f = h5py.File(path, "r")
    except OSError as error:
        raise DPHTError(f"{path} cannot be read as HDF5 ({error}); expected {what}") from None
    try:
        problem = format_problem(f.attrs.get("format"), fmt, what)
    except (OSError, KeyError, TypeError, ValueError) as error:  # a damaged attribute table
        problem = f"its format tag cannot be read ({error}); expected {what}"
    if problem:
        f.close()
        raise DPHTError(f"{path}: {problem}")
    return f


def check_values(path, dataset: str, values, *, low: float | None = None, high: float | None = None,
                 increasing: bool = False, what: str = "") -> None:
    """Raise DPHTError naming ``path`` and ``dataset`` unless every entry of ``values`` is finite and
    within [``low``, ``high``] (either may be None), and, with ``increasing``, strictly increasing
    along the last axis. ``what`` says what the values are (with their unit)."""
    values = np.asarray(values, dtype=float)
    expected = f"expected {what + ': ' if what else ''}finite values" + (
        f" in [{low:g}, {high:g}]" if low is not None and high is not None
        else f" >= {low:g}" if low is not None else f" <= {high:g}" if high is not None else "")  # fmt: skip
    bad = ~np.isfinite(values)
    if low is not None:
        bad |= values < low
    if high is not None:
        bad |= values > high
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise DPHTError(f"{path}: dataset {dataset} has {int(bad.sum())} bad entr{'y' if bad.sum() == 1 else 'ies'} "
                        f"(the first, at index {index}, is {float(values[index]):g}); {expected}; the file is damaged or "
                        "was not written by dpht: make it again (delete it and run the workflow again)")  # fmt: skip
    if increasing and values.size > 1 and not np.all(np.diff(values, axis=-1) > 0):
        raise DPHTError(f"{path}: dataset {dataset} is not strictly increasing ({what or 'a table axis'}); the file is "
                        "damaged or was not written by dpht: make it again (delete it and run the workflow again)")
