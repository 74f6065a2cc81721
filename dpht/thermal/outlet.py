"""The thermal stage's record of what leaves a segment of a chain (:mod:`dpht.chain.outlet`, the
group ``outlet`` of thermal.h5): the crossings of its outlet plane, journalled as they happen in a
file beside the run's work directory (:class:`Journal`), so that a run resumed from a checkpoint
keeps the crossings before it and makes those after it again, bit for bit; or its particles at the
end of the run (a travelling slice).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpht.chain.outlet import BED, CROSSINGS, Record, crossed

_FIXED = 5  # journal columns before the nodes: frame, particle (negative: an upward crossing), x, y, h


class Journal:
    """The crossings of a run so far, appended to ``path`` as float64 rows ``(frame, particle, x, y,
    h, node enthalpies...)`` (an upward crossing: particle -1 - index, no enthalpy). Opened at the
    run's ``start`` frame (0, or the frame after its checkpoint): rows of later frames, and a row
    cut short by a kill, are dropped. ``length``: m, the periodic box along z (a jump up of more
    than half of it is a re-entry, not a crossing)."""

    def __init__(self, path, plane: float, length: float, shells: int, start: int):
        self.path, self.plane, self.length, self.width = Path(path), float(plane), float(length), _FIXED + shells
        rows = _read(self.path, self.width)
        keep = int(np.searchsorted(rows[:, 0], start, side="left")) if rows.size else 0
        with open(self.path, "ab") as f:
            f.truncate(keep * self.width * 8)
        self._file = open(self.path, "ab")

    def observe(self, frame: int, previous, positions: np.ndarray, h: np.ndarray, shells) -> None:
        """Record the crossings between the ``previous`` frame's positions (None: the first frame)
        and those of thermal frame ``frame``, with the enthalpies ``h`` (N,) J/kg and node
        enthalpies ``shells`` (N, K) or None the run holds then. A particle re-entering through the
        periodic boundary jumps up and crosses nothing."""
        if previous is None:
            return
        down, up, xy = crossed(previous, positions, self.plane, self.length)
        rows = np.zeros((down.size + up.size, self.width))
        rows[:, 0] = frame
        rows[: down.size, 1] = down
        rows[: down.size, 2:4] = xy
        rows[: down.size, 4] = h[down]
        if shells is not None:
            rows[: down.size, _FIXED:] = shells[down]
        rows[down.size :, 1] = -1 - up
        self._file.write(rows.tobytes())
        self._file.flush()  # in the page cache before the frame's checkpoint can be

    def rows(self) -> np.ndarray:
        """Every row journalled (read back from the file)."""
        if not self._file.closed:
            self._file.flush()
        return _read(self.path, self.width)

    def close(self, remove: bool = False) -> None:
        self._file.close()
        if remove:
            self.path.unlink(missing_ok=True)


def _read(path: Path, width: int) -> np.ndarray:
    try:
        data = np.fromfile(path, dtype=np.float64)
    except FileNotFoundError:
        return np.zeros((0, width))
    return data[: data.size // width * width].reshape(-1, width)


def journal_path(workdir) -> Path:
    """The journal of a run whose work directory is ``workdir``: beside it (the work directory keeps
    only the files of its own checkpoints)."""
    workdir = Path(workdir)
    return workdir.with_name(workdir.name + ".outlet")


def crossings(rows: np.ndarray, plane: float, times: np.ndarray, to_temperature, radius: float, shell_weight) -> Record:
    """The record of journalled ``rows`` (:class:`Journal`) of the plane z = ``plane``, ``times``
    the run's frame times (s), ``to_temperature`` the run's h -> T (K)."""
    upward = int(np.count_nonzero(rows[:, 1] < 0))
    rows = rows[rows[:, 1] >= 0]
    frame = rows[:, 0].astype(np.int64)
    shells = to_temperature(rows[:, _FIXED:]) if rows.shape[1] > _FIXED else np.zeros((rows.shape[0], 0))
    return Record(CROSSINGS, frame, np.asarray(times, dtype=np.float64)[frame], rows[:, 1].astype(np.int64),
                  rows[:, 2:4].copy(), to_temperature(rows[:, 4]), shells, np.asarray(shell_weight, dtype=np.float64),
                  float(radius), float(plane), upward)  # fmt: skip


def bed(positions: np.ndarray, h: np.ndarray, shells, frame: int, time: float, to_temperature, radius: float,
        shell_weight) -> Record:  # fmt: skip
    """The record of a run's particles at its end: ``positions`` (N, 3) m of its last frame (thermal
    frame ``frame`` at ``time`` s), ``h`` (N,) J/kg and ``shells`` (N, K) J/kg or None."""
    placed = np.flatnonzero(np.all(np.isfinite(positions[:, :2]), axis=1))
    nodes = to_temperature(shells[placed]) if shells is not None else np.zeros((placed.size, 0))
    return Record(BED, np.full(placed.size, frame, dtype=np.int64), np.full(placed.size, float(time)), placed.astype(np.int64),
                  np.asarray(positions[placed, :2], dtype=np.float64), to_temperature(h[placed]), nodes,
                  np.asarray(shell_weight, dtype=np.float64), float(radius))  # fmt: skip


