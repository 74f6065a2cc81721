"""Fault injection: the tiny workflow killed in every stage (geometry, DEM settle, DEM flow, HTC
tables, thermal, figures) at random points, in random ways, over repeated runs, each run resumed
until the workflow completes. After every kill no file that looks complete may be partial; at the
end every result equals that of the stage run uninterrupted on the same inputs: bitwise for the
deterministic stages, and for the DEM bitwise up to its first resumed frame (LIGGGHTS granular runs
do not restart bit-exactly), the rest within the restart tolerance.

``DPHT_FAULT_KILLS`` (default 1) kills per stage; ``make faults`` runs the long variant (3 each).
``DPHT_FAULT_SEED`` repeats a run (the seed is printed with ``pytest -s`` and in failures).

Results damaged on disk between runs (deleted, cut short, bytes flipped inside, data altered in
place with the file's time kept): every kind of result once, each in one of the four ways
(``DPHT_DAMAGE_ROUNDS``, default 1; ``make faults``: 4 rounds, every kind in every way).
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht import config
from dpht.dem.liggghts import read_thermo
from dpht.plan import FIGURES, Plan, path
from dpht.thermal.stage import reproducible
from dpht.util.processes import stage_processes
from test_interrupts import STOP_SECONDS, processes_in, wait_for
from test_workflow import SNAKEMAKE, end_to_end, write_config

KILLS = int(os.environ.get("DPHT_FAULT_KILLS", "1"))
SEED = int(os.environ.get("DPHT_FAULT_SEED", np.random.default_rng().integers(1 << 31)))
TARGETS = ("geometry", "dem:settle", "dem:flow", "screening", "htc_table", "thermal", "figures")
KINDS = ("SIGINT to snakemake", "SIGTERM to snakemake", "SIGKILL to snakemake", "SIGKILL to the stage",
         "machine lost")  # fmt: skip
# The DEM on 2 MPI ranks (as the default; the same decks on the same processor grid give the same
# run, so its frames before a resume compare bit for bit); thermal checkpoints every 10 of its 61
# frames (not part of the key).
OVERRIDES = {"dem": {"ranks": 2}, "thermal": {"checkpoint_frames": 10}}


# A DEM attempt is killed within the first DEM_SHARE of the steps it runs: near their end the stage
# may finish before its last rows are seen.
DEM_SHARE = 2 / 3


def _attempt_screen(folder: Path) -> Path | None:
    """The screen file of the newest LIGGGHTS attempt in a DEM work folder (``settle`` or ``flow``):
    ``screen.txt`` (a first settle), then ``screen.<n>.txt`` by attempt."""
    screens = [folder / "screen.txt"] if (folder / "screen.txt").is_file() else []
    screens += sorted(folder.glob("screen.*.txt"), key=lambda p: int(p.name.split(".")[1]))
    return screens[-1] if screens else None


def _deck_steps(deck: Path) -> tuple[int, int]:
    """(the step its last run ends on, the thermo interval) of a DEM deck the stage rendered."""
    text = deck.read_text()
    return int(re.findall(r"^run (\d+) upto", text, re.M)[-1]), int(re.search(r"^thermo (\d+)", text, re.M).group(1))


def _stage_name(pid: int) -> str | None:
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
    except OSError:
        return None
    return argv[argv.index("stage") + 1] if "stage" in argv else None


class Faults:
    """The workflow in ``folder``, run again and again and killed at random points."""

    def __init__(self, folder: Path, rng: np.random.Generator):
        folder.mkdir(parents=True)
        self.folder, self.rng = folder.resolve(), rng
        write_config(folder / "tiny.yaml", OVERRIDES)
        self.command = [*SNAKEMAKE, "--directory", str(self.folder), "--configfile", str(folder / "tiny.yaml")]
        self.killed = Counter()
        self.log = []  # (target, how, at what point, seconds until every process had ended)

    def _running(self, snakemake: int) -> dict[str, int]:
        """target -> pid of the stage process now running it."""
        running = {}
        for pid in stage_processes(snakemake):
            name = _stage_name(pid)
            if name == "dem":
                work = next(self.folder.glob("results/dem/*/work"), None)
                flow = work is not None and any(read_thermo(p) for p in work.glob("flow/screen.*.txt"))
                running["dem:flow" if flow else "dem:settle"] = pid
            elif name is not None:
                running[name] = pid
        return running

    def _kill_point(self, target: str):
        """A random point of ``target``'s run: (a description of it, a predicate over the seconds
        since the stage was first seen); the description is complete once the point is reached."""
        rng = self.rng
        if target in ("dem:settle", "dem:flow"):
            return self._dem_kill_point(target, float(rng.uniform()))
        if target == "thermal":  # a random frame: past a random checkpoint, then up to 9 frames more
            frames, extra = 10 * int(rng.integers(0, 5)), float(rng.uniform(0.0, 0.5))
            state = {}

            def reached(_):
                checkpoint = next(self.folder.glob("results/thermal/*/work/checkpoint.h5"), None)
                try:
                    with h5py.File(checkpoint) as f:
                        saved = int(f.attrs["count"])
                except (OSError, KeyError, TypeError):
                    saved = 0
                if saved >= frames and "since" not in state:
                    state["since"] = time.monotonic()
                return "since" in state and time.monotonic() - state["since"] >= extra

            return (lambda: f"frame {frames} + {extra:.2f} s"), reached
        delay = float(rng.uniform(0.0, {"geometry": 2.0, "screening": 2.0, "htc_table": 0.8, "figures": 4.0}[target]))
        return (lambda: f"{delay:.2f} s in"), (lambda seconds: seconds >= delay)

    def _dem_kill_point(self, target: str, share: float):
        """A thermo step of the DEM attempt now starting, ``share`` of the way through the first
        DEM_SHARE of the steps it still runs: from its first thermo row (step 0, or the step of the
        restart file a resumed attempt reads) to the last step of its deck. So a resumed attempt,
        which runs fewer steps than the first, is killed within them too."""
        planned, point = time.time(), {}
        folder, deck = ("settle", "settle.in") if target == "dem:settle" else ("flow", "flow.in")

        def reached(_):
            work = next(self.folder.glob("results/dem/*/work"), None)
            screen = _attempt_screen(work / folder) if work is not None else None
            # Rows of this attempt: of a screen file LIGGGHTS has written since the plan was made.
            rows = read_thermo(screen) if screen is not None and screen.stat().st_mtime > planned else []
            if not rows:
                return False
            if not point:
                start, (end, every) = int(rows[0]["step"]), _deck_steps(work / deck)
                intervals = math.ceil(share * DEM_SHARE * (end - start) / every)
                point.update(start=start, step=min(end, start + every * max(1, intervals)))
            return int(rows[-1]["step"]) >= point["step"]

        def describe():
            return f"thermo step {point['step']} ({point['start']}..)" if point else f"{share:.2f} of its steps"

        return describe, reached

    def _kill(self, how: str, snakemake: subprocess.Popen, stage: int) -> None:
        if how == "machine lost":  # everything at once (MPI ranks have their own process groups)
            for pid in [snakemake.pid, *processes_in(self.folder)]:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        elif how == "SIGKILL to the stage":
            os.kill(stage, signal.SIGKILL)
        else:
            snakemake.send_signal(getattr(signal, how.split()[0]))

    def run_once(self) -> bool:
        """One start of the workflow, killed in the first stage still owed a kill; True once the
        workflow has completed."""
        output = open(self.folder / f"snakemake.{len(self.log)}.txt", "w")
        snakemake = subprocess.Popen(self.command, start_new_session=True, stdout=output, stderr=subprocess.STDOUT)
        try:
            return self._monitor(snakemake, output)
        except BaseException:  # a failed check: leave nothing running
            self._kill("machine lost", snakemake, None)
            raise

    def _monitor(self, snakemake: subprocess.Popen, output) -> bool:
        plans, seen = {}, {}
        while snakemake.poll() is None:
            now = time.monotonic()
            for target, pid in self._running(snakemake.pid).items():
                if target not in TARGETS or self.killed[target] >= KILLS:
                    continue
                if target not in plans:
                    plans[target], seen[target] = self._kill_point(target), now
                describe, reached = plans[target]
                if reached(now - seen[target]) and Path(f"/proc/{pid}").exists():
                    how = str(self.rng.choice(KINDS))
                    sent = time.monotonic()
                    self._kill(how, snakemake, pid)
                    # After a failed job Snakemake lets the others finish (a DEM run, say); else all stop.
                    limit = 900 if how == "SIGKILL to the stage" else STOP_SECONDS
                    wait_for(lambda: not processes_in(self.folder, exclude={snakemake.pid}), limit,
                             f"the run's processes to end after {how} in {target}")  # fmt: skip
                    snakemake.wait(timeout=STOP_SECONDS)
                    output.close()
                    self.log.append((target, how, describe(), round(time.monotonic() - sent, 2)))
                    self.killed[target] += 1
                    assert_nothing_partial(self.folder)
                    if how in ("SIGKILL to snakemake", "machine lost"):
                        subprocess.run([*self.command[:-2], "--unlock", *self.command[-2:]], capture_output=True, check=True)
                    return False
            time.sleep(0.02)
        output.close()
        assert snakemake.returncode == 0, Path(output.name).read_text()[-3000:]
        return True


# --- files that look complete ---------------------------------------------------------------


def _partial(path: Path) -> str | None:
    """Why ``path``, a file at a final name, is not complete (None if it is)."""
    data = path.read_bytes()
    suffix = path.suffix
    try:
        if suffix == ".h5":
            with h5py.File(path, "r") as f:
                return None if f.attrs.get("complete", True) else "HDF5 file marked incomplete"
        if suffix == ".json":
            json.loads(data)
        elif suffix == ".png":
            return None if data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82") else "PNG cut short"
        elif suffix == ".csv":
            return None if data.endswith(b"\n") and len(data.splitlines()) > 1 else "CSV cut short"
        elif suffix == ".xdmf":
            ET.fromstring(data)
        elif suffix == ".stl":
            if data.startswith(b"solid"):  # ASCII
                return None if data.rstrip().split(b"\n")[-1].startswith(b"endsolid") else "STL cut short"
            return None if len(data) == 84 + 50 * int.from_bytes(data[80:84], "little") else "STL cut short"
        elif suffix == ".msh":
            return None if data.rstrip().endswith(b"$EndElements") else "gmsh file cut short"
    except (OSError, ValueError, ET.ParseError) as error:
        return str(error)
    return None


def assert_nothing_partial(folder: Path) -> None:
    """Every result file at its final name (not a hidden temporary) in results/ and tables/ is
    complete, and so is every HDF5 file in the stages' work directories (positions, checkpoints,
    segments and complete outputs, which their stages reuse)."""
    bad = {}
    for root in (folder / "results", folder / "tables"):
        for path in root.rglob("*"):
            parts = path.relative_to(folder).parts
            if not path.is_file() or path.is_symlink() or any(p.startswith(".") for p in parts):
                continue
            if "work" in parts and path.suffix != ".h5":
                continue  # a stage's own files (restart files, dumps, mesh copies): rewritten or checked by it
            if (why := _partial(path)) is not None:
                bad[str(path.relative_to(folder))] = why
    assert not bad, bad


# --- the same stages uninterrupted ------------------------------------------------------------


def _stage(name: str, spec: str, inputs: dict, outputs: dict, threads: int = 1, mpi: dict | None = None) -> None:
    io = {"input": {k: str(v) for k, v in inputs.items()}, "output": {k: str(v) for k, v in outputs.items()},
          "threads": threads}  # fmt: skip
    if mpi:
        io["mpi"] = mpi
    io = json.dumps(io)
    done = subprocess.run([sys.executable, "-m", "dpht", "stage", name, "--spec", spec, "--io", io],
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]


def h5_contents(path: Path, skip=("summary",)) -> dict:
    contents = {}
    with h5py.File(path) as f:
        f.visititems(lambda name, obj: contents.__setitem__(name, obj[...]) if isinstance(obj, h5py.Dataset) else None)
        contents.update({f"@{k}": v for k, v in f.attrs.items() if k not in skip})
    return contents


def assert_same(a: dict, b: dict, what: str) -> None:
    assert a.keys() == b.keys(), what
    for name in a:
        x, y = np.asarray(a[name]), np.asarray(b[name])
        assert x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f"{what}: {name}"


def without_sources(data: dict) -> dict:
    for record in data.get("solid_fraction", {}).values():  # names the DEM summary it read, where the run read it
        record.pop("source", None)
    return data


def without_timings(summary: str) -> dict:
    return without_sources(reproducible(json.loads(summary)))


@end_to_end
def test_killed_everywhere_the_workflow_still_gives_the_uninterrupted_results(tmp_path):
    rng = np.random.default_rng(SEED)
    faults = Faults(tmp_path / "faults", rng)
    started = time.monotonic()
    while not faults.run_once():
        assert time.monotonic() - started < 1800, (SEED, faults.log)
    seconds = time.monotonic() - started
    print(f"\nseed {SEED}: {len(faults.log)} kills, workflow completed in {seconds:.0f} s")
    for entry in faults.log:
        print("  %-10s %-22s at %-18s everything ended %5.2f s later" % entry)
    missed = [t for t in TARGETS if faults.killed[t] < KILLS]
    # The DEM and thermal kill points are progress points, always reached; the short stages may
    # end before their random delay (then they ran to completion unharmed).
    assert not set(missed) & {"dem:settle", "dem:flow", "thermal"}, (SEED, faults.log)
    assert len(missed) <= 2, (SEED, missed, faults.log)
    assert_nothing_partial(faults.folder)
    again = subprocess.run([*faults.command[:-2], "--dry-run", *faults.command[-2:]], capture_output=True, text=True)
    assert "Nothing to be done" in again.stdout + again.stderr

    # Every stage again, uninterrupted, on the faulted run's own inputs.
    cfg = config.validate(yaml.safe_load((faults.folder / "tiny.yaml").read_text()))
    plan, run = Plan(cfg), faults.folder
    keys = plan.keys["base"]
    ref = tmp_path / "reference"
    def screened(key):
        return json.loads((run / path("screening", key, "screening.json")).read_text())["decisions"]

    at = {name: run / file for name, file in plan.thermal_inputs(keys["thermal"], screened).items()}
    geometry = {"walls": ref / "geometry" / "walls.h5", "summary": ref / "geometry" / "geometry.json",
                "picture": ref / "geometry" / "geometry.png"}  # fmt: skip
    _stage("geometry", plan.spec_json(keys["geometry"]), {}, geometry)
    assert_same(h5_contents(geometry["walls"]), h5_contents(at["walls"]), "walls.h5")
    for stl in (run / plan.variant_file("base", "geometry")).glob("*.stl"):
        assert (ref / "geometry" / stl.name).read_bytes() == stl.read_bytes(), stl.name
    for kind in ("pfp", "pfw"):
        htc_inputs = {name: run / file for name, file in plan.htc_inputs(keys[kind]).items()}  # a measured solid fraction
        _stage("htc_table", plan.spec_json(keys[kind]), htc_inputs, {"table": ref / f"{kind}.h5"})
        assert_same(h5_contents(ref / f"{kind}.h5"), h5_contents(at[kind]), f"{kind} table")
    dem = {"positions": ref / "dem" / "positions.h5", "summary": ref / "dem" / "summary.json"}
    _stage("dem", plan.spec_json(keys["dem"]), {"walls": at["walls"], "geometry": at["walls"].with_name("geometry.json")},
           dem, mpi={"launcher": "mpirun", "ranks": 2})  # fmt: skip
    _compare_dem(dem["positions"], at["positions"], (faults.folder / "tiny.yaml"))
    screening_inputs = {name: run / file for name, file in plan.screening_inputs(keys["screening"]).items()}
    _stage("screening", plan.spec_json(keys["screening"]), screening_inputs, {"screening": ref / "screening.json"})
    decided = [without_sources(json.loads(file.read_text())) for file in (ref / "screening.json", at["screening"])]
    assert decided[0] == decided[1]
    thermal = {"thermal": ref / "thermal" / "thermal.h5", "xdmf": ref / "thermal" / "thermal.xdmf",
               "summary": ref / "thermal" / "summary.json"}  # fmt: skip
    _stage("thermal", plan.spec_json(keys["thermal"]), at, thermal, threads=2)
    ours = run / plan.variant_file("base", "thermal", "thermal.h5")
    assert_same(h5_contents(thermal["thermal"]), h5_contents(ours), "thermal.h5")
    with h5py.File(thermal["thermal"]) as a, h5py.File(ours) as b:
        assert without_timings(a.attrs["summary"]) == without_timings(b.attrs["summary"])
    figures = {name: ref / "figures" / f"{name}.png" for name in FIGURES}
    _stage("figures", plan.figures_spec("base"), plan_inputs(plan.figures_inputs("base"), run), figures)
    for csv in (run / "results" / "tiny" / "base" / "figures").glob("*.csv"):
        assert (ref / "figures" / csv.name).read_bytes() == csv.read_bytes(), csv.name
    for name in FIGURES:
        assert (ref / "figures" / f"{name}.png").read_bytes() == (run / "results" / "tiny" / "base" / "figures" / f"{name}.png").read_bytes(), name


def plan_inputs(inputs: dict, root: Path) -> dict:
    return {name: root / file for name, file in inputs.items()}


def _compare_dem(reference: Path, ours: Path, cfg_file: Path) -> None:
    """Frames before the first resumed flow step are bitwise the uninterrupted run's; after it the
    trajectories part (granular flow is chaotic, restarts are not bit-exact), so the mass flow is
    compared within the tolerance seen between resumed and uninterrupted runs."""
    with h5py.File(reference) as a, h5py.File(ours) as b:
        assert np.array_equal(a["step"][...], b["step"][...]) and np.array_equal(a["ids"][...], b["ids"][...])
        summary_a, summary_b = json.loads(a.attrs["summary"]), json.loads(b.attrs["summary"])
        resumed = summary_b["flow_attempts"][1:]
        exact = np.searchsorted(b["step"][...], min(resumed), side="right") if resumed else b["step"].size
        for name in ("positions", "image", "lost"):
            assert np.array_equal(a[name][:exact], b[name][:exact], equal_nan=True), name
    assert summary_a["particles"] == summary_b["particles"]
    if not resumed:
        assert summary_a["orifice_crossings"] == summary_b["orifice_crossings"]
    # Measured here: a 0.3 s flow resumed once ends within 1% of the uninterrupted crossings.
    assert summary_b["mass_flow_kg_s"] == pytest.approx(summary_a["mass_flow_kg_s"], rel=0.1)


# --- results damaged on disk between runs ------------------------------------------------------

# Every kind of result the tiny workflow keeps: (name, path in the workflow folder given the plan's
# keys of the variant "base").
ARTEFACTS = (
    ("geometry walls.h5", lambda k: path("geometry", k["geometry"], "walls.h5")),
    ("DEM positions.h5", lambda k: path("dem", k["dem"], "positions.h5")),
    ("DEM summary.json", lambda k: path("dem", k["dem"], "summary.json")),
    ("HTC table", lambda k: path("pfw", k["pfw"], "")),
    ("screening.json", lambda k: path("screening", k["screening"], "screening.json")),
    ("thermal.h5", lambda k: path("thermal", k["thermal"], "thermal.h5")),
    ("thermal summary.json", lambda k: path("thermal", k["thermal"], "summary.json")),
    ("figure PNG", lambda k: "results/tiny/base/figures/wall_heat_flux.png"),
    ("figure JSON", lambda k: "results/tiny/base/figures/engineering.json"),
    ("variant summary.json", lambda k: "results/tiny/base/summary.json"),
)
DAMAGES = ("delete", "truncate", "flip bytes inside", "alter data in place")


def damage_file(file: Path, how: str, rng: np.random.Generator) -> None:
    """Damage ``file`` as a disk, a copy or a person might; its modification time is kept (so
    Snakemake's own time check cannot see it)."""
    stat = file.stat()
    data = file.read_bytes()
    if how == "delete":
        file.unlink()
        return
    if how == "truncate":
        file.write_bytes(data[: len(data) // 2])
    elif how == "flip bytes inside":  # up to 20 kB of random bytes in the middle, the size kept
        start, n = len(data) // 3, min(20_000, len(data) // 3)
        with open(file, "r+b") as f:
            f.seek(start)
            f.write(rng.integers(0, 256, n, dtype=np.uint8).tobytes())
    elif file.suffix == ".h5":  # a valid file with other numbers in its largest dataset
        with h5py.File(file, "r+") as f:
            datasets = []
            f.visititems(lambda name, obj: datasets.append(obj) if isinstance(obj, h5py.Dataset) and obj.size else None)
            largest = max(datasets, key=lambda d: d.size)
            values = largest[...]
            values.flat[values.size // 2] = values.flat[values.size // 2] + 1 if values.dtype.kind in "iuf" else values.flat[0]
            largest[...] = values
    elif file.suffix == ".json":  # valid JSON, one number changed
        text = data.decode()
        digit = next(k for k, c in enumerate(text) if c.isdigit() and k > len(text) // 2)
        file.write_text(text[:digit] + str((int(text[digit]) + 1) % 10) + text[digit + 1:])
    else:  # an image: one pixel row's bytes changed, the chunk checksums left stale
        with open(file, "r+b") as f:
            f.seek(len(data) // 2)
            f.write(bytes(255 - b for b in data[len(data) // 2: len(data) // 2 + 16]))
    os.utime(file, ns=(stat.st_atime_ns, stat.st_mtime_ns))


def result_contents(folder: Path, keys: dict) -> dict:
    """What the workflow's results hold (their data, for HDF5 files)."""
    contents = {}
    for name, where in ARTEFACTS:
        file = folder / where(keys)
        if file.suffix == ".h5":
            contents[name] = h5_contents(file, skip=("summary", "created"))
        elif file.suffix == ".json":
            contents[name] = json.loads(file.read_text())
        else:
            contents[name] = file.read_bytes()
    return contents


DAMAGE_ROUNDS = int(os.environ.get("DPHT_DAMAGE_ROUNDS", "1"))  # rounds of damage; round r shifts the ways by r


@end_to_end
def test_every_result_damaged_on_disk_is_found_and_made_again(tmp_path):
    """Every kind of result damaged in one of four ways (each way on several kinds; ``make faults``
    runs every kind in every way), then the workflow run again: each is named in a warning, a dry
    run changes nothing, the run remakes what was damaged without running LIGGGHTS or the thermal
    integration again (their work copies are intact), and the results equal the undamaged run's."""
    rng = np.random.default_rng(SEED)
    folder = tmp_path / "damage"
    folder.mkdir()
    write_config(folder / "tiny.yaml")
    command = [*SNAKEMAKE, "--directory", str(folder), "--configfile", str(folder / "tiny.yaml")]
    first = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert first.returncode == 0, first.stderr[-3000:]
    keys = Plan(config.validate(yaml.safe_load((folder / "tiny.yaml").read_text()))).keys["base"]
    reference = result_contents(folder, keys)
    for round_ in range(DAMAGE_ROUNDS):
        damaged = {}
        for k, (name, where) in enumerate(ARTEFACTS):
            how = DAMAGES[(k + round_) % len(DAMAGES)]
            damage_file(folder / where(keys), how, rng)
            damaged[name] = (where(keys), how)
        before = {p: p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file() and ".snakemake" not in p.parts}
        dry = subprocess.run([*command[:-2], "--dry-run", *command[-2:]], capture_output=True, text=True, timeout=300)
        assert dry.returncode == 0, dry.stderr[-3000:]
        after = {p: p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file() and ".snakemake" not in p.parts}
        assert after == before, "a dry run changed files"
        again = subprocess.run(command, capture_output=True, text=True, timeout=900)
        assert again.returncode == 0, again.stderr[-3000:]
        for name, (file, how) in damaged.items():
            assert file in again.stderr, f"round {round_}: {name} ({how}) was not reported"
            assert file in dry.stderr, f"round {round_}: {name} ({how}) was not reported by the dry run"
        dem_log = (folder / path("dem", keys["dem"], "dem.log")).read_text().split("=== stage dem")[-1]
        assert "earlier run of this stage" in dem_log and "DEM settle" not in dem_log  # no LIGGGHTS
        thermal_log = (folder / path("thermal", keys["thermal"], "thermal.log")).read_text().split("=== stage thermal")[-1]
        assert "earlier run of these inputs" in thermal_log
        ours = result_contents(folder, keys)
        for name in reference:
            if name.endswith(".h5") or name == "HTC table":
                assert_same(ours[name], reference[name], f"round {round_}: {name}")
            else:
                assert ours[name] == reference[name], f"round {round_}: {name}"
        assert_nothing_partial(folder)
        dry = subprocess.run([*command[:-2], "--dry-run", *command[-2:]], capture_output=True, text=True, timeout=300)
        assert "Nothing to be done" in dry.stdout + dry.stderr, dry.stderr[-3000:]
        for aside in folder.rglob("*.damaged"):
            aside.unlink()
