"""Opening the project's own HDF5 files: one check of existence, readability and format tag."""

from __future__ import annotations

from pathlib import Path

import h5py

from dpht.errors import DPHTError


def open_checked(path, fmt: str, what: str) -> h5py.File:
    """Open ``path`` read-only as ``what`` (e.g. "an HTC table") with format tag ``fmt``.

    A missing file, a file that is not HDF5 or one of another format raises DPHTError naming the
    file and what was expected. Use the result as a context manager.
    """
    path = Path(path)
    if not path.is_file():
        raise DPHTError(f"{path} does not exist (expected {what})")
    try:
        f = h5py.File(path, "r")
    except OSError as error:
        raise DPHTError(f"{path} cannot be read as HDF5 ({error}); expected {what}") from None
    if f.attrs.get("format") != fmt:
        f.close()
        raise DPHTError(f"{path}: not {what} (attribute format != {fmt!r})")
    return f
