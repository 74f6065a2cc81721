"""Interruptions of the real workflow (snakemake, LIGGGHTS under mpirun, the stages) on the tiny
scene: signals sent to snakemake alone stop LIGGGHTS, the stage, mpirun and its ranks die with
their parent, a complete output an interrupted run wrote is kept, a retry refused by the DEM lock
keeps the running job's log. Times are printed (``pytest -s``) and asserted loosely."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dem_scene import SPEC, needs_liggghts, spec_with, tube_meshes
from dpht.dem.dumps import PositionsFile
from dpht.dem.liggghts import read_thermo
from dpht.stages import LOG_HEADER
from test_workflow import SNAKEMAKE, write_config

pytestmark = [needs_liggghts, pytest.mark.slow]

STOP_SECONDS = 20.0  # everything below snakemake ends this soon after a signal (measured: 1-5 s)


def processes_in(folder: Path, exclude=()) -> dict[int, str]:
    """pid -> command name of the processes whose working directory lies in ``folder``."""
    found = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) in exclude:
            continue
        try:
            if Path(os.readlink(proc / "cwd")).is_relative_to(folder) and (proc / "stat").read_text().split()[2] != "Z":
                found[int(proc.name)] = (proc / "comm").read_text().strip()
        except OSError:
            continue
    return found


def wait_for(condition, timeout: float, what: str, poll: float = 0.1):
    deadline = time.monotonic() + timeout
    while not (result := condition()):
        assert time.monotonic() < deadline, f"timed out after {timeout} s waiting for {what}"
        time.sleep(poll)
    return result


class Workflow:
    """The tiny workflow in ``folder``, started and interrupted like a user or a scheduler would."""

    def __init__(self, folder: Path, overrides: dict):
        self.folder = folder.resolve()
        write_config(folder / "tiny.yaml", overrides)
        self.command = [*SNAKEMAKE, "--directory", str(self.folder), "--configfile", str(folder / "tiny.yaml")]

    def start(self) -> subprocess.Popen:
        # Its own session: a signal goes to snakemake alone, as `kill -INT <pid>` or a scheduler sends it.
        self.proc = subprocess.Popen(self.command, start_new_session=True, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)  # fmt: skip
        return self.proc

    def dem_dir(self) -> Path | None:
        found = list(self.folder.glob("results/dem/*/work"))
        return found[0].parent if found else None

    def flow_attempt(self) -> tuple[int, list[dict]]:
        """(number, thermo rows) of the DEM flow's newest attempt ((0, []) before the flow)."""
        dem = self.dem_dir()
        screens = sorted(dem.glob("work/flow/screen.*.txt"), key=lambda p: int(p.name.split(".")[1])) if dem else []
        return (len(screens), read_thermo(screens[-1])) if screens else (0, [])

    def interrupt(self, sig: int) -> tuple[float, dict]:
        """Send ``sig`` to snakemake alone; returns the seconds until every process of the run
        (the stage, mpirun, the ranks; snakemake unless SIGKILLed) has ended, and what was running."""
        running = processes_in(self.folder, exclude={self.proc.pid})
        sent = time.monotonic()
        self.proc.send_signal(sig)
        wait_for(lambda: not processes_in(self.folder, exclude={self.proc.pid}), STOP_SECONDS, "the run's processes to end")
        self.proc.wait(timeout=STOP_SECONDS)
        return time.monotonic() - sent, running

    def unlock(self):
        assert subprocess.run([*self.command[:-2], "--unlock", *self.command[-2:]], capture_output=True).returncode == 0


@pytest.fixture
def flow(tmp_path):
    # 1 s of flow with a restart file every 2000 steps: long enough to be interrupted four times
    # (LIGGGHTS runs ~20,000 steps of this scene between a signal and its end: mpirun holds SIGTERM
    # for a second before it passes it on to the ranks).
    return Workflow(tmp_path, {"dem": {"flow_time": 1.0, "restart_interval": 2000, "ranks": 2}})


