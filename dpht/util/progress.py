"""Progress reports for long stages: done/total, throughput and ETA, at most every few seconds."""

from __future__ import annotations

import logging
import time
from datetime import timedelta

log = logging.getLogger("dpht")


class Progress:
    """Log ``label: done/total (pct) rate unit/s, ETA`` every ``interval`` seconds and at the end."""

    def __init__(self, label: str, total: int, *, unit: str = "items", interval: float = 5.0, clock=time.monotonic):
        self.label, self.total, self.unit, self.interval, self.clock = label, total, unit, interval, clock
        self.start = self.last = clock()
        self.done = 0
        self.work = 0.0

    def update(self, done: int, work: float = 0.0) -> None:
        """``done`` items finished so far; ``work`` adds to the throughput count (e.g. particle-steps)."""
        self.done = done
        self.work += work
        now = self.clock()
        if now - self.last >= self.interval or done >= self.total:
            self.last = now
            log.info(self.line(now))

    def line(self, now: float) -> str:
        elapsed = max(now - self.start, 1e-9)
        eta = elapsed * (self.total - self.done) / self.done if self.done else float("nan")
        eta_text = str(timedelta(seconds=round(eta))) if eta == eta else "?"
        pct = 100.0 * self.done / self.total if self.total else 100.0
        return (
            f"{self.label}: {self.done}/{self.total} ({pct:.0f}%), {self.work / elapsed:.3g} {self.unit}/s, "
            f"elapsed {timedelta(seconds=round(elapsed))}, ETA {eta_text}"
        )
