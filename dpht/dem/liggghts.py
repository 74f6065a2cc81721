"""The DEM stage: LIGGGHTS run on the rendered decks (:mod:`dpht.dem.decks`) as a subprocess, resumable.

Resume: a flow restart file counts as complete only when a thermo line at or after its step was
printed (LIGGGHTS writes dumps, then restarts, then thermo, in that order within a step, and the
screen is line-buffered), so a file cut short by a kill is never read. An interrupted flow
continues from the newest complete restart; dumps from that step on are deleted and rewritten.
Each stage stores a digest of its deck and meshes: a changed config re-runs only what depends on it.
The settled bed (settle/settled.restart) is reused while unchanged; an interrupted settle resumes
the same way from its newest complete restart file (written once every particle is in).

After the flow the dumps are gathered into one HDF5 file (:mod:`dpht.dem.dumps`) and deleted; its run
summary (:mod:`dpht.dem.report`) says, given ``dem.target_mass_flow``, whether the flow is within
``dem.mass_flow_tolerance`` of it (:mod:`dpht.dem.calibrate` searches the orifice diameter for it).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shlex
import shutil
import signal
import subprocess
import time
from dataclasses import asdict
from datetime import timedelta
from pathlib import Path
from typing import Callable

import h5py
import numpy as np

from dpht.dem import dumps
from dpht.dem.decks import (
    FLOW_DIR,
    MESH_DIR,
    RECYCLED,
    WALL_MESH,
    RESTART_GLOB,
    SETTLE_DIR,
    SETTLE_RESTART_GLOB,
    SETTLED_RESTART,
    render_check_deck,
    render_decks,
)
from dpht.dem.params import LOAD_INCREMENTS, LOAD_STRAIN, DemParams, mass_flow_target, read_geometry
from dpht.dem.report import mass_flow_check, run_summary, wall_stress
from dpht.errors import ConfigError, DPHTError, ExternalToolError
from dpht.util import processes
from dpht.util.files import WorkdirLock, publish

RAYLEIGH_WARN, RAYLEIGH_MAX = 0.2, 0.5  # dem.timestep as a fraction of the Rayleigh time
TAIL_LINES = 30
PROGRESS_SECONDS = 10.0
SCREEN_GLOB = "screen.*.txt"  # one screen file per flow attempt
POSITIONS = "positions.h5"  # the gathered frames in the work directory, published as the stage's output


# --------------------------------------------------------------------------------------------
# Running LIGGGHTS


# The thermo_style columns of the decks (decks.THERMO_STYLE), in order (LIGGGHTS truncates f_ID[i] in
# its header); a driven flow (dem.drive) prints DRIVE_COLUMN after them, a loading slice its wall stress.
THERMO_COLUMNS = ("step", "atoms", "time", "iz_sum", "z_max", "rayleigh_fraction", "hertz_fraction")
DRIVE_COLUMN = "drive_acceleration"  # m/s^2 downwards, the controller's mean over the thermo interval


class _ThermoParser:
    """Thermo rows (dicts keyed by THERMO_COLUMNS) from screen text fed in pieces. A table may have
    columns after these, which depend on the deck (a driven flow's DRIVE_COLUMN, flow.in; a loading
    packed slice's wall stress, pack.in): a row keeps the first of them as ``extra`` when the reader
    names it, and drops them otherwise."""

    def __init__(self, extra: str | None = None):
        self._keys = (*THERMO_COLUMNS, extra) if extra else THERMO_COLUMNS
        self._width = 0  # columns of the current table, 0 outside one
        self._partial = ""

    def feed(self, text: str) -> list[dict]:
        lines = (self._partial + text).split("\n")
        self._partial = lines.pop()
        rows = []
        for line in lines:
            words = line.split()
            if words[:2] == ["Step", "Atoms"]:
                self._width = len(words) if len(words) >= len(THERMO_COLUMNS) else 0
            elif self._width and len(words) == self._width:
                try:
                    rows.append(dict(zip(self._keys, map(float, words))))
                except ValueError:
                    continue
        return rows


def read_thermo(screen: Path, extra: str | None = None) -> list[dict]:
    """All thermo rows printed in a LIGGGHTS screen file (none if it does not exist); ``extra`` names
    the column after THERMO_COLUMNS (see _ThermoParser)."""
    if not Path(screen).is_file():
        return []
    return _ThermoParser(extra).feed(Path(screen).read_text(errors="replace") + "\n")


def _tail(path: Path, n: int = TAIL_LINES) -> str:
    """The last ``n`` lines, preceded by any earlier ERROR lines (warnings can push them out)."""
    try:
        lines = Path(path).read_text(errors="replace").splitlines()
    except OSError:
        return "(no output)"
    errors = [line for line in lines[:-n] if "ERROR" in line]
    return "\n".join(errors + lines[-n:]) if lines else "(empty)"


DEFAULT_MPI = "mpirun"  # MPI launcher when a rule's resources.mpi names none (profiles/slurm: srun)


def _command(deck: str, ranks: int, variables: dict[str, str], mpi: str = DEFAULT_MPI) -> tuple[list[str], dict[str, str]]:
    executable = shutil.which("liggghts")
    if executable is None:
        raise ExternalToolError(
            "LIGGGHTS executable 'liggghts' not found on PATH; install it with "
            "'apt-get install --no-install-recommends liggghts' (see the Makefile)"
        )
    # Line-buffered stdout: LIGGGHTS aborts through MPI_Abort without flushing, which would
    # otherwise lose the ERROR line. Screen goes to stdout: '-screen none' segfaults with meshes.
    command = ["stdbuf", "-oL", "-eL"] if shutil.which("stdbuf") else []
    command += [executable, "-in", deck, "-log", "none"]
    for name, value in variables.items():
        command += ["-var", name, value]
    env = dict(os.environ)
    if ranks > 1:
        # The launcher comes from the rule's resources.mpi ("mpirun", "srun", "srun --mpi=pmix",
        # "mpiexec", ...); all of them take the rank count as -n.
        launcher = shlex.split(mpi)
        if not launcher or shutil.which(launcher[0]) is None:
            hint = " (apt-get install openmpi-bin)" if launcher == [DEFAULT_MPI] else ""
            raise ExternalToolError(
                f"{ranks} MPI ranks requested but the MPI launcher {mpi!r} (the rule's resources.mpi) "
                f"is not on PATH{hint}"
            )
        launcher += ["-n", str(ranks)]
        if launcher[0] == DEFAULT_MPI and ranks > (os.cpu_count() or 1):
            launcher.append("--oversubscribe")
        if os.geteuid() == 0:
            env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
        # Idle ranks yield the core instead of spinning: twice as fast here when the cores are shared.
        env.setdefault("OMPI_MCA_mpi_yield_when_idle", "1")
        command = launcher + processes.rank_prefix() + command
    return command, env


_GRID = re.compile(r"(\d+) by (\d+) by (\d+) MPI processor grid")


def _check_grid(text: str, ranks: int, mpi: str) -> bool:
    """False until LIGGGHTS has printed its processor grid; raises if the grid has another number of
    ranks than were launched (a launcher that started independent serial copies instead of one job)."""
    match = _GRID.search(text)
    if match is None:
        return False
    grid = math.prod(int(n) for n in match.groups())
    if grid != ranks:
        raise ExternalToolError(
            f"LIGGGHTS runs on a {' x '.join(match.groups())} processor grid but {ranks} ranks were launched "
            f"with {mpi!r}: the launcher did not connect the ranks into one MPI job. Under SLURM, name the "
            "PMI plugin Debian's OpenMPI needs (resources.mpi: 'srun --mpi=pmix'), or use 'mpirun' inside "
            "the allocation"
        )
    return True


def run_liggghts(
    deck: str,
    cwd: Path,
    screen: Path,
    *,
    ranks: int = 1,
    mpi: str = DEFAULT_MPI,
    variables: dict[str, str] | None = None,
    on_thermo: Callable[[dict], None] | None = None,
    pass_fds: tuple[int, ...] = (),
) -> float:
    """Run LIGGGHTS on ``deck`` (relative to ``cwd``), screen output to ``screen``; returns wall time (s).

    With ``ranks`` > 1 it runs under the MPI launcher ``mpi`` (``mpirun``, ``srun``, ...), and stops
    with an error unless LIGGGHTS reports a processor grid of that many ranks. ``on_thermo`` is
    called with each thermo row as it is printed. A non-zero exit raises ExternalToolError with the
    tail of the screen file. The child stays in the caller's process group (Ctrl-C or a group kill
    stops it too), is terminated if this function is interrupted (SIGINT, and SIGTERM or SIGHUP in
    the main thread), gets SIGTERM from the kernel if the calling thread dies, and MPI ranks die
    with their launcher (:mod:`dpht.util.processes`).
    """
    command, env = _command(deck, ranks, variables or {}, mpi)
    parser = _ThermoParser()
    head, grid_checked = "", ranks == 1
    start = time.monotonic()
    with processes.stop_on_signals(), open(screen, "wb") as out, open(screen, "rb") as follow:
        proc = subprocess.Popen(
            command, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, env=env, pass_fds=pass_fds,
            preexec_fn=processes.die_with_parent(signal.SIGTERM),
        )  # fmt: skip
        try:
            while True:
                finished = proc.poll() is not None
                text = follow.read().decode(errors="replace")
                if not grid_checked:
                    head += text
                    grid_checked = _check_grid(head, ranks, mpi)
                for row in parser.feed(text):
                    if on_thermo:
                        on_thermo(row)
                if finished:
                    break
                time.sleep(0.5)
        finally:
            if proc.poll() is None:
                with processes.signals_ignored():
                    proc.terminate()  # mpirun passes it on to the ranks
                    try:
                        proc.wait(timeout=10)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()
    if proc.returncode != 0:
        code = proc.returncode
        how = f"was killed by signal {-code}" if code < 0 else f"exited with code {code}"
        raise _tool_error(f"LIGGGHTS {how} running {deck} in {cwd}.", screen)
    return time.monotonic() - start


def _tool_error(what: str, screen: Path) -> ExternalToolError:
    return ExternalToolError(
        f"{what}\n--- last {TAIL_LINES} lines of {screen} ---\n{_tail(screen)}\n--- full screen output: {screen}"
    )


class _Progress:
    """Log one thermo row at most every PROGRESS_SECONDS, plus the last one, with the wall time
    since the first row and the ETA at the rate since then (a resumed run's rate is its own).
    ``label`` starts with the run's tag (its stage key), so that the lines of DEM runs side by side
    in one terminal tell which run they are of.

    Times are counted from ``start_step`` (LIGGGHTS' own clock restarts at every read_restart).
    """

    def __init__(self, label: str, start_step: int, end_step: int, timestep: float, log, clock=time.monotonic):
        self.label, self.start, self.end, self.timestep, self.log = label, start_step, end_step, timestep, log
        self.clock = clock
        self.last = -math.inf
        self.first = None  # (wall time, step) of the first row

    def __call__(self, row: dict) -> None:
        now = self.clock()
        step = int(row["step"])
        if self.first is None:
            self.first = (now, step)
        if now - self.last < PROGRESS_SECONDS and step < self.end:
            return
        self.last = now
        elapsed, total = (step - self.start) * self.timestep, (self.end - self.start) * self.timestep
        wall, done = now - self.first[0], step - self.first[1]
        left = max(self.end - step, 0)
        eta = timedelta(seconds=round(left * wall / done)) if done > 0 else ("0:00:00" if left == 0 else "?")
        self.log(
            f"DEM {self.label}: step {step}/{self.end}, t = {elapsed:.3f}/{total:.3f} s, "
            f"{int(row['atoms'])} particles, {-int(row['iz_sum'])} through the orifice, "
            f"elapsed {timedelta(seconds=round(wall))}, ETA {eta}"
        )


# --------------------------------------------------------------------------------------------
# Work directory state


def _digest(*parts: str | bytes) -> str:
    h = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


def _read_state(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _write_state(path: Path, state: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(state, indent=2, sort_keys=True) + "\n")
    tmp.replace(path)


def _stl_facets(data: bytes, source: Path) -> list[str]:
    """The facets of an STL file (ASCII, as the geometry stage writes, or binary) as ASCII lines."""
    text = data[:5] == b"solid" and b"facet" in data[:1024]
    if text:
        lines = data.decode(errors="replace").strip().splitlines()
        if lines[-1].startswith("endsolid"):
            return lines[1:-1]
    elif len(data) >= 84 and len(data) == 84 + 50 * int(np.frombuffer(data[80:84], "<u4")[0]):
        record = np.frombuffer(data[84:], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
        return [f"facet normal {n[0]!r} {n[1]!r} {n[2]!r}\nouter loop\n"
                + "".join(f"vertex {v[0]!r} {v[1]!r} {v[2]!r}\n" for v in vs)
                + "endloop\nendfacet" for n, vs in zip(record["n"].tolist(), record["v"].tolist())]
    raise DPHTError(f"wall mesh {source} is not an STL file (ASCII solid ... endsolid, or binary)")


def _stage_meshes(zones: tuple[str, ...], mesh_dir: Path, workdir: Path) -> bytes:
    """Write the triangles of the zone STLs, zone after zone, into ``workdir/meshes/walls.stl`` (ASCII),
    the one mesh the decks read; returns the zones' names and contents' digest."""
    target = workdir / MESH_DIR
    target.mkdir(exist_ok=True)
    h = hashlib.sha256()
    facets = []
    for zone in zones:
        source = mesh_dir / f"{zone}.stl"
        if not source.is_file() or source.stat().st_size == 0:
            raise DPHTError(f"wall mesh {source} is missing or empty; the DEM needs {', '.join(zones)} (.stl)")
        data = source.read_bytes()
        facets += _stl_facets(data, source)
        h.update(zone.encode() + hashlib.sha256(data).digest())
    (target / WALL_MESH).write_text("\n".join(["solid walls", *facets, "endsolid walls", ""]))
    return h.digest()


# --------------------------------------------------------------------------------------------
# Stages


def _ranks(params: DemParams, ranks: int, mpi: str) -> str:
    if ranks == 1:
        return "ranks = 1"
    return f"ranks = {ranks} ({mpi}), {params.z_slabs(ranks)} along the tube axis"


def _settle(params: DemParams, workdir: Path, key: str, ranks: int, mpi: str, log, lock: WorkdirLock, tag: str = "") -> dict:
    settle_dir = workdir / SETTLE_DIR
    state_path = settle_dir / "state.json"
    state = _read_state(state_path)
    # A kill between LIGGGHTS writing the settled restart and this state being marked complete leaves
    # the restart without its record: only a complete state is reused.
    if state.get("key") == key and state.get("complete") and (workdir / SETTLED_RESTART).is_file():
        log(f"DEM settle: reusing the settled bed in {settle_dir} ({state['particles']} particles)")
        return state
    steps = params.steps()
    # An interrupted settle of this very deck resumes from its newest complete restart file (written
    # once every particle is in; a packed slice has none and starts again).
    resume = _newest_restart(settle_dir, SETTLE_RESTART_GLOB) if state.get("key") == key else None
    if resume is None:
        shutil.rmtree(settle_dir, ignore_errors=True)
        (settle_dir / "post").mkdir(parents=True)  # LIGGGHTS fails silently without it
        (settle_dir / "restart").mkdir()
        _write_state(state_path, {"key": key, "complete": False})
    shutil.rmtree(workdir / FLOW_DIR, ignore_errors=True)  # a new bed invalidates the flow
    screens = _settle_screens(settle_dir)
    screen = settle_dir / ("screen.txt" if not screens else f"screen.{len(screens) + 1}.txt")
    if resume is not None:
        start, restart_file = resume
        for step, path in dumps.numbered_files(settle_dir / "restart", SETTLE_RESTART_GLOB).items():
            if step > start:
                path.unlink()
        log(f"DEM settle: resuming from {restart_file} (step {start} of {steps['settle_end']}); {_ranks(params, ranks, mpi)}")
    elif params.packed:
        log(
            f"DEM settle: packing {params.n_particles} particles (d = {params.diameter} m) to solid fraction "
            f"{params.fill_solid_fraction} over the periodic tube: inserted in a {params.pack_length * 1e3:.2f} mm box "
            f"shrinking to {params.length * 1e3:.2f} mm until step {steps['compress_end']}, at rest by step "
            f"{steps['settle_end']}; {_ranks(params, ranks, mpi)}"
        )
    else:
        log(
            f"DEM settle: inserting {params.n_particles} particles (d = {params.diameter} m) in "
            f"{steps['fill_end']} steps (or until step {steps['insert_end']} if the bed leaves no room earlier), "
            f"settling until step {steps['settle_end']}; {_ranks(params, ranks, mpi)}"
        )
    variables = {"pz": str(params.z_slabs(ranks))}
    if resume is not None:
        variables["restart_file"] = resume[1]
    wall = run_liggghts(
        "settle.in" if resume is None else "settle_resume.in",
        workdir,
        screen,
        ranks=ranks,
        mpi=mpi,
        variables=variables,
        on_thermo=_Progress(f"{tag} settle".strip(), 0 if resume is None else resume[0], steps["settle_end"],
                            params.timestep, log),  # fmt: skip
        pass_fds=(lock.fd,),
    )
    rows = [row for path in _settle_screens(settle_dir) for row in read_thermo(path)]
    if not rows or int(rows[-1]["step"]) != steps["settle_end"] or not (workdir / SETTLED_RESTART).is_file():
        raise _tool_error(
            f"LIGGGHTS finished settle.in without reaching step {steps['settle_end']} or writing {SETTLED_RESTART}.",
            screen,
        )
    inserted = int(max(row["atoms"] for row in rows))
    state = {
        "key": key,
        "complete": True,
        "attempts": len(_settle_screens(settle_dir)),
        "step": steps["settle_end"],
        "particles_target": params.n_particles,
        "particles_inserted": inserted,
        "particles": int(rows[-1]["atoms"]),
        "bed_top_m": rows[-1]["z_max"] + params.radius,
        "rayleigh_fraction_liggghts": rows[-1]["rayleigh_fraction"],
        "hertz_fraction_max": max(row["hertz_fraction"] for row in rows),
        "wall_time_s": round(wall, 2),
        "ranks": ranks,
    }
    if params.loaded:
        settled = dumps.read_dump(workdir / SETTLE_DIR / "post" / f"dump.{steps['settle_end']}.txt")
        length = float(settled.box_hi[2] - settled.box_lo[2])
        state["wall_stress_Pa"] = wall_stress(params, settled.positions, length)
        log(f"DEM settle: loaded to {state['wall_stress_Pa']:.0f} Pa on the wall (dem.drive.wall_stress "
            f"{params.wall_stress:.0f} Pa), the box shortened to {length * 1e3:.3f} mm "
            f"({100 * (1 - length / params.length):.2f}%)")
        if state["wall_stress_Pa"] < params.wall_stress:
            log(f"DEM settle: warning: the wall stress stayed below dem.drive.wall_stress after {LOAD_INCREMENTS} "
                f"shortenings of {100 * LOAD_STRAIN:g}%")
    bed = state["bed_top_m"] - params.orifice_height
    log(f"DEM settle: {state['particles']} particles settled in {wall:.0f} s; "
        + ("packed over the periodic tube" if params.packed else
           f"bed height {bed * 1e3:.1f} mm above the orifice plate (dem.fill_height {params.fill_height * 1e3:.1f} mm)"))
    if inserted < params.n_particles:
        log(f"DEM settle: warning: only {inserted} of {params.n_particles} particles could be inserted")
    if state["particles"] < inserted:
        log(f"DEM settle: warning: {inserted - state['particles']} particles left the domain while settling")
    _write_state(state_path, state)
    return state


def _settle_screens(settle_dir: Path) -> list[Path]:
    """The settle's screen files in the order of its attempts: screen.txt, then screen.<n>.txt."""
    first = [settle_dir / "screen.txt"] if (settle_dir / "screen.txt").is_file() else []
    return first + list(dumps.numbered_files(settle_dir, SCREEN_GLOB).values())


def _newest_restart(folder: Path, glob: str) -> tuple[int, str] | None:
    """Newest complete restart file ``folder/restart/<glob>`` (step, path relative to the work
    directory): one at or before a thermo line printed after it (see the module docstring)."""
    screens = [folder / "screen.txt", *folder.glob(SCREEN_GLOB)]
    reached = max((int(row["step"]) for screen in screens for row in read_thermo(screen)), default=-1)
    for step, path in reversed(dumps.numbered_files(folder / "restart", glob).items()):
        if step <= reached and path.stat().st_size > 0:
            return step, f"{folder.name}/restart/{path.name}"
    return None


def _resume_point(flow_dir: Path, settle_end: int) -> tuple[int, str]:
    """Newest complete flow restart (step, path relative to the work directory), else the settled bed."""
    return _newest_restart(flow_dir, RESTART_GLOB) or (settle_end, SETTLED_RESTART)


def _flow(params: DemParams, workdir: Path, key: str, ranks: int, mpi: str, log, lock: WorkdirLock, tag: str = "") -> dict:
    flow_dir = workdir / FLOW_DIR
    state_path = flow_dir / "state.json"
    steps = params.steps()
    state = _read_state(state_path)
    if state.get("key") == key and state.get("complete") and dumps.dump_files(flow_dir / "post"):
        return state
    if state.get("key") != key or state.get("complete"):
        if state.get("key") == key:
            log(f"DEM flow: its dumps were gathered into {workdir / POSITIONS}, which is gone or damaged; running it again")
        shutil.rmtree(flow_dir, ignore_errors=True)
        state = {"key": key, "complete": False, "attempts": []}
    for sub in ("restart", "post"):
        (flow_dir / sub).mkdir(parents=True, exist_ok=True)  # LIGGGHTS fails silently without them
    start, restart_file = _resume_point(flow_dir, steps["settle_end"])
    for step, path in dumps.numbered_files(flow_dir / "restart", RESTART_GLOB).items():
        if step > start:
            path.unlink()
    for step, path in dumps.dump_files(flow_dir / "post").items():
        if step >= start:
            path.unlink()
    attempt = 1 + max(dumps.numbered_files(flow_dir, SCREEN_GLOB), default=0)
    screen = flow_dir / f"screen.{attempt}.txt"
    if start > steps["settle_end"]:
        log(f"DEM flow: resuming from {restart_file} (step {start} of {steps['settle_end']}..{steps['flow_end']})")
    else:
        log(
            f"DEM flow: steps {steps['settle_end']}..{steps['flow_end']}, dump every {params.dump_interval}; "
            f"{_ranks(params, ranks, mpi)}"
        )
    state["attempts"].append({"start_step": start, "screen": screen.name, "ranks": ranks, "wall_time_s": None})
    _write_state(state_path, state)
    wall = run_liggghts(
        "flow.in",
        workdir,
        screen,
        ranks=ranks,
        mpi=mpi,
        variables={"restart_file": restart_file, "pz": str(params.z_slabs(ranks))},
        on_thermo=_Progress(f"{tag} flow".strip(), steps["settle_end"], steps["flow_end"], params.timestep, log),
        pass_fds=(lock.fd,),
    )
    state["attempts"][-1]["wall_time_s"] = round(wall, 2)
    rows = read_thermo(screen)
    if not rows or int(rows[-1]["step"]) != steps["flow_end"] or not dumps.dump_files(flow_dir / "post"):
        raise _tool_error(
            f"LIGGGHTS finished flow.in without reaching step {steps['flow_end']} or without writing dumps.", screen
        )
    state["complete"] = True
    state["hertz_fraction_max"] = max(
        row["hertz_fraction"] for path in flow_dir.glob(SCREEN_GLOB) for row in read_thermo(path)
    )
    if params.driven:
        state["drive_acceleration"] = _drive_record(flow_dir)
    _write_state(state_path, state)
    return state


def _drive_record(flow_dir: Path) -> list[list[float]]:
    """[step, acceleration m/s^2] of a driven flow: the controller's net body acceleration (downwards)
    averaged over each thermo interval, from every attempt's screen; the first row of an attempt is
    its start step, over which nothing has been averaged yet, and a later attempt's rows replace an
    earlier one's from its start on."""
    by_step = {}
    for _, screen in sorted(dumps.numbered_files(flow_dir, SCREEN_GLOB).items()):
        rows = read_thermo(screen, DRIVE_COLUMN)[1:]
        if rows:
            by_step = {step: a for step, a in by_step.items() if step < rows[0]["step"]}
        by_step.update((row["step"], row[DRIVE_COLUMN]) for row in rows if DRIVE_COLUMN in row)
    return [[int(step), a] for step, a in sorted(by_step.items())]


def _gather(params: DemParams, workdir: Path, out_h5: Path, key: str, settle: dict, flow: dict, log) -> dict:
    files = dumps.dump_files(workdir / (FLOW_DIR if params.flow_time > 0 else SETTLE_DIR) / "post")
    if params.flow_time == 0:
        files = {step: f for step, f in files.items() if step == params.steps()["settle_end"]}
    log(f"DEM gather: {len(files)} dump files -> {out_h5}")
    partial = out_h5.with_name(out_h5.name + ".part")
    stats = dumps.write_positions(
        partial,
        dumps.read_dumps(files.values()),
        radius=params.radius,
        density=params.density,
        timestep=params.timestep,
        dump_interval=params.dump_interval,
        precision=params.precision,
        attrs={"source_key": key, "recycled": list(RECYCLED)},
    )
    steps = params.steps()
    if stats.steps[0] != steps["settle_end"] or stats.steps[-1] != steps["flow_end"]:
        raise DPHTError(
            f"dumps in {workdir / FLOW_DIR / 'post'} cover steps {stats.steps[0]}..{stats.steps[-1]}, "
            f"expected {steps['settle_end']}..{steps['flow_end']}"
        )
    with dumps.PositionsFile(partial) as positions:
        summary = run_summary(params, settle, flow, stats, positions)
    dumps.set_summary(partial, summary)
    with h5py.File(partial, "r+") as h5:
        h5.attrs[dumps.CONTENT_DIGEST] = dumps.content_digest(h5)
    partial.replace(out_h5)
    _discard_dumps(workdir)
    flow_rate = summary["mass_flow_kg_s"]
    log(
        f"DEM done: {summary['particles']} particles, {stats.n_frames} frames, mass flow {flow_rate * 1e3:.3f} g/s "
        f"({summary['orifice_crossings']} crossings), lost {summary['lost_particles']['count']}"
    )
    drive = summary["drive"]
    if drive and drive["acceleration_over_gravity"] > 1.0:
        log(f"DEM warning: the drive pushed the bed with {drive['acceleration_over_gravity']:.2f} g on average over the "
            "second half of the flow: more than gravity, so a gravity-fed tube would not pass this flow")
    if summary["jammed"]:
        log("DEM warning: the bed stopped flowing in the last quarter of the flow (no particle left through the "
            "orifice, or a driven run moved at less than half its target velocity): the bed jammed")
    if summary["lost_particles"]["count"]:
        log(f"DEM warning: lost particles (id: first step missing) {summary['lost_particles']['first_step']}")
    return summary


def _discard_dumps(workdir: Path) -> None:
    """The text dumps, once they are in the positions file (about six times its size)."""
    for path in dumps.dump_files(workdir / FLOW_DIR / "post").values():
        path.unlink()


def _existing(path: Path, key: str) -> dict | None:
    """The stored summary of the positions file ``path`` if it was gathered from exactly this run
    and its frames are those gathered (their digest is the one stored then), else None (also for a
    truncated, foreign or damaged file)."""
    if not path.is_file():
        return None
    try:
        with h5py.File(path, "r") as h5:
            stored = h5.attrs.get(dumps.CONTENT_DIGEST)
            if h5.attrs.get("source_key") == key and stored is not None and dumps.content_digest(h5) == stored:
                return json.loads(h5.attrs["summary"])
    except (OSError, KeyError, ValueError):
        pass
    return None


def parameter_warnings(params: DemParams) -> list[str]:
    """The DEM stage's warnings that its parameters alone decide (logged before LIGGGHTS runs;
    ``dpht check`` shows them before any job)."""
    warnings = []
    if params.timestep / params.rayleigh_time > RAYLEIGH_WARN:
        warnings.append(f"DEM warning: timestep above {RAYLEIGH_WARN} of the Rayleigh time; contacts may be inaccurate")
    if params.orifice_diameter < 5.0 * params.diameter:
        warnings.append("DEM warning: orifice narrower than 5 particle diameters; the bed may jam")
    return warnings


def run_dem(
    spec: dict, mesh_dir: Path, workdir: Path, out_h5: Path, ranks: int = 1, log=print, mpi: str = DEFAULT_MPI
) -> dict:
    """Run the DEM stage (fill + settle, flow, gather) and return the run summary.

    ``spec`` holds the config sections ``particles``, ``wall``, ``contact``, ``geometry``, ``dem``;
    ``mesh_dir`` the geometry stage's output: ``geometry.json`` and one ``<zone>.stl`` per wall zone
    (tube, orifice plate, mixers); ``workdir`` keeps the rendered decks, LIGGGHTS output and restart
    files and the complete positions file, which ``out_h5`` is a copy of (Snakemake deletes
    ``out_h5`` before it runs a job again; the work copy survives); with ``ranks`` > 1 LIGGGHTS
    runs under the MPI launcher ``mpi`` (``mpirun``, ``srun``, ...). Calling again after an
    interruption resumes; once the positions file is complete it is a no-op (publishing the work
    copy again if ``out_h5`` is gone or damaged), except that the second-half mass flow is checked
    again against the target (dem.target_mass_flow, dem.mass_flow_tolerance) in the returned
    summary, which never re-runs LIGGGHTS.
    """
    mesh_dir, workdir, out_h5 = Path(mesh_dir), Path(workdir), Path(out_h5)
    params = DemParams.from_spec(spec, read_geometry(mesh_dir))
    target = mass_flow_target(spec)
    if isinstance(ranks, bool) or not isinstance(ranks, int) or ranks < 1:
        raise DPHTError(f"ranks = {ranks!r}: expected a positive integer (MPI ranks)")
    fraction = params.timestep / params.rayleigh_time
    log(f"DEM: timestep {params.timestep} s = {fraction:.3f} of the Rayleigh time {params.rayleigh_time:.3e} s")
    if fraction > RAYLEIGH_MAX:
        raise ConfigError(
            f"dem.timestep = {params.timestep} s is {fraction:.2f} of the Rayleigh time {params.rayleigh_time:.3e} s; "
            f"keep it below {RAYLEIGH_WARN} (at most {RAYLEIGH_WARN * params.rayleigh_time:.2e} s)"
        )
    for warning in parameter_warnings(params):
        log(warning)
    workdir.mkdir(parents=True, exist_ok=True)
    out_h5.parent.mkdir(parents=True, exist_ok=True)
    with WorkdirLock(workdir, ".dem.lock", "DEM") as lock:
        mesh_digest = _stage_meshes(params.mesh_zones, mesh_dir, workdir)
        decks = render_decks(params)
        for name, text in decks.items():
            (workdir / name).write_text(text)
        settle_key = _digest(decks["settle.in"], decks.get("settle_resume.in", ""), mesh_digest)
        flow_key = _digest(settle_key, decks["flow.in"])
        gather_key = _digest(flow_key, json.dumps(asdict(params), sort_keys=True))
        work_h5 = workdir / POSITIONS  # the complete file; out_h5 is a copy of it
        summary = _existing(out_h5, gather_key)
        if summary is not None:
            log(f"DEM: {out_h5} is up to date")
            if not work_h5.exists():
                publish(out_h5, work_h5)  # gathered before work copies were kept: keep one now
        elif (summary := _existing(work_h5, gather_key)) is not None:
            log(f"DEM: {out_h5} is the complete {work_h5} of an earlier run of this stage")
            publish(work_h5, out_h5)
            _discard_dumps(workdir)
        else:
            tag = out_h5.parent.name  # results/dem/<key>/: the stage key
            settle = _settle(params, workdir, settle_key, ranks, mpi, log, lock, tag)
            if params.flow_time > 0:
                flow = _flow(params, workdir, flow_key, ranks, mpi, log, lock, tag)
            else:  # a static bed: its one frame is the settled bed
                log("DEM: dem.flow_time = 0, a static bed: no flow phase; the positions file holds the settled bed")
                flow = {"attempts": [], "hertz_fraction_max": settle["hertz_fraction_max"]}
            summary = _gather(params, workdir, work_h5, gather_key, settle, flow, log)
            publish(work_h5, out_h5)
        # The check rides along in the returned summary (summary.json), never in the positions file.
        check = mass_flow_check(summary["mass_flow_second_half_kg_s"], *target) if target else None
        summary["mass_flow_target"] = check
    if check and check["off_target"]:
        log(
            f"DEM warning: mass flow {check['measured_kg_s'] * 1e3:.3f} g/s (second half) is "
            f"{check['relative_error']:+.1%} off the target {check['target_kg_s'] * 1e3:.3f} g/s "
            f"(dem.mass_flow_tolerance {check['tolerance']:.0%}); adjust geometry.tube.orifice_diameter, "
            "e.g. with 'python -m dpht calibrate-orifice'"
        )
    return summary


# --------------------------------------------------------------------------------------------
# LIGGGHTS' own time-step check


def liggghts_rayleigh_fraction(params: DemParams, workdir: Path) -> float:
    """dem.timestep over the Rayleigh time as LIGGGHTS' fix check/timestep/gran reports it for the
    stage's model and materials (a run of :func:`render_check_deck` in ``workdir``; under a second)."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "check.in").write_text(render_check_deck(params))
    screen = workdir / "check.screen.txt"
    run_liggghts("check.in", workdir, screen)
    rows = read_thermo(screen)
    if not rows or rows[-1]["rayleigh_fraction"] <= 0.0:
        raise _tool_error("LIGGGHTS printed no time-step check running check.in.", screen)
    return rows[-1]["rayleigh_fraction"]
