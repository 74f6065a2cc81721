"""Child processes that follow their parent: signals forwarded down, death propagated down.

The chain is snakemake -> stage process (``python -m dpht stage NAME``) -> LIGGGHTS (serial) or
``mpirun`` -> MPI ranks. What each link does (Linux):

- **snakemake** (the workflow's ``onstart`` calls :func:`forward_signals`): SIGINT or SIGTERM sent
  to snakemake alone is passed on to its stage processes, then to snakemake's own handler
  (SIGINT: cancel; SIGTERM: finish running jobs, start no new ones). Without it Snakemake waits for
  a running DEM to end.
- **stage process** (:func:`stop_on_signals`, :func:`watch_workflow`): SIGTERM and SIGHUP raise
  SystemExit, so ``finally`` blocks stop LIGGGHTS; a watchdog thread sends SIGTERM to the stage
  when the snakemake process that started it is gone (SIGKILL, lost terminal), since Snakemake
  then can no longer record the job anyway.
- **LIGGGHTS or mpirun** (:func:`die_with_parent` as ``preexec_fn``): the kernel sends it SIGTERM
  when the thread that started it exits (``prctl(PR_SET_PDEATHSIG)``); mpirun passes SIGTERM on to
  its ranks.
- **MPI ranks** (:func:`rank_prefix`, ``setpriv --pdeathsig KILL`` from util-linux between mpirun
  and LIGGGHTS): killed at once if mpirun is killed. Measured here with Debian's OpenMPI 4.1:
  ranks outlive a SIGKILLed mpirun by about 1 s without it, 5-25 ms with it.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import select
import shutil
import signal
import threading
import time
from pathlib import Path

log = logging.getLogger("dpht")

WORKFLOW_PID = "DPHT_WORKFLOW_PID"  # set by workflow/rules/common.smk: the snakemake process's pid
STAGE_ARGV = ("-m", "dpht", "stage")  # how the rules start a stage process
GRACE_SECONDS = 30.0  # after its parent died, a stage that has not ended on SIGTERM is killed
SAME_SIGNAL_SECONDS = 1.0  # a signal again within this time is a copy of the first, not a second request

_PR_SET_PDEATHSIG = 1
_libc = ctypes.CDLL(None, use_errno=True)  # loaded here, not in the forked child


def die_with_parent(sig: int = signal.SIGTERM):
    """A ``preexec_fn`` for :class:`subprocess.Popen`: the child gets ``sig`` when the thread that
    started it ends (so call Popen from the thread that waits for the child), and exits at once
    if that parent is already gone."""
    parent = os.getpid()

    def preexec() -> None:
        _libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
        if os.getppid() != parent:
            os._exit(128 + int(sig))

    return preexec


def rank_prefix() -> list[str]:
    """Command words between ``mpirun -n N`` and the program, so that each rank is killed when
    mpirun is (``setpriv --pdeathsig KILL``); none where util-linux's setpriv is missing (the
    ranks then notice a lost mpirun themselves, about 1 s later)."""
    setpriv = shutil.which("setpriv")
    return [setpriv, "--pdeathsig", "KILL"] if setpriv else []


# --- /proc -------------------------------------------------------------------------------


def _stat(pid: int) -> list[str] | None:
    """Fields of /proc/<pid>/stat after the command name (state, ppid, ..., starttime at [19])."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def _start_time(pid: int) -> str | None:
    fields = _stat(pid)
    return fields[19] if fields and fields[0] not in ("Z", "X") else None


def children() -> dict[int, list[int]]:
    """Parent pid -> pids of its children, for every live process."""
    tree: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            fields = _stat(int(entry.name))
            if fields and fields[0] not in ("Z", "X"):
                tree.setdefault(int(fields[1]), []).append(int(entry.name))
    return tree


def descendants(pid: int) -> list[int]:
    """Pids of all live descendants of ``pid``, parents before children."""
    tree, found, queue = children(), [], [pid]
    while queue:
        for child in tree.get(queue.pop(0), []):
            found.append(child)
            queue.append(child)
    return found


def _argv(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return []


def stage_processes(pid: int) -> list[int]:
    """Descendants of ``pid`` that are stage processes (``python -m dpht stage ...``)."""
    n = len(STAGE_ARGV)
    found = []
    for child in descendants(pid):
        argv = _argv(child)
        if any(tuple(argv[i : i + n]) == STAGE_ARGV for i in range(len(argv))):
            found.append(child)
    return found


# --- snakemake side ------------------------------------------------------------------------


def forward_signals(signals=(signal.SIGINT, signal.SIGTERM)) -> None:
    """In the snakemake process (main thread): pass each of ``signals`` on to the running stage
    processes, then to the handler that was installed before (Snakemake's, or KeyboardInterrupt
    for SIGINT)."""
    for sig in signals:
        previous = signal.getsignal(sig)

        def handler(signum, frame, previous=previous):
            for pid in stage_processes(os.getpid()):
                try:
                    os.kill(pid, signum)
                except ProcessLookupError:
                    pass
            if callable(previous):
                previous(signum, frame)
            elif previous == signal.SIG_DFL:
                signal.signal(signum, signal.SIG_DFL)
                os.kill(os.getpid(), signum)

        signal.signal(sig, handler)


# --- stage side ------------------------------------------------------------------------------


STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)  # Python's default for these exits without unwinding


