"""Running a design: `dpht check` previews what `dpht run` will do (particles, steps, frames, the
Rayleigh fraction of the DEM step, cost, the jobs of Snakemake's own dry run), `dpht run` runs the
project's Snakefile on one config; both plan the same jobs as `snakemake --dry-run`."""

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dpht import cost
from dpht.__main__ import main
from test_workflow import SNAKEMAKE, job_counts, write_config

ROOT = Path(__file__).resolve().parents[2]
QUICK = ROOT / "config" / "quick.yaml"


@pytest.fixture
def tiny(tmp_path):
    """A working folder with the tiny test scene's config and no results."""
    write_config(tmp_path / "tiny.yaml")
    return tmp_path


@pytest.fixture
def project_copy(tmp_path):
    """A working folder with the project's config/config.yaml (as a checkout has), no results."""
    (tmp_path / "config").mkdir()
    shutil.copy(ROOT / "config" / "config.yaml", tmp_path / "config" / "config.yaml")
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "rdf").symlink_to(ROOT / "tables" / "rdf")
    return tmp_path


def total_of(text: str) -> int:
    return int(re.search(r"jobs to run \(snakemake --dry-run\): (\d+)", text).group(1))


def test_check_and_run_plan_the_jobs_of_snakemakes_dry_run(tiny, capsys):
    assert main(["check", str(tiny / "tiny.yaml"), "-d", str(tiny), "--cores", "2"]) == 0
    out = capsys.readouterr().out
    snakemake = subprocess.run([*SNAKEMAKE, "--directory", str(tiny), "--dry-run", "--configfile", str(tiny / "tiny.yaml")],
                               capture_output=True, text=True)  # fmt: skip
    counts = job_counts(snakemake)
    assert total_of(out) == sum(counts.values())
    assert f"dem {counts['dem']}, " in out and "thermal" in counts
    dry = subprocess.run([sys.executable, "-m", "dpht", "run", str(tiny / "tiny.yaml"), "-d", str(tiny), "--dry-run",
                          "--cores", "2"], capture_output=True, text=True)  # fmt: skip
    assert job_counts(dry) == counts
    assert not (tiny / "results").exists()  # a dry run writes nothing


def test_check_previews_each_scene(tiny, capsys):
    assert main(["check", str(tiny / "tiny.yaml"), "-d", str(tiny), "--no-jobs"]) == 0
    out = capsys.readouterr().out
    plan = cost.load_plan([tiny / "tiny.yaml"], tiny)
    (found,) = [cost.scene(label, c, keys) for label, (c, keys) in cost.scenes(plan).items()]
    # .test/config: 8 mm tube filled 8 mm above the plate with 1 mm spheres at the poured solid fraction.
    assert 380 < found.particles < 460
    # 0.05 s settling and 0.3 s flow at 1e-5 s after the fill; a frame every 500 steps.
    assert found.dem_steps - found.settle_steps == 30_000 and found.dem_frames == 61 == found.thermal_frames
    assert f"DEM: {found.particles:,} particles (fill estimate), {found.dem_steps:,} steps" in out
    assert "time step 0.137 of the Rayleigh time" in out and "jobs to run" not in out
    rate = cost.RATES.dem_particle_steps_per_rank_s * found.ranks
    assert found.dem_s == pytest.approx(cost.RATES.dem_overhead_s + found.particles * found.dem_steps / rate)


def test_the_rayleigh_fraction_warns_above_02_and_stops_above_05(tmp_path, capsys):
    write_config(tmp_path / "warn.yaml", {"dem": {"timestep": 2.0e-5}})  # 0.274 of the Rayleigh time
    assert main(["check", str(tmp_path / "warn.yaml"), "-d", str(tmp_path), "--no-jobs"]) == 0
    assert "DEM warning: timestep above 0.2 of the Rayleigh time" in capsys.readouterr().out
    write_config(tmp_path / "stop.yaml", {"dem": {"timestep": 4.0e-5}})  # 0.548
    assert main(["check", str(tmp_path / "stop.yaml"), "-d", str(tmp_path), "--no-jobs"]) == 2
    assert "dem.timestep = 4e-05 s is 0.55 of the Rayleigh time" in capsys.readouterr().err


