"""LIGGGHTS text dumps and the positions HDF5 file the thermal stage reads.

Text dumps are one file per step written by ``dump custom ... id x y z ix iy iz`` with
``dump_modify sort id``: 9 header lines (timestep, atom count, box bounds with boundary flags),
then one line per particle. A sheared box (LIGGGHTS' triclinic box with an xy tilt only, driven by
``fix deform ... xy erate ... remap v``) has the header ``BOX BOUNDS xy xz yz ...``, its bounds
lines the bounding box of the tilted cell and the tilt; the box is then the orthogonal one
[lo, hi) whose periodic image one period up in y lies ``tilt`` further along x, and a particle's
unwrapped position is its position plus ``ix Lx + iy tilt`` in x, ``iy Ly`` in y, ``iz Lz`` in z
(:func:`unwrapped`). Dump headers print the box with 6 significant digits: a reader that knows it
better (the run's thermo output, :class:`Box`) passes it to :func:`read_dump`, which checks it
against the header and uses it. A dump with non-finite positions or box bounds, duplicate or
non-integer ids, or (in :func:`write_positions`) more than :data:`MAX_LOST_FRACTION` of the particles
missing is refused with a message naming the file or step. :func:`write_positions` streams the
frames into one HDF5 file:

``/positions`` (n_frames, N, 3) float32|float64, m (NaN where a particle is lost);
``/image`` (n_frames, N, 3) int32 periodic image flags; ``/lost`` (n_frames, N) bool;
``/ids`` (N,) int64 sorted; ``/step`` (n_frames,) int64; ``/time`` (n_frames,) float64, s since
the first frame; ``/tilt`` (n_frames,) float64, m, the xy tilt of each frame, in files of a sheared
box only (absent: an orthogonal box). Root attributes: ``format``, ``radius`` (m), ``density`` (kg/m3), ``timestep``
(DEM step, s), ``dump_interval`` (steps), ``box_lo``/``box_hi`` (m), ``periodic`` (3 bools), a
JSON ``summary`` and, in files the DEM stage gathered, ``content_sha256`` (:func:`content_digest`);
optional ``recycled`` (3 bools): the periodic axes across which the run only recycles particles
(the DEM stage's tube: z), which the thermal stage lets no heat cross (the others, physically
periodic, it keeps periodic). Per-frame datasets are chunked one frame per chunk, gzip level 1 + shuffle:
on a settled 2,500-particle bed this gave files 10 % smaller than lzf at similar speed, and any
HDF5 reader can open gzip (lzf is h5py-only).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator, Mapping, NamedTuple

import h5py
import numpy as np

from dpht.errors import DPHTError
from dpht.util.h5 import open_checked

FORMAT = "dpht-positions-1"
COLUMNS = ("id", "x", "y", "z", "ix", "iy", "iz")
DUMP_GLOB = "dump.*.txt"
_HEADER_LINES = 9
_COMPRESSION = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
PRECISIONS = ("float32", "float64")
# Particles missing from a dump (LIGGGHTS drops atoms that leave the domain) beyond this fraction of
# the first frame's stop the gather: the flow has lost its bed, through a gap in the walls or a time
# step too large for the contact stiffness. A few lost particles are recorded (NaN, /lost) and reported.
MAX_LOST_FRACTION = 0.05


class Box(NamedTuple):
    """A box at full precision: ``lo``, ``hi`` (3,) m and the xy ``tilt`` (m) of a sheared box."""

    lo: np.ndarray
    hi: np.ndarray
    tilt: float


@dataclass(frozen=True)
class DumpFrame:
    """One dump step: ``ids`` (n,) int64, ``positions`` (n, 3) m, ``image`` (n, 3) int32; ``tilt``
    (m) the xy tilt of a sheared box, None for an orthogonal one (see the module docstring)."""

    step: int
    box_lo: np.ndarray
    box_hi: np.ndarray
    periodic: tuple[bool, bool, bool]
    ids: np.ndarray
    positions: np.ndarray
    image: np.ndarray
    tilt: float | None = None

    def __post_init__(self):
        """Check what the thermal stage relies on; DPHTError says what is wrong."""
        n = self.ids.shape[0] if self.ids.ndim == 1 else -1
        if self.positions.shape != (n, 3) or self.image.shape != (n, 3):
            raise DPHTError(f"ids {self.ids.shape}, positions {self.positions.shape} and image flags "
                            f"{self.image.shape} do not describe the same particles")  # fmt: skip
        if not (np.all(np.isfinite(self.box_lo)) and np.all(np.isfinite(self.box_hi))
                and np.all(self.box_lo < self.box_hi)):  # fmt: skip
            raise DPHTError(f"box bounds {self.box_lo.tolist()} .. {self.box_hi.tolist()} are not a box")
        if self.tilt is not None and not (math.isfinite(self.tilt) and self.periodic[0] and self.periodic[1]):
            raise DPHTError(f"box tilt xy = {self.tilt} m: a sheared box needs a finite tilt and periodic x and y "
                            f"(boundary flags {self.periodic})")  # fmt: skip
        bad = ~np.all(np.isfinite(self.positions), axis=1)
        if bad.any():
            raise DPHTError(
                f"{int(bad.sum())} particles have non-finite positions, ids {self.ids[bad][:10].tolist()}: "
                "the DEM run blew up (is dem.timestep small enough for the contact stiffness?)"
            )
        if n and np.any(self.ids < 1):
            raise DPHTError(f"particle ids must be positive integers, got {self.ids.min()}")
        duplicate = self.ids[1:][np.diff(self.ids) == 0]
        if duplicate.size:
            raise DPHTError(f"particle ids {np.unique(duplicate)[:10].tolist()} appear more than once")
        if np.any(np.diff(self.ids) < 0):
            raise DPHTError("ids are not sorted (the dump needs 'dump_modify sort id')")


def numbered_files(folder: Path, glob: str) -> dict[int, Path]:
    """Files matching ``glob`` (one ``*``, e.g. ``dump.*.txt``) whose ``*`` is an integer, by that integer."""
    prefix, suffix = glob.split("*")
    pattern = re.compile(re.escape(prefix) + r"(\d+)" + re.escape(suffix) + "$")
    found = {}
    for path in Path(folder).glob(glob):
        match = pattern.match(path.name)
        if match:
            found[int(match.group(1))] = path
    return dict(sorted(found.items()))


def dump_files(folder: Path) -> dict[int, Path]:
    """Dump files ``dump.<step>.txt`` in ``folder`` by step, ascending."""
    return numbered_files(folder, DUMP_GLOB)


def read_dump(path: Path, boxes: Mapping[int, Box] | None = None) -> DumpFrame:
    """Parse one text dump; a truncated or foreign file raises DPHTError naming it.

    Positions come back inside the (orthogonal) box along periodic axes, image flags adjusted to
    match. ``boxes`` maps steps to the box at full precision: the dump's step must be among them,
    and its box replaces the header's once the header is seen to print it (to 6 significant digits).
    """
    path = Path(path)
    try:
        with open(path) as stream:
            header = [stream.readline() for _ in range(_HEADER_LINES)]
            body = stream.read()
    except (OSError, UnicodeDecodeError) as err:
        raise DPHTError(f"dump file {path} cannot be read as text: {err}") from None
    try:
        if header[0].strip() != "ITEM: TIMESTEP" or header[2].strip() != "ITEM: NUMBER OF ATOMS":
            raise ValueError("not a LIGGGHTS/LAMMPS text dump")
        step = int(header[1])
        n_atoms = int(header[3])
        if n_atoms < 0 or step < 0:
            raise ValueError(f"step {step} and atom count {n_atoms} must not be negative")
        bounds_item = header[4].split()
        triclinic = bounds_item[3:6] == ["xy", "xz", "yz"]
        if bounds_item[:3] != ["ITEM:", "BOX", "BOUNDS"] or len(bounds_item) != (9 if triclinic else 6):
            raise ValueError("expected 'ITEM: BOX BOUNDS xx yy zz' or 'ITEM: BOX BOUNDS xy xz yz xx yy zz'")
        periodic = tuple(flags == "pp" for flags in bounds_item[-3:])
        bounds = np.array([header[5 + k].split()[: 3 if triclinic else 2] for k in range(3)], dtype=float)
        tilt = _tilt(bounds) if triclinic else None
        bounds = bounds[:, :2]
        if boxes is not None:
            if step not in boxes:
                raise ValueError(f"no full-precision box for step {step}")
            bounds, tilt = _exact_box(bounds, tilt, boxes[step])
        columns = tuple(header[8].split()[2:])
        if columns != COLUMNS:
            raise ValueError(f"columns {columns}, expected {COLUMNS}")
        table = np.array(body.split(), dtype=float)
        if table.size != n_atoms * len(COLUMNS):
            raise ValueError(f"{table.size} values for {n_atoms} atoms x {len(COLUMNS)} columns (truncated?)")
    except (ValueError, IndexError) as err:
        raise DPHTError(f"dump file {path}: {err}") from None
    table = table.reshape(n_atoms, len(COLUMNS))
    integers = table[:, [0, 4, 5, 6]]
    with np.errstate(invalid="ignore"):
        whole = np.isfinite(integers) & (integers == np.round(integers)) & (np.abs(integers) < 2**31)
    if not whole.all():
        row = int(np.flatnonzero(~whole.all(axis=1))[0])
        raise DPHTError(f"dump file {path}: atom line {row + 1} has a non-integer id or image flag: "
                        f"{table[row].tolist()}")
    ids = table[:, 0].astype(np.int64)
    positions, image = table[:, 1:4], table[:, 4:7].astype(np.int32)
    try:
        frame = DumpFrame(step, bounds[:, 0], bounds[:, 1], periodic, ids, positions, image, tilt)
    except DPHTError as err:
        raise DPHTError(f"dump file {path}: {err}") from None
    _wrap(frame.positions, frame.image, frame.box_lo, frame.box_hi, periodic, tilt or 0.0)
    return frame


def _tilt(bounds: np.ndarray) -> float:
    """The xy tilt of a triclinic dump's bounds (rows: lo_bound hi_bound tilt), turning its
    bounding box into the box (``bounds[:, :2]``, in place): LIGGGHTS writes
    xlo_bound = xlo + min(0, xy) and xhi_bound = xhi + max(0, xy) when xz = yz = 0."""
    xy, xz, yz = bounds[:, 2]
    if xz != 0.0 or yz != 0.0:
        raise ValueError(f"tilt factors xz = {xz}, yz = {yz}: only a shear along x with its gradient along y "
                         "(an xy tilt) is supported")
    bounds[0, 0] -= min(0.0, xy)
    bounds[0, 1] -= max(0.0, xy)
    return float(xy)


def _exact_box(bounds: np.ndarray, tilt: float | None, box: Box) -> tuple[np.ndarray, float | None]:
    """``box`` as the dump's bounds and tilt, once the header's (6 significant digits) agree with it."""
    exact = np.column_stack([box.lo, box.hi]).astype(float)
    size = float(np.max(exact[:, 1] - exact[:, 0]))
    printed = [*bounds.ravel(), 0.0 if tilt is None else tilt]
    wanted = [*exact.ravel(), float(box.tilt)]
    if any(abs(a - b) > 1e-5 * (abs(b) + size) for a, b in zip(printed, wanted)) or (tilt is None and box.tilt != 0.0):
        raise ValueError(f"the box {exact.tolist()} with tilt {box.tilt} m given for this step is not the header's "
                         f"{bounds.tolist()} with tilt {tilt}")
    return exact, (None if tilt is None else float(box.tilt))


def _wrap(positions: np.ndarray, image: np.ndarray, lo: np.ndarray, hi: np.ndarray, periodic, tilt: float = 0.0) -> None:
    """Move positions into [lo, hi) along periodic axes, in place, keeping the unwrapped position
    (:func:`unwrapped`): in a sheared box a period in y moves x by the tilt.

    LIGGGHTS wraps atoms only when it rebuilds neighbour lists, so a dump can hold a particle a
    few micrometres past a periodic boundary with its old image flag; a sheared box's dump holds
    them in its tilted cell, whose x range at height y is shifted by ``tilt (y - ylo) / Ly``.
    """
    for axis in sorted(np.flatnonzero(periodic), key=lambda a: a != 1):  # y first: it moves x
        span = hi[axis] - lo[axis]
        shift = np.floor((positions[:, axis] - lo[axis]) / span).astype(np.int32)
        positions[:, axis] -= shift * span
        image[:, axis] += shift
        if axis == 1 and tilt:
            positions[:, 0] -= shift * tilt


def unwrapped(positions: np.ndarray, image: np.ndarray, box_lo, box_hi, tilt: float = 0.0) -> np.ndarray:
    """Positions (N, 3, m) unwrapped with their image flags: ``ix Lx + iy tilt`` added in x,
    ``iy Ly`` in y, ``iz Lz`` in z (``tilt`` the frame's xy tilt of a sheared box, else 0)."""
    length = np.asarray(box_hi, float) - np.asarray(box_lo, float)
    out = np.asarray(positions, dtype=np.float64) + image * length
    out[:, 0] += image[:, 1] * float(tilt)
    return out


def axial_length(attrs) -> float:
    """m: the box's length along z of a positions file (its ``box_lo``/``box_hi`` attributes): the
    periodic length a driven slice ran with, shorter than the configured tube once loaded."""
    return float(np.asarray(attrs["box_hi"], float)[2] - np.asarray(attrs["box_lo"], float)[2])


def axial_step(z0: np.ndarray, z1: np.ndarray, image0, image1, length: float) -> np.ndarray:
    """Displacement along z (m) from one frame to a later one across the periodic boundary of
    ``length`` (m): by the image flags (z-columns of (N, 3) arrays), or without them (None) to the
    nearest periodic image."""
    step = np.asarray(z1, dtype=np.float64) - z0
    if image0 is not None and image1 is not None:
        return step + length * (image1[:, 2].astype(np.float64) - image0[:, 2])
    return step - length * np.round(step / length)


def read_dumps(paths: Iterable[Path], boxes: Mapping[int, Box] | None = None) -> Iterator[DumpFrame]:
    """Parse dump files one at a time (for streaming into :func:`write_positions`), ``boxes`` as
    :func:`read_dump` takes them."""
    for path in paths:
        yield read_dump(path, boxes)


@dataclass(frozen=True)
class GatherStats:
    """What :func:`write_positions` saw while streaming.

    ``crossings`` (n_frames,) counts, per frame, the net number of periodic-boundary crossings in
    -z since the first frame (sum of iz decreases over particles present in both frames).
    ``lost_first_step`` maps each lost particle id to the first step it was missing.
    """

    n_frames: int
    n_particles: int
    steps: np.ndarray
    crossings: np.ndarray
    lost_first_step: dict[int, int]


def write_positions(
    path: Path,
    frames: Iterable[DumpFrame],
    *,
    radius: float,
    density: float,
    timestep: float,
    dump_interval: int,
    precision: str = "float64",
    summary: dict | None = None,
    attrs: dict | None = None,
    max_lost_fraction: float = MAX_LOST_FRACTION,
) -> GatherStats:
    """Stream ``frames`` into the positions HDF5 file ``path`` (format in the module docstring).

    Frames must be exactly ``dump_interval`` steps apart (no gap, no duplicate). The particle set
    is the first frame's ids; a particle missing later is stored as NaN with ``/lost`` set, an id
    absent from the first frame is an error, and so is a frame missing more than
    ``max_lost_fraction`` of the particles, or one whose box differs from the first frame's in its
    bounds or in being sheared (a sheared box's tilt goes to ``/tilt``, frame by frame).
    ``attrs`` adds extra root attributes.
    """
    if precision not in PRECISIONS:
        raise DPHTError(f"position precision {precision!r}: expected one of {PRECISIONS}")
    frames = iter(frames)
    first = next(frames, None)
    if first is None:
        raise DPHTError(f"no dump frames to write into {path}")
    ids = first.ids
    n = ids.size
    steps, crossings, lost_first_step = [], [], {}
    iz_first = first.image[:, 2].astype(np.int64)
    with h5py.File(path, "w") as h5:
        h5.attrs.update(
            {
                "format": FORMAT,
                "radius": float(radius),
                "density": float(density),
                "timestep": float(timestep),
                "dump_interval": int(dump_interval),
                "box_lo": np.asarray(first.box_lo, dtype=float),
                "box_hi": np.asarray(first.box_hi, dtype=float),
                "periodic": np.asarray(first.periodic, dtype=bool),
                "summary": json.dumps(summary or {}, sort_keys=True),
            }
        )
        h5.attrs.update(attrs or {})
        h5.create_dataset("ids", data=ids)
        positions = h5.create_dataset(
            "positions", shape=(0, n, 3), maxshape=(None, n, 3), dtype=precision, chunks=(1, n, 3), **_COMPRESSION
        )
        image = h5.create_dataset(
            "image", shape=(0, n, 3), maxshape=(None, n, 3), dtype=np.int32, chunks=(1, n, 3), **_COMPRESSION
        )
        lost = h5.create_dataset("lost", shape=(0, n), maxshape=(None, n), dtype=bool, chunks=(1, n), **_COMPRESSION)
        tilts = []
        for index, frame in enumerate(itertools.chain([first], frames)):
            expected = first.step + index * dump_interval
            if frame.step != expected:
                raise DPHTError(
                    f"dump frame {index} is step {frame.step}, expected {expected} "
                    f"(frames must be every {dump_interval} steps with no gap or duplicate)"
                )
            if (not (np.array_equal(frame.box_lo, first.box_lo) and np.array_equal(frame.box_hi, first.box_hi))
                    or (frame.tilt is None) != (first.tilt is None)):  # fmt: skip
                raise DPHTError(
                    f"dump step {frame.step}: box {frame.box_lo.tolist()} .. {frame.box_hi.tolist()} (tilt {frame.tilt}) "
                    f"is not the first frame's {first.box_lo.tolist()} .. {first.box_hi.tolist()} (tilt {first.tilt}): "
                    "the box may only tilt while dumping"
                )
            tilts.append(frame.tilt)
            slot = np.searchsorted(ids, frame.ids)
            if np.any(slot >= n) or np.any(ids[np.minimum(slot, n - 1)] != frame.ids):
                unknown = np.setdiff1d(frame.ids, ids)
                raise DPHTError(f"dump step {frame.step}: particle ids {unknown[:10].tolist()} not in the first frame")
            frame_positions = np.full((n, 3), np.nan)
            frame_positions[slot] = frame.positions
            frame_image = np.zeros((n, 3), dtype=np.int32)
            frame_image[slot] = frame.image
            frame_lost = np.ones(n, dtype=bool)
            frame_lost[slot] = False
            if frame_lost.sum() > max_lost_fraction * n:
                raise DPHTError(
                    f"dump step {frame.step}: {int(frame_lost.sum())} of the {n} particles are missing, more than "
                    f"{max_lost_fraction:.0%}: LIGGGHTS lost them (through a gap in the walls, or with a time step "
                    f"too large for the contact stiffness); ids {ids[frame_lost][:10].tolist()}"
                )
            for pid in ids[frame_lost]:
                lost_first_step.setdefault(int(pid), frame.step)
            for dataset, value in ((positions, frame_positions), (image, frame_image), (lost, frame_lost)):
                dataset.resize(index + 1, axis=0)
                dataset[index] = value
            steps.append(frame.step)
            present = ~frame_lost
            crossings.append(int(np.sum(iz_first[present] - frame_image[present, 2])))
        steps = np.asarray(steps, dtype=np.int64)
        h5.create_dataset("step", data=steps)
        h5.create_dataset("time", data=(steps - steps[0]) * float(timestep))
        if first.tilt is not None:
            h5.create_dataset(TILT, data=np.asarray(tilts, dtype=np.float64))
    return GatherStats(len(steps), n, steps, np.asarray(crossings, dtype=np.int64), lost_first_step)


# SHA-256 of a positions file's frame data, so that a stage that read the file (the thermal stage)
# can tell whether a regenerated one holds the very same frames.
CONTENT_DIGEST = "content_sha256"
TILT = "tilt"  # the dataset of a sheared box's xy tilt per frame
_DIGESTED = ("ids", "step", "positions", "image", "lost")


def content_digest(h5: h5py.File) -> str:
    """SHA-256 of the frame data (datasets ``_DIGESTED``, and the tilt of a sheared box) of an
    open positions file, read one frame at a time."""
    h = hashlib.sha256()
    for name in _DIGESTED + ((TILT,) if TILT in h5 else ()):
        data = h5[name]
        h.update(f"{name} {data.dtype.str} {data.shape}".encode())
        for k in range(data.shape[0]) if data.ndim > 1 else [Ellipsis]:
            h.update(data[k].tobytes())
    return h.hexdigest()


def set_summary(path: Path, summary: dict) -> None:
    """Replace the JSON ``summary`` attribute of a positions file."""
    with h5py.File(path, "r+") as h5:
        h5.attrs["summary"] = json.dumps(summary, sort_keys=True)


@dataclass(frozen=True)
class PositionsFrame:
    """One stored frame: ``positions`` (N, 3) m, ``image`` (N, 3), ``lost`` (N,) bool; ``tilt``
    (m) the xy tilt of a sheared box (0 for an orthogonal one)."""

    index: int
    step: int
    time: float
    positions: np.ndarray
    image: np.ndarray
    lost: np.ndarray
    tilt: float = 0.0


class PositionsFile:
    """Read a positions HDF5 file frame by frame (never loads all frames at once).

    Use as a context manager: ``with PositionsFile(p) as f: for frame in f.frames(): ...``.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self._h5 = open_checked(self.path, FORMAT, "a positions file")
        try:
            self._read_layout()
        except (KeyError, ValueError, TypeError, OSError) as err:  # missing, malformed or unreadable
            self._h5.close()
            raise DPHTError(
                f"positions file {self.path}: not a complete {FORMAT!r} file ({type(err).__name__}: {err}); "
                "delete it and run the workflow again to regather it from the DEM run"
            ) from None

    def _read_layout(self) -> None:
        h5 = self._h5
        self.ids = h5["ids"][...]
        self.steps = h5["step"][...]
        self.times = h5["time"][...]
        self.summary = json.loads(h5.attrs["summary"])
        self.attrs = {k: v for k, v in h5.attrs.items() if k != "summary"}
        n, frames = self.ids.shape, self.steps.shape
        expected = {"ids": (n, "iu"), "step": (frames, "iu"), "time": (frames, "f"),
                    "positions": ((*frames, *n, 3), "f"), "image": ((*frames, *n, 3), "iu"),
                    "lost": ((*frames, *n), "b")}  # fmt: skip
        if TILT in h5:
            expected[TILT] = (frames, "f")
        for name, (shape, kinds) in expected.items():
            if len(n) != 1 or len(frames) != 1 or h5[name].shape != shape or h5[name].dtype.kind not in kinds:
                raise ValueError(f"/{name} is {h5[name].dtype} {h5[name].shape}, expected {shape}")
        self.tilts = h5[TILT][...] if TILT in h5 else None
        for name in ("radius", "timestep", "box_lo", "box_hi", "periodic"):
            np.asarray(self.attrs[name], dtype=float)  # KeyError or ValueError when missing or not numeric

    def __enter__(self) -> "PositionsFile":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._h5.close()

    @property
    def n_frames(self) -> int:
        return int(self.steps.size)

    @property
    def sheared(self) -> bool:
        """Whether the box is sheared (its frames have a tilt, ``/tilt``)."""
        return self.tilts is not None

    @property
    def n_particles(self) -> int:
        return int(self.ids.size)

    @property
    def radius(self) -> float:
        return float(self.attrs["radius"])

    @property
    def timestep(self) -> float:
        return float(self.attrs["timestep"])

    def frame(self, index: int) -> PositionsFrame:
        if not -self.n_frames <= index < self.n_frames:
            raise DPHTError(f"positions file {self.path}: frame {index} out of range (0..{self.n_frames - 1})")
        index %= self.n_frames
        try:
            arrays = [self._h5[name][index] for name in ("positions", "image", "lost")]
        except OSError as err:  # a file truncated after its layout was written
            raise DPHTError(f"positions file {self.path}: frame {index} cannot be read ({err}); the file is damaged: "
                            "delete it and run the workflow again") from None  # fmt: skip
        tilt = 0.0 if self.tilts is None else float(self.tilts[index])
        return PositionsFrame(index, int(self.steps[index]), float(self.times[index]), *arrays, tilt)

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[PositionsFrame]:
        """Frames ``start`` to ``stop`` (exclusive, Python slice semantics), one read per frame."""
        for index in range(*slice(start, stop).indices(self.n_frames)):
            yield self.frame(index)
