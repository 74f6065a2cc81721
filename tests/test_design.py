"""Running a design: `dpht check` previews what `dpht run` will do (particles, steps, frames, the
Rayleigh fraction of the DEM step, cost, the jobs of Snakemake's own dry run), `dpht run` runs the
project's Snakefile on one config; both plan the same jobs as `snakemake --dry-run`."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dpht import cost
from dpht.__main__ import main
from test_workflow import SNAKEMAKE, job_counts, write_config

ROOT = Path(__file__).resolve().parent.parent
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
