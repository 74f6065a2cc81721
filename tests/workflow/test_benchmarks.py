"""Every script in benchmarks/ runs, at its tiny size (``--tiny``: seconds, or a minute for those
that run LIGGGHTS), and ends with the line its docstring promises. Nothing is measured here: the
point is that a benchmark that no longer runs (a deck reading a mesh file it no longer gets, a plan
that needs screening decisions) is noticed."""

import re
import shutil
import subprocess
import sys

import pytest

from test_workflow import ROOT, run  # noqa: F401 (run: the fixture of a completed tiny workflow run)

# The last line each benchmark prints (its docstring says which).
LAST_LINE = {
    "dem": r"dem speed-up over plain settings: \d+\.\d+",
    "gas_pressure": r"pfw gap 0\.1 d +1000 K .*\(-\d+\.\d%\)",
    "integrators": r"implicit speed-up on stiff scene: \d",
    "raytrace": r"rays/s: \d",
    "thermal_checkpoints": r"checkpoint every 10 frames: [+-]\d+\.\d% wall time",
    "thermal_step": r"particle-steps/s: \d",
}
NEEDS_LIGGGHTS = {"dem", "thermal_checkpoints"}  # a DEM run of the tiny scene (the second reads a whole workflow run)


def test_every_benchmark_is_listed():
    assert {p.stem for p in (ROOT / "benchmarks").glob("*.py")} == set(LAST_LINE)


def _params():
    liggghts = pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed")
    return [pytest.param(name, marks=[pytest.mark.slow, liggghts]) if name in NEEDS_LIGGGHTS else name
            for name in sorted(LAST_LINE)]  # fmt: skip


@pytest.mark.parametrize("name", _params())
def test_benchmark_runs_at_its_tiny_size(name, tmp_path, request):
    extra = []
    if name == "dem":
        extra = ["--workdir", str(tmp_path)]
    elif name == "thermal_checkpoints":
        folder = request.getfixturevalue("run")
        extra = ["--config", str(folder / "tiny.yaml"), "--run", str(folder)]
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / f"{name}.py"), "--tiny", *extra], cwd=tmp_path,
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    assert re.match(LAST_LINE[name], done.stdout.strip().splitlines()[-1]), done.stdout[-2000:]


def test_thermal_step_times_the_network_pass_at_its_tiny_size(tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "thermal_step.py"), "--tiny", "--network"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    assert re.match(r"network pass ms: \d", done.stdout.strip().splitlines()[-1]), done.stdout[-2000:]
