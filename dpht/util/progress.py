"""Progress reports for long stages: done/total, throughput and ETA, at most every few seconds."""

from __future__ import annotations

import logging
import time
from datetime import timedelta

log = logging.getLogger("dpht")


class Progress:
    """Log ``label: done/total (pct) rate unit/s, ETA`` every ``interval`` seconds and at the end.

    Rate and ETA are measured from the first item finished on (the first item of a numba stage
    includes compiling its kernels, which would inflate the ETA many times over): the first line
    has no ETA yet unless it is the last. ``start`` is the number of items already done before
    (a resumed run).
    """

    def __init__(self, label: str, total: int, *, unit: str = "items", interval: float = 5.0, start: int = 0,
                 clock=time.monotonic):  # fmt: skip
        self.label, self.total, self.unit, self.interval, self.clock = label, total, unit, interval, clock
        self.start = self.last = clock()
        self.done = start
        self.work = 0.0
        self.first = None  # (time, done, work) when the first item of this run finished

    def update(self, done: int, work: float = 0.0) -> None:
        """``done`` items finished so far; ``work`` adds to the throughput count (e.g. particle-steps)."""
        self.done = done
        self.work += work
        now = self.clock()
        if self.first is None:
            self.first = (now, done, self.work)
        if now - self.last >= self.interval or done >= self.total:
            self.last = now
            log.info(self.line(now))

    def line(self, now: float) -> str:
        elapsed = max(now - self.start, 1e-9)
        pct = 100.0 * self.done / self.total if self.total else 100.0
        t0, done0, work0 = self.first if self.first is not None else (self.start, self.done, self.work)
        span, items = now - t0, self.done - done0
        if self.done >= self.total:
            eta, rate = 0.0, self.work / elapsed
        elif items > 0 and span > 0:
            eta, rate = span * (self.total - self.done) / items, (self.work - work0) / span
        else:
            eta, rate = None, self.work / elapsed
        eta_text = str(timedelta(seconds=round(eta))) if eta is not None else "? (after the first)"
        return (
            f"{self.label}: {self.done}/{self.total} ({pct:.0f}%), {rate:.3g} {self.unit}/s, "
            f"elapsed {timedelta(seconds=round(elapsed))}, ETA {eta_text}"
        )