def test_signals_to_snakemake_alone_stop_liggghts_and_nothing_complete_is_redone(flow):
    report = {}
    reached = []
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        before = flow.flow_attempt()[0]
        flow.start()
        # Interrupt once this attempt has gone past a restart file (7 dumps of 500 steps > 2000 steps).
        wait_for(lambda: flow.flow_attempt()[0] > before and len(flow.flow_attempt()[1]) >= 7, 600, "the DEM flow")
        seconds, running = flow.interrupt(sig)
        assert {"liggghts", "mpirun"} <= set(running.values()), running  # LIGGGHTS was running under mpirun
        reached.append(int(flow.flow_attempt()[1][-1]["step"]))
        report[signal.Signals(sig).name] = round(seconds, 2)
        if sig == signal.SIGKILL:
            flow.unlock()  # Snakemake cannot remove its lock when it is killed
    # An interruption just after the positions file was written, before Snakemake recorded the job.
    flow.start()
    positions = wait_for(lambda: list(flow.folder.glob("results/dem/*/positions.h5")), 900, "positions.h5", poll=0.02)[0]
    flow.proc.kill()
    flow.proc.wait()
    wait_for(lambda: not processes_in(flow.folder), STOP_SECONDS, "the stage to end")
    flow.unlock()
    target = str(positions.relative_to(flow.folder))  # the DEM job only: what comes after it is tested elsewhere
    done = subprocess.run([*flow.command[:-2], target, *flow.command[-2:]], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    log = (positions.parent / "dem.log").read_text()
    last = log[log.rindex(LOG_HEADER):]  # the log keeps every attempt; the last one only publishes
    assert "earlier run of this stage" in last and "DEM flow" not in last and "DEM settle" not in last, log
    with PositionsFile(positions) as dem:
        np.testing.assert_array_equal(np.diff(dem.steps), 500)
        assert dem.n_frames == 201  # 1 s of flow, a frame every 500 steps of 1e-5 s, both ends
        attempts = dem.summary["flow_attempts"]
        assert max(reached) < dem.steps[-1], "a signal to snakemake did not stop the DEM flow"
    assert len(attempts) == 4 and attempts == sorted(attempts), attempts  # first run + three resumes
    print("seconds from the signal to snakemake until LIGGGHTS, mpirun, the ranks and the stage ended:", report)


def test_retry_refused_by_the_dem_lock_keeps_the_running_jobs_log(tmp_path):
    """A second DEM stage on the same work directory is refused without truncating the log of the
    one running; if the log is removed (Snakemake does, before it starts a job again) the running
    stage writes it again in full. SIGTERM then stops the stage and LIGGGHTS."""
    meshes = tube_meshes(tmp_path / "geometry")
    out = tmp_path / "dem" / "positions.h5"
    io = json.dumps({"input": {"walls": str(meshes / "walls.h5"), "geometry": str(meshes / "geometry.json")},
                     "output": {"positions": str(out), "summary": str(out.with_name("summary.json"))}, "threads": 1,
                     "mpi": {"launcher": "mpirun", "ranks": 1}})
    log = tmp_path / "dem" / "dem.log"
    command = [sys.executable, "-m", "dpht", "stage", "dem", "--spec", json.dumps(spec_with(flow_time=2.0)), "--io", io,
               "--log", str(log)]  # fmt: skip
    running = subprocess.Popen(command, stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: log.is_file() and "DEM settle: inserting" in log.read_text(), 120, "the DEM to start")
        first = log.read_text()
        retry = subprocess.run(command, capture_output=True, text=True, timeout=120)
        assert retry.returncode == 1 and "is in use by another run" in retry.stderr
        # the refused attempt logs beside the running one's log (dem.<pid>.log), never into it
        assert log.read_text().startswith(first) and "is in use by another run" not in log.read_text()
        beside = [f for f in log.parent.glob("dem.*.log")]
        assert len(beside) == 1 and "is in use by another run" in beside[0].read_text()
        log.unlink()
        wait_for(lambda: log.is_file() and "DEM settle: inserting" in log.read_text(), 60,
                 "the running stage to write its log again")
        sent = time.monotonic()
        running.send_signal(signal.SIGTERM)
        assert running.wait(timeout=STOP_SECONDS) == 128 + signal.SIGTERM
        wait_for(lambda: not processes_in(tmp_path.resolve()), STOP_SECONDS, "LIGGGHTS to end")
        print(f"SIGTERM to the DEM stage: it and LIGGGHTS ended in {time.monotonic() - sent:.2f} s")
        assert "stopped by signal 15" in log.read_text()
    finally:
        running.kill()
