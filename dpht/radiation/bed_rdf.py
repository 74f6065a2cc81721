"""One bed: a positions file -> its RDF matrix as CSV (the ``python -m dpht rdf`` command), by Monte
Carlo ray tracing (:mod:`dpht.radiation.raytrace`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpht.errors import DPHTError
from dpht.radiation import raytrace


def read_positions(path: str | Path) -> np.ndarray:
    """Particle centres from a text file with ``x y z`` (m) per line (commas allowed; blank lines
    and ``#`` comments skipped)."""
    path = Path(path)
    if not path.is_file():
        raise DPHTError(f"positions file {path} does not exist")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
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


def write_rdf_csv(path: str | Path, result: raytrace.RDFResult) -> None:
    """N x (N + 2) CSV: row i = fractions of particle i's rays absorbed by each particle j
    (diagonal: self-absorption), by the walls (summed), and lost through open boundaries."""
    table = np.hstack([result.matrix.toarray(), result.walls.sum(axis=1, keepdims=True), result.lost[:, None]])
    np.savetxt(path, table, delimiter=",", fmt="%.10g")


def rdf_command(args) -> int:
    """Handler of ``python -m dpht rdf`` (arguments defined in dpht.__main__)."""
    positions = read_positions(args.positions)
    if not args.radius > 0:
        raise DPHTError(f"--radius must be positive; got {args.radius}")
    raytrace.check_emissivity("--emissivity", args.emissivity, allow_zero=False)
    raytrace.check_emissivity("--wall-emissivity", args.wall_emissivity, allow_zero=True)
    if args.rays < 1:
        raise DPHTError(f"--rays must be a positive integer; got {args.rays}")
    walls = [raytrace.PlaneWall(plane[:3], plane[3:], args.wall_emissivity) for plane in args.wall_plane or []]
    walls += [raytrace.MeshWall.from_file(path, args.wall_emissivity) for path in args.wall_mesh or []]
    if set(args.periodic) - set("xyz"):
        raise DPHTError(f"--periodic: expected a combination of the letters x, y, z; got {args.periodic!r}")
    periodic = tuple(axis in args.periodic for axis in "xyz")
    box = None if args.box is None else np.reshape(args.box, (2, 3))
    result = raytrace.trace(
        positions, args.radius, args.emissivity, args.rays, walls=walls, box=box, periodic=periodic, seed=args.seed
    )
    write_rdf_csv(args.out, result)
    print(f"{args.out}: RDFs of {len(positions)} particles, {args.rays} rays each; lost {result.lost.mean():.3g}")
    return 0
