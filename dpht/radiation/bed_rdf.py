"""One bed: a positions file -> its RDF matrix as CSV (the ``python -m dpht rdf`` command), by Monte
Carlo ray tracing (:mod:`dpht.radiation.raytrace`).

Overlapping spheres: the tracer treats every sphere as whole, so where two spheres overlap by
``delta`` (centre distance ``2R - delta``) the cap of each inside the other, ``delta / 4R`` of its
surface, still emits, and its rays cross the other sphere unseen. A pair's RDF is then off by about
that fraction (a neighbour overlapping by 0.8 R got 0.000 instead of about 0.055). Overlaps up to
``--max-overlap`` (default 0.05 R, a 1.25% cap; DEM contacts overlap far less) are traced as they
are; deeper ones, between particles or of a particle with a plane wall, are refused with the
first pairs named. Periodic images count along ``--periodic`` axes.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from dpht.errors import DPHTError
from dpht.radiation import raytrace


def read_positions(path: str | Path) -> np.ndarray:
    """Particle centres from a text file with ``x y z`` (m) per line (commas allowed; blank lines
    and ``#`` comments skipped)."""
    path = Path(path)
    if not path.is_file():
        raise DPHTError(f"positions file {path} does not exist or is not a file")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise DPHTError(f"positions file {path} cannot be read as text: {err}") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        text = line.split("#", 1)[0].replace(",", " ").split()
        if not text:
            continue
        try:
            values = [float(v) for v in text]
        except ValueError:
            values = []
        if len(values) != 3 or not np.all(np.isfinite(values)):
            raise DPHTError(f"{path}:{number}: expected three numbers 'x y z', got {line.strip()!r}")
        rows.append(values)
    if not rows:
        raise DPHTError(f"positions file {path} contains no particles")
    return np.array(rows)


def check_output(path: str | Path) -> Path:
    """``path`` as a file the CSV can be written to: its folder exists and is writable, and it is not
    a folder itself (checked before any ray is traced)."""
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise DPHTError(f"--out {path}: the folder {folder} does not exist; create it first")
    if path.is_dir():
        raise DPHTError(f"--out {path} is a folder; give a file name, e.g. {path / 'rdf.csv'}")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise DPHTError(f"--out {path}: no permission to write there")
    return path


# Bytes per traced ray held at once: its outcome code (int32) and the run-length tally of a block
# of them (three int64 arrays, at most one entry per ray); and per entry of the dense N x (N + 2)
# matrix written as CSV (the matrix and the table stacked from it, float64).
BYTES_PER_RAY, BYTES_PER_ENTRY = 4 + 3 * 8, 2 * 8


def available_memory() -> int:
    """Bytes of memory the system can still give (MemAvailable of /proc/meminfo; else free pages)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def check_memory(particles: int, rays: int, available: int | None = None) -> None:
    """Refuse, before anything is allocated, a trace whose arrays would not fit in memory: the rays of
    one block of emitters (at least one particle's, ``rays``) and the dense RDF matrix."""
    need = max(rays, raytrace._CHUNK_ELEMENTS) * BYTES_PER_RAY + particles * (particles + 2) * BYTES_PER_ENTRY
    available = available_memory() if available is None else available
    if need > available:
        most = max((available - particles * (particles + 2) * BYTES_PER_ENTRY) // BYTES_PER_RAY, 0)
        raise DPHTError(
            f"--rays {rays} for {particles} particles needs about {need / 2**30:.3g} GiB of memory at once, more than the "
            f"{available / 2**30:.3g} GiB available; use at most {most} rays per particle (or fewer particles)"
        )


def write_rdf_csv(path: str | Path, result: raytrace.RDFResult) -> None:
    """N x (N + 2) CSV: row i = fractions of particle i's rays absorbed by each particle j
    (diagonal: self-absorption), by the walls (summed), and lost through open boundaries."""
    table = np.hstack([result.matrix.toarray(), result.walls.sum(axis=1, keepdims=True), result.lost[:, None]])
    try:
        np.savetxt(path, table, delimiter=",", fmt="%.10g")
    except OSError as err:
        raise DPHTError(f"--out {path}: cannot write the RDF matrix: {err}") from None


def check_overlaps(positions: np.ndarray, radius: float, max_overlap: float, *, box=None,
                   periodic=(False, False, False), planes=()) -> None:
    """Refuse spheres that overlap each other, or cross a plane wall ``(point, normal)``, by more
    than ``max_overlap`` radii (see the module docstring); the first pairs are named (0-based rows)."""
    limit = (2.0 - max_overlap) * radius
    periodic = np.asarray(periodic, dtype=bool)
    lo = positions.min(axis=0) - 2 * limit if box is None else np.asarray(box[0], dtype=float)
    span = positions.max(axis=0) + 2 * limit - lo if box is None else np.asarray(box[1], dtype=float) - lo
    # A torus along the periodic axes; along the others a "box" wider than the bed, so nothing wraps.
    size = np.where(periodic, span, np.ptp(positions, axis=0) + 4 * limit + 1.0)
    inside = np.where(periodic, np.mod(positions - lo, size), positions - positions.min(axis=0) + 2 * limit)
    inside = np.where(inside >= size, inside - size, inside)  # np.mod(-1e-20, L) is L
    pairs = cKDTree(inside, boxsize=size).query_pairs(limit, output_type="ndarray")
    if pairs.size:
        gap = inside[pairs[:, 0]] - inside[pairs[:, 1]]
        gap -= size * np.round(gap / size) * periodic
        depth = 2.0 - np.linalg.norm(gap, axis=1) / radius
        worst = np.argsort(-depth)[:5]
        named = ", ".join(f"{a} and {b} by {d:.3g} R" for (a, b), d in zip(pairs[worst].tolist(), depth[worst]))
        raise DPHTError(
            f"{len(pairs)} pairs of spheres overlap by more than --max-overlap = {max_overlap} radii, e.g. rows "
            f"{named}: the tracer would let the buried caps emit (see 'python -m dpht rdf --help'); separate "
            f"them, or raise --max-overlap"
        )
    for k, (point, normal) in enumerate(planes):
        normal = np.asarray(normal, dtype=float)
        length = np.linalg.norm(normal)
        if not length > 0:
            continue  # the tracer names a zero normal
        depth = 1.0 - np.abs((positions - np.asarray(point, dtype=float)) @ (normal / length)) / radius
        if np.any(depth > max_overlap):
            row = int(np.argmax(depth))
            raise DPHTError(f"--wall-plane number {k + 1} cuts {int(np.sum(depth > max_overlap))} spheres by more "
                            f"than --max-overlap = {max_overlap} radii, e.g. row {row} by {depth[row]:.3g} R")  # fmt: skip


def rdf_command(args) -> int:
    """Handler of ``python -m dpht rdf`` (arguments defined in dpht.__main__)."""
    out = check_output(args.out)
    positions = read_positions(args.positions)
    if not (math.isfinite(args.radius) and args.radius > 0):
        raise DPHTError(f"--radius must be positive (a length in m); got {args.radius}")
    if not (math.isfinite(args.max_overlap) and 0 <= args.max_overlap < 2):
        raise DPHTError(f"--max-overlap must lie in [0, 2) radii; got {args.max_overlap}")
    raytrace.check_emissivity("--emissivity", args.emissivity, allow_zero=False)
    raytrace.check_emissivity("--wall-emissivity", args.wall_emissivity, allow_zero=True)
    check_memory(len(positions), args.rays)
    walls = [raytrace.PlaneWall(plane[:3], plane[3:], args.wall_emissivity) for plane in args.wall_plane or []]
    walls += [raytrace.MeshWall.from_file(path, args.wall_emissivity) for path in args.wall_mesh or []]
    if set(args.periodic) - set("xyz"):
        raise DPHTError(f"--periodic: expected a combination of the letters x, y, z; got {args.periodic!r}")
    periodic = tuple(axis in args.periodic for axis in "xyz")
    box = None if args.box is None else np.reshape(args.box, (2, 3))
    if any(periodic) and box is None:
        raise DPHTError("--periodic needs --box")
    if box is not None and not (np.all(np.isfinite(box)) and np.all(box[1] > box[0])):
        raise DPHTError(f"--box: expected X0 Y0 Z0 X1 Y1 Z1 with X1 > X0, Y1 > Y0, Z1 > Z0 (m); got {args.box}")
    planes = [(plane[:3], plane[3:]) for plane in args.wall_plane or []]
    check_overlaps(positions, args.radius, args.max_overlap, box=box, periodic=periodic, planes=planes)
    result = raytrace.trace(
        positions, args.radius, args.emissivity, args.rays, walls=walls, box=box, periodic=periodic, seed=args.seed
    )
    write_rdf_csv(out, result)
    print(f"{out}: RDFs of {len(positions)} particles, {args.rays} rays each; lost {result.lost.mean():.3g}")
    return 0