def test_quick_over_the_default_config_and_its_designs_alone(project_copy, capsys):
    """config/quick.yaml merged over the working folder's config/config.yaml, as snakemake merges it:
    every study's scene; with --designs only the two variants' jobs."""
    assert main(["check", str(QUICK), "-d", str(project_copy), "--cores", "2"]) == 0
    out = capsys.readouterr().out
    assert "config/config.yaml, " in out and ": valid; " in out
    for label in ("base", "flat_plate", "watkins watkins", "mixers radial"):
        assert f"\n{label}: " in "\n" + out
    everything = total_of(out)
    snakemake = subprocess.run([*SNAKEMAKE, "--directory", str(project_copy), "--dry-run", "--configfile", str(QUICK)],
                               capture_output=True, text=True)  # fmt: skip
    assert everything == sum(job_counts(snakemake).values())
    assert main(["check", str(QUICK), "-d", str(project_copy), "--cores", "2", "--designs"]) == 0
    designs = capsys.readouterr().out
    counts = dict(re.findall(r"(\w+) (\d+)", designs.split("jobs to run (snakemake --dry-run): ")[1].splitlines()[0]))
    assert total_of(designs) < everything
    assert counts["dem"] == "2" and counts["thermal"] == "2" and "compare_variants" in counts
    assert not {"radiation_study", "intraparticle_study", "watkins", "mixers", "radiation", "intraparticle"} & set(counts)


def test_a_config_that_cannot_run_stops_run_before_snakemake(tmp_path, capsys):
    write_config(tmp_path / "bad.yaml", {"dem": {"timestep": 4.0e-5}})
    assert main(["run", str(tmp_path / "bad.yaml"), "-d", str(tmp_path), "--dry-run"]) == 2
    assert "Rayleigh time" in capsys.readouterr().err
    assert not (tmp_path / ".snakemake").exists()
    assert main(["check", str(tmp_path / "bad.yaml"), "-d", str(tmp_path / "none")]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_compile_notice_on_a_cold_cache(tmp_path):
    """With an empty numba cache the stages say they compile, and for how long about."""
    code = "from dpht.cost import compile_notice, kernels_cached; print(kernels_cached()); compile_notice('thermal', print)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                            env={**cost.environment(), "NUMBA_CACHE_DIR": str(tmp_path)})  # fmt: skip
    assert result.stdout.splitlines() == ["False", f"thermal: compiling the thermal kernels (first run only, "
                                                   f"~{cost.RATES.compile_s['thermal']:.0f} s on this machine)"]


def test_the_overall_line_counts_runs_done_by_their_outputs_and_scales_the_eta(tmp_path):
    """The overall line's total is the preview's estimate of the same jobs; a run is done when its
    outputs were written after the start (an output left from before does not count); the ETA is
    what is left scaled by elapsed / done."""
    found = [cost.Scene("a", "d" * 12, "t" * 12, 400, 2, 41_000, 10_000, 61, 61, 0.1, (), 30.0, 10.0),
             cost.Scene("b", "e" * 12, "t" * 12, 400, 2, 41_000, 10_000, 61, 61, 0.1, (), 50.0, 10.0)]  # fmt: skip
    jobs = cost.Jobs({"dem": 2, "thermal": 1, "figures": 2}, 5, {"dem": {"d" * 12, "e" * 12}, "thermal": {"t" * 12}})
    outputs = {("dem", "d" * 12): [str(tmp_path / "d.h5")], ("dem", "e" * 12): [str(tmp_path / "e.h5")],
               ("thermal", "t" * 12): [str(tmp_path / "t.h5"), str(tmp_path / "t.json")]}  # fmt: skip
    (tmp_path / "e.h5").write_text("from an earlier run")
    now = [time.time() + 1.0]
    overall = cost.Overall(found, jobs, outputs, cores=2, cold=True, clock=lambda: now[0])
    preview = cost.estimate(found, jobs, 2, True)
    # Two DEM runs of 2 ranks on 2 cores one after the other, a thermal run of 2 threads, compiling.
    assert overall.total == preview and preview.wall_s == 30.0 + 50.0 + 10.0 + sum(cost.RATES.compile_s.values())
    total = cost.duration(preview.wall_s)
    assert overall.line() == f"overall: 0 s of {total} estimated done (0/3 DEM and thermal runs), 0 s elapsed, ETA {total}"
    assert f"estimated {total} of wall time for 2 DEM and 1 thermal run(s) and numba compiling" in overall.explain()
    now[0] += 60.0
    (tmp_path / "d.h5").write_text("written")
    os.utime(tmp_path / "d.h5", (now[0], now[0]))
    os.utime(tmp_path / "e.h5", (now[0] - 3600, now[0] - 3600))  # before the start: not this run's
    assert overall.done_s() == 30.0
    left = (preview.wall_s - 30.0) * 60.0 / 30.0  # this machine took twice the estimate so far
    assert overall.line().endswith(f"(1/3 DEM and thermal runs), 60 s elapsed, ETA {cost.duration(left)}")
    (tmp_path / "t.h5").write_text("written")  # one of the thermal run's two outputs: not done yet
    os.utime(tmp_path / "t.h5", (now[0], now[0]))
    assert overall.done_s() == 30.0
    (tmp_path / "t.json").write_text("written")
    os.utime(tmp_path / "t.json", (now[0], now[0]))
    assert overall.done_s() == 30.0 + 10.0 + sum(cost.RATES.compile_s.values())  # its first thermal job compiled
