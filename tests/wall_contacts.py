"""LIGGGHTS' own particle-wall overlaps on one frame of a real DEM run, for tests of the distances
the thermal stage measures (import it as ``wall_contacts`` from a test, like ``dem_scene``).

:func:`liggghts_wall_contacts` restarts LIGGGHTS from a restart file of a flow run, in that run's
work directory and with its own model (the rendered flow deck, less its dumps, restarts and run),
sets every velocity to zero and runs 0 steps, which evaluates every contact once, and dumps:

* mesh walls: ``compute wall/gran/local id delta``, one row per particle-triangle contact: the
  triangle (its index in the decks' one mesh, which holds the zones of ``DemParams.mesh_zones``
  zone after zone), turned into the zone (index into ``mesh_zones``) and the triangle's index in
  that zone's STL, and LIGGGHTS' overlap delta;
* the primitive tube (``dem.tube_wall: primitive``): LIGGGHTS reports no contact data for
  primitive walls (``wall/gran/local`` takes meshes only), so ``store_force yes`` records each
  particle's force from the cylinder instead; with zero velocities it is the elastic Hertz force,
  F_n = 4/3 Y* sqrt(r delta) delta along the normal (LIGGGHTS normal_model_hertz with
  reff = r at walls; the tangential force is perpendicular to it), inverted here for delta;
* the positions (17 digits) and radii of all particles.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpht.dem.decks import render_decks
from dpht.dem.liggghts import run_liggghts
from dpht.dem.params import DemParams

OUT_DIR = "wall_contacts"
TUBE_FIX = "tube_wall"  # the primitive cylinder's fix ID in the decks


@dataclass(frozen=True)
class WallContacts:
    ids: np.ndarray  # (N,) particle ids
    positions: np.ndarray  # (N, 3) m
    radius: np.ndarray  # (N,) m
    tube_overlap: np.ndarray  # (N,) m, from the primitive cylinder's force; 0 without contact (or primitive)
    mesh_zones: tuple[str, ...]
    mesh: np.ndarray  # (K,) per mesh contact: index into mesh_zones
    triangle: np.ndarray  # (K,) triangle index in that zone's STL
    particle: np.ndarray  # (K,) row in ids/positions
    delta: np.ndarray  # (K,) LIGGGHTS' overlap, m


def _rows(path: Path, header: str) -> np.ndarray:
    """Data rows (one per line, as many columns as the header names) of a one-snapshot LIGGGHTS
    dump after its ``ITEM: <header> ...`` line."""
    lines = path.read_text().splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith(f"ITEM: {header}"))
    columns = len(lines[start].split()) - 2
    rows = [[float(v) for v in line.split()] for line in lines[start + 1 :] if line.strip()]
    return np.array(rows, dtype=float).reshape(len(rows), columns)


def contacts_deck(params: DemParams) -> str:
    """The flow deck's set-up and model with the contact dumps and a zero-step run instead of its
    dumps, restarts and run."""
    keep = [
        line + (" store_force yes" if line.startswith(f"fix {TUBE_FIX} ") else "")
        for line in render_decks(params)["flow.in"].splitlines()
        if not re.match(r"(restart|dump|dump_modify|run) ", line)
    ]
    digits = "%.17g"
    atoms = "id x y z radius" + (f" f_force_{TUBE_FIX}[1] f_force_{TUBE_FIX}[2] f_force_{TUBE_FIX}[3]" if params.tube_wall == "primitive" else "")
    n_atom_columns = len(atoms.split())
    return "\n".join([
        *keep,
        "velocity all set 0.0 0.0 0.0",
        "compute contacts all wall/gran/local id delta",
        f"dump contacts all local 1 {OUT_DIR}/contacts.txt c_contacts[1] c_contacts[2] c_contacts[3] c_contacts[4]",
        f'dump_modify contacts format "{" ".join([digits] * 4)}"',
        f"dump atoms all custom 1 {OUT_DIR}/atoms.txt {atoms}",
        f'dump_modify atoms sort id format "%d {" ".join([digits] * (n_atom_columns - 1))}"',
        "run 0",
        "",
    ])  # fmt: skip


def effective_modulus(params: DemParams) -> float:
    """Y* of the particle-wall pair, Pa, as LIGGGHTS' Hertz model combines it."""
    return 1.0 / ((1 - params.poisson_p**2) / params.youngs_p + (1 - params.poisson_w**2) / params.youngs_w)


def liggghts_wall_contacts(params: DemParams, workdir: Path, restart: Path, mesh_dir: Path) -> WallContacts:
    """Run the contact deck on ``restart`` (a restart file of a flow run in ``workdir``, the DEM
    work directory with its ``meshes/``; ``mesh_dir``: the geometry stage's zone STLs the run
    staged) and read what LIGGGHTS computed."""
    workdir = Path(workdir)
    (workdir / OUT_DIR).mkdir(exist_ok=True)
    (workdir / f"{OUT_DIR}.in").write_text(contacts_deck(params))
    run_liggghts(f"{OUT_DIR}.in", workdir, workdir / OUT_DIR / "screen.txt",
                 variables={"restart_file": str(restart), "pz": str(params.z_slabs(1))})  # one serial rank
    atoms = _rows(workdir / OUT_DIR / "atoms.txt", "ATOMS")
    ids = atoms[:, 0].astype(np.int64)
    positions, radius = atoms[:, 1:4], atoms[:, 4]
    overlap = np.zeros(len(ids))
    if params.tube_wall == "primitive":
        rho = np.hypot(positions[:, 0], positions[:, 1])
        # The wall pushes towards the axis: F_n = -F . (x, y) / rho.
        normal_force = -(atoms[:, 5] * positions[:, 0] + atoms[:, 6] * positions[:, 1]) / rho
        touching = normal_force > 0
        scale = 4.0 / 3.0 * effective_modulus(params) * np.sqrt(radius[touching])
        overlap[touching] = (normal_force[touching] / scale) ** (2.0 / 3.0)
    entries = _rows(workdir / OUT_DIR / "contacts.txt", "ENTRIES")
    row_of = {int(i): k for k, i in enumerate(ids)}
    # The zones' first triangles in the one mesh, which holds each zone's STL triangles in turn.
    import trimesh

    counts = [len(trimesh.load(Path(mesh_dir) / f"{zone}.stl", process=False).triangles) for zone in params.mesh_zones]
    starts = np.concatenate([[0], np.cumsum(counts)])
    merged = entries[:, 1].astype(np.int64)
    zone = np.searchsorted(starts, merged, side="right") - 1
    return WallContacts(
        ids, positions, radius, overlap, params.mesh_zones,
        mesh=zone,
        triangle=merged - starts[zone],
        particle=np.array([row_of[int(i)] for i in entries[:, 2]], dtype=np.int64),
        delta=entries[:, 3],
    )  # fmt: skip


def per_particle(contacts: WallContacts, zone: str) -> np.ndarray:
    """LIGGGHTS' overlap (m) of every particle with the mesh of ``zone``: its deepest contact with
    the mesh's triangles, 0 without contact."""
    overlap = np.zeros(len(contacts.ids))
    rows = contacts.mesh == contacts.mesh_zones.index(zone)
    np.maximum.at(overlap, contacts.particle[rows], contacts.delta[rows])
    return overlap


def newest_restart(workdir: Path) -> Path:
    """The newest flow restart file in a DEM work directory."""
    files = sorted((Path(workdir) / "flow" / "restart").glob("flow.*.restart"), key=lambda p: int(p.name.split(".")[1]))
    if not files:
        raise FileNotFoundError(f"no flow restart file in {workdir}")
    return files[-1]

