"""Progress lines: the ETA comes from the items after the first (which, in a numba stage, includes
compiling the kernels), and a resumed run counts from where it resumed."""

import logging

from dpht.util.progress import Progress


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def lines(caplog, progress, clock, durations, done_from=0):
    caplog.clear()
    for k, seconds in enumerate(durations, done_from + 1):
        clock.now += seconds
        progress.update(k, work=100.0)
    return [r.getMessage() for r in caplog.records]


def test_eta_leaves_out_the_first_item(caplog):
    # 21 minutes of compiling in the first of 100 frames, then 0.1 s a frame: the first line has no
    # ETA yet, the next says 9.9 s for the 99 frames left after the first ten.
    clock = Clock()
    progress = Progress("thermal", 100, unit="particle-steps", interval=0.0, clock=clock)
    with caplog.at_level(logging.INFO, logger="dpht"):
        out = lines(caplog, progress, clock, [1260.0] + [0.1] * 99)
    assert out[0].startswith("thermal: 1/100 (1%)") and "ETA ? (after the first)" in out[0]
    assert "10/100" in out[9] and "ETA 0:00:09" in out[9] and "1e+03 particle-steps/s" in out[9]
    assert out[-1].startswith("thermal: 100/100 (100%)") and out[-1].endswith("ETA 0:00:00")


def test_a_resumed_run_counts_from_where_it_resumed(caplog):
    clock = Clock()
    progress = Progress("thermal", 100, interval=0.0, start=60, clock=clock)
    with caplog.at_level(logging.INFO, logger="dpht"):
        out = lines(caplog, progress, clock, [5.0] + [1.0] * 39, done_from=60)
    assert out[0].startswith("thermal: 61/100 (61%)") and "ETA ?" in out[0]
    assert out[1].startswith("thermal: 62/100") and "ETA 0:00:38" in out[1]