@contextlib.contextmanager
def _handling(signals, handler):
    """Within the block, ``handler`` for ``signals`` (in the main thread; elsewhere signals stay as
    they are), the previous handlers restored afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, handler) for sig in signals}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _raise(signum: int, frame=None):
    """What a signal stops a stage with: KeyboardInterrupt for SIGINT, else SystemExit(128 + signal)."""
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise SystemExit(128 + signum)


def stop_on_signals():
    """Within the block SIGTERM and SIGHUP raise SystemExit(128 + signal), so that ``finally``
    blocks run: they stop LIGGGHTS and close files."""
    return _handling(STOP_SIGNALS, _raise)


def signals_ignored():
    """Within the block SIGINT, SIGTERM and SIGHUP are ignored: a clean-up that stops a child is
    not cut short by a second Ctrl-C or a forwarded copy of the signal."""
    return _handling((signal.SIGINT, *STOP_SIGNALS), signal.SIG_IGN)


class Deferred:
    """Signals received within :func:`deferred_signals`: the first is held until :meth:`stop_if_asked`.

    Copies of it within :data:`SAME_SIGNAL_SECONDS` are the same request: Ctrl-C reaches a stage
    from the terminal and again through snakemake (:func:`forward_signals`), a batch scheduler
    signals every process of the job.
    """

    def __init__(self):
        self.signal: int | None = None
        self.received = 0.0

    def hold(self, signum, frame) -> None:
        if self.signal is not None:
            if time.monotonic() - self.received > SAME_SIGNAL_SECONDS:
                _raise(signum)
            return
        self.signal, self.received = signum, time.monotonic()
        log.info("dpht: signal %d: stopping at the end of this step (send it again to stop at once)", signum)

    def stop_if_asked(self) -> None:
        """At a point where stopping loses nothing: raise what the held signal would have raised."""
        if self.signal is not None:
            _raise(self.signal)


@contextlib.contextmanager
def deferred_signals():
    """Within the block the first SIGINT, SIGTERM or SIGHUP is held until the caller reaches a safe
    point (:meth:`Deferred.stop_if_asked`); a second one acts at once. Yields the :class:`Deferred`."""
    held = Deferred()
    with _handling((signal.SIGINT, *STOP_SIGNALS), held.hold):
        yield held


def watch_workflow(environ=os.environ) -> threading.Thread | None:
    """In a stage process: a daemon thread that sends this process SIGTERM once the snakemake
    process named by $DPHT_WORKFLOW_PID has ended (and SIGKILL :data:`GRACE_SECONDS` later if
    that did not end it). Nothing when the variable is unset or names a process that is not an
    ancestor of this one (a stage started by hand, or by another workflow manager)."""
    try:
        pid = int(environ.get(WORKFLOW_PID, ""))
    except ValueError:
        return None
    ancestor, seen = os.getppid(), set()
    while ancestor > 1 and ancestor != pid and ancestor not in seen:
        seen.add(ancestor)
        fields = _stat(ancestor)
        ancestor = int(fields[1]) if fields else 0
    if ancestor != pid:
        # Either not started by that workflow, or it died before we looked (we were reparented).
        if os.getppid() == 1 or _start_time(pid) is None:
            _parent_gone(pid)
        return None
    thread = threading.Thread(target=_watch, args=(pid, _start_time(pid)), name="dpht-watch-workflow", daemon=True)
    thread.start()
    return thread


def _watch(pid: int, started: str | None) -> None:
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        fd = None
    except OSError:  # no pidfd (Linux < 5.3): poll the process's start time
        fd = -1
    if fd is not None and fd >= 0:
        select.select([fd], [], [])  # readable once the process has exited
        os.close(fd)
    elif fd == -1:
        stop = threading.Event()
        while _start_time(pid) == started:
            stop.wait(0.5)
    _parent_gone(pid)


def _parent_gone(pid: int) -> None:
    log.error("dpht: the workflow (snakemake, pid %d) that started this stage is gone; stopping", pid)
    os.kill(os.getpid(), signal.SIGTERM)
    kill = threading.Timer(GRACE_SECONDS, os.kill, (os.getpid(), signal.SIGKILL))
    kill.daemon = True
    kill.start()
