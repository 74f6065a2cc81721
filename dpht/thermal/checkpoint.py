"""The thermal stage's checkpoints: its work directory (:class:`WorkDir`), the segment files its
rows are written into (:class:`Segments`) and how often the State is saved (:class:`Checkpoints`).

Rows are written into *segment* files in the stage's work directory; every
``thermal.checkpoint_frames`` frames or ``thermal.checkpoint_minutes`` minutes, whichever comes
first, the segment is closed and the State (:mod:`dpht.thermal.state`) saved (``checkpoint.h5``,
replaced atomically). A run killed at any point restarts from the last checkpoint and writes the
same rows: the State is all the loop carries, so the result is bitwise that of an uninterrupted
run. When the last frame is done the segments are copied, compressed chunks as they are, into
``thermal.h5`` in the work directory, which is then published as the stage's output (a hard link,
:func:`dpht.util.files.publish`): a file at the output's name is always complete, and a later run
of the same inputs (the same :func:`fingerprint`) publishes it again instead of recomputing it.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.defaults import default
from dpht.dem.dumps import CONTENT_DIGEST, PositionsFile
from dpht.thermal.model import ThermalModel
from dpht.thermal.output import Row, ThermalWriter
from dpht.thermal.state import State
from dpht.util.files import partial_path, replacing


@dataclass(frozen=True)
class Checkpoints:
    """How often the state is saved: after ``frames`` frames or ``minutes`` of computing, whichever
    comes first (``thermal.checkpoint_frames``, ``thermal.checkpoint_minutes``, the schema's defaults
    where not given; not part of the stage key, since they do not change the result)."""

    frames: int = default("thermal.checkpoint_frames")
    minutes: float = default("thermal.checkpoint_minutes")


class WorkDir:
    """The work directory of one thermal run: ``rows.<first frame>.h5`` segments, ``checkpoint.h5``
    (the State after the segments' rows, and the list of segments) and, once done, the complete
    ``thermal.h5``. Everything in it belongs to one ``fingerprint`` of the inputs (spec, positions
    frames, walls, tables); a checkpoint of other inputs is discarded."""

    CHECKPOINT, FINAL = "checkpoint.h5", "thermal.h5"

    def __init__(self, folder, fingerprint: str):
        self.folder, self.fingerprint = Path(folder), fingerprint
        self.folder.mkdir(parents=True, exist_ok=True)

    @property
    def final(self) -> Path:
        return self.folder / self.FINAL

    def segment(self, first: int) -> Path:
        return self.folder / f"rows.{first:08d}.h5"

    def complete(self) -> dict | None:
        """The stored summary of the complete output of these inputs, if there is one."""
        return _complete(self.final, self.fingerprint)

    def restore(self, model: ThermalModel, n: int) -> tuple[State, list[tuple[int, int]], float]:
        """(State, [(first frame, rows) of each segment], seconds spent) of the last checkpoint of
        these inputs, or the initial state; files that the checkpoint does not list are removed."""
        state, segments, seconds = State.initial(model, n), [], 0.0
        try:
            with h5py.File(self.folder / self.CHECKPOINT, "r") as f:
                if f.attrs["fingerprint"] == self.fingerprint:
                    segments = [tuple(s) for s in json.loads(f.attrs["segments"])]
                    previous = (f["previous_positions"][...], f["previous_image"][...]) if "previous_image" in f else None
                    shells = f["shells"][...] if "shells" in f else None
                    if (shells is None) == (model.shells is None):  # the same decision of auto as before
                        carried = {}

                        def read(key, item):
                            if isinstance(item, h5py.Dataset):
                                carried[key] = item[...]

                        f["integrator"].visititems(read)
                        frames_by, clamped = json.loads(f.attrs["carried"])
                        state = State(int(f.attrs["count"]), f["h"][...], float(f.attrs["wall_energy"]),
                                      float(f.attrs["recycled_energy"]), previous, shells=shells,
                                      convected_energy=float(f.attrs["convected_energy"]), frames_by=frames_by,
                                      clamped=clamped, integrator={**json.loads(f.attrs["integrator"]), **carried})  # fmt: skip
                        seconds = float(f.attrs["seconds"])
                    else:
                        segments = []
        except (OSError, KeyError, ValueError):
            pass
        if not all(_rows(self.segment(first)) == rows for first, rows in segments):
            state, segments, seconds = State.initial(model, n), [], 0.0  # a damaged segment: start again
        keep = {self.segment(first).name for first, _ in segments} | {self.CHECKPOINT, self.FINAL, LOCK}
        for path in self.folder.iterdir():
            if path.name not in keep:
                path.unlink()
        return state, segments, seconds

    def save(self, state: State, segments: list[tuple[int, int]], seconds: float) -> None:
        """Replace the checkpoint (atomically): the State after the rows of ``segments``."""
        with replacing(self.folder / self.CHECKPOINT) as tmp, h5py.File(tmp, "w") as f:
            f.create_dataset("h", data=state.h)
            if state.shells is not None:
                f.create_dataset("shells", data=state.shells)
            if state.previous is not None:
                f.create_dataset("previous_positions", data=state.previous[0])
                f.create_dataset("previous_image", data=state.previous[1])
            arrays = {k: v for k, v in state.integrator.items() if isinstance(v, np.ndarray)}
            group = f.create_group("integrator")  # arrays at their keys ("implicit/amg_T"), the rest in JSON
            for key, value in arrays.items():
                group.create_dataset(key, data=value)
            f.attrs.update(fingerprint=self.fingerprint, count=state.count, wall_energy=state.wall_energy,
                           recycled_energy=state.recycled_energy, convected_energy=state.convected_energy,
                           segments=json.dumps(segments), seconds=seconds, carried=json.dumps([state.frames_by, state.clamped]),
                           integrator=json.dumps({k: v for k, v in state.integrator.items() if k not in arrays}))  # fmt: skip

    def clear(self) -> None:
        """Remove the segments and the checkpoint (once the complete output exists)."""
        for path in self.folder.glob("rows.*.h5"):
            path.unlink()
        (self.folder / self.CHECKPOINT).unlink(missing_ok=True)


LOCK = ".thermal.lock"


def _rows(segment: Path) -> int | None:
    try:
        with h5py.File(segment, "r") as f:
            return int(f.attrs["rows"])
    except (OSError, KeyError, ValueError):
        return None


def _complete(path: Path, fingerprint: str) -> dict | None:
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("complete") and f.attrs.get("fingerprint") == fingerprint:
                return json.loads(f.attrs["summary"])
    except (OSError, KeyError, ValueError):
        pass
    return None


def fingerprint(spec: dict, positions_h5, inputs) -> str:
    """Digest of what a thermal run computes from: the spec, the positions file's frames (its
    content digest where the DEM stage stored one) and the bytes of the other input files."""
    h = hashlib.sha256(json.dumps(spec, sort_keys=True).encode())
    with PositionsFile(positions_h5) as dem:
        digest = dem.attrs.get(CONTENT_DIGEST)
    for path in ([] if digest else [positions_h5]) + [p for p in inputs if p is not None]:
        with open(path, "rb") as stream:
            h.update(hashlib.file_digest(stream, "sha256").digest())
    h.update(str(digest).encode())
    return h.hexdigest()


SEGMENT_FORMAT = "dpht-thermal-segment-1"  # the output's layout, with rows 0..rows-1 of frames first..


class Segments:
    """The rows of a run, written into *segment* files of the work directory (module docstring):
    one is open from its first row until a checkpoint is due (``rows`` rows written, ``minutes``
    of computing since it opened, or a signal), then closed with the State after its rows saved.
    ``done`` lists the closed segments, ``(first frame, rows)``; as a context, a segment left open
    by an error is removed (its rows are lost, the checkpoint before them stays)."""

    def __init__(self, work: WorkDir, done: list, *, ids, dem_frames, n_elements: int, attrs: dict, rows: int, minutes: float):
        self.work, self.done, self.rows, self.minutes = work, done, rows, minutes
        self.ids, self.dem_frames, self.n_elements, self.attrs = ids, dem_frames, n_elements, attrs
        self.writer, self.first, self.opened = None, None, time.monotonic()

    def write(self, count: int, row: Row) -> None:
        """Write the row of thermal frame ``count``, opening a segment at it if none is open."""
        if self.writer is None:
            self.first = count
            self.writer = ThermalWriter(partial_path(self.work.segment(count)), ids=self.ids, n_elements=self.n_elements,
                                        dem_frames=self.dem_frames[count : count + self.rows], attrs=self.attrs)  # fmt: skip
        self.writer.write(count - self.first, row)

    def due(self, count: int, signal) -> bool:
        """Whether a checkpoint is due after the rows up to ``count`` (exclusive)."""
        full = count - self.first == self.writer.file["time"].shape[0]
        return bool(full or signal or time.monotonic() - self.opened >= 60.0 * self.minutes)

    def checkpoint(self, state: State, seconds: float) -> None:
        """Close the open segment (complete as a segment, under its name) and save ``state``, the
        State after its rows, with the list of segments and the computing time (s)."""
        rows = state.count - self.first
        self.writer.file.attrs.update(format=SEGMENT_FORMAT, first=self.first, rows=rows, complete=True)
        self.writer.close()
        self.writer.path.replace(self.work.segment(self.first))
        self.done.append((self.first, rows))
        self.work.save(state, self.done, seconds)
        self.writer, self.opened = None, time.monotonic()

    def __enter__(self) -> Segments:
        return self

    def __exit__(self, *exc) -> None:
        if self.writer is not None:  # an error or a second signal: the rows since the checkpoint are lost
            self.writer.close()
            self.writer.path.unlink(missing_ok=True)
            self.writer = None
