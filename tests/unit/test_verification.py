"""Every case of `python -m dpht verify` (dpht.verification.harness) runs here too, so the suite and
an installation check use one source of truth; cases needing a missing program are skipped."""

import subprocess
import sys

import pytest

from dpht.verification import harness

CASES = harness.cases()


@pytest.mark.parametrize("name", list(CASES))
def test_case(name):
    case = CASES[name]
    if case.missing():
        pytest.skip(f"needs {', '.join(case.missing())}")
    outcome = harness.check(case)
    assert outcome.passed, outcome.line()


def test_harness_reports_units_and_skips_missing_programs(monkeypatch):
    ran = harness.Case("demo", "a demo", lambda: (2.0, 1.0), "K")
    assert harness.check(ran).line().startswith("FAIL  demo")
    assert " K " in harness.check(ran).line()
    absent = harness.Case("needs", "needs a program", lambda: (0.0, 1.0), "relative", requires=("no-such-program-dpht",))
    outcome = harness.check(absent)
    assert outcome.skipped and not outcome.passed
    assert "needs no-such-program-dpht" in outcome.line()


def test_cli_lists_cases_and_refuses_unknown_names():
    listing = subprocess.run([sys.executable, "-m", "dpht", "verify", "--list"], capture_output=True, text=True)
    assert listing.returncode == 0
    assert set(line.split()[0] for line in listing.stdout.splitlines()) == set(CASES)
    unknown = subprocess.run([sys.executable, "-m", "dpht", "verify", "no_such_case"], capture_output=True, text=True)
    assert unknown.returncode == 2 and "unknown verification case" in unknown.stderr
