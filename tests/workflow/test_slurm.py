"""End to end on a real SLURM: a one-node cluster on this machine (tests/cluster/slurm.sh: Debian's
slurmctld, slurmd and slurmdbd with MariaDB, munge), the tiny scene of test_workflow through
profiles/slurm with the DEM as a 2-task MPI job under srun, compared with a local run."""

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from dpht.plan import FIGURES
from test_workflow import TINY, write_config

ROOT = Path(__file__).resolve().parents[2]
CLUSTER = ROOT / "tests" / "cluster" / "slurm.sh"
PACKAGES = ("slurmctld", "slurmd", "slurm-client", "slurmdbd", "munge", "mariadb-server", "libpmix-dev")
ACCOUNT, PARTITION = "dpht", "debug"  # made by slurm.sh
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile")]


def _installed(package):
    return subprocess.run(["dpkg", "-s", package], capture_output=True).returncode == 0


def _cannot_run():
    if shutil.which("liggghts") is None:
        return "LIGGGHTS is not installed"
    if importlib.util.find_spec("snakemake_executor_plugin_slurm") is None:
        return "snakemake-executor-plugin-slurm is not installed (pip install -e '.[slurm]')"
    if os.geteuid() != 0:
        return "the one-node cluster of tests/cluster/slurm.sh runs its daemons as root"
    if shutil.which("dpkg") is None:
        return "not a Debian system: tests/cluster/slurm.sh installs SLURM with apt-get"
    if shutil.which("apt-get") is None and not all(map(_installed, PACKAGES)):
        return "SLURM is not installed and apt-get is not available"
    return None


pytestmark = [pytest.mark.slurm, pytest.mark.slow, pytest.mark.skipif(_cannot_run() is not None, reason=str(_cannot_run()))]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """The environment pointing SLURM's commands at a one-node cluster, stopped afterwards."""
    folder = tmp_path_factory.mktemp("slurm")
    start = subprocess.run(["bash", str(CLUSTER), "start", str(folder)], capture_output=True, text=True, timeout=900)
    try:
        logs = "\n".join(f"--- {p.name}\n{p.read_text()[-1500:]}" for p in sorted((folder / "log").glob("*")))
        assert start.returncode == 0, f"{start.stderr[-3000:]}\n{logs}"
        yield {**os.environ, "SLURM_CONF": str(folder / "etc" / "slurm.conf")}
    finally:
        subprocess.run(["bash", str(CLUSTER), "stop", str(folder)], capture_output=True, timeout=120)


def sacct(env, *args):
    """Rows (lists of fields) of ``sacct --parsable2 --noheader ARGS``."""
    out = subprocess.run(["sacct", "--parsable2", "--noheader", "--starttime", "now-2days", *args], env=env, capture_output=True, text=True, check=True)
    return [line.split("|") for line in out.stdout.splitlines() if line]


@pytest.fixture(scope="module")
def runs(cluster, tmp_path_factory):
    """The tiny scene through profiles/slurm, then its thermal stage run locally in another folder."""
    on_slurm, local = tmp_path_factory.mktemp("on_slurm"), tmp_path_factory.mktemp("local")
    for folder in (on_slurm, local):
        write_config(folder / "tiny.yaml", TINY)
    result = subprocess.run(
        [*SNAKEMAKE, "--directory", str(on_slurm), "--workflow-profile", str(ROOT / "profiles" / "slurm"),
         "--default-resources", f"slurm_account={ACCOUNT}", f"slurm_partition={PARTITION}",
         "--slurm-init-seconds-before-status-checks", "2", "--configfile", str(on_slurm / "tiny.yaml")],
        env=cluster, capture_output=True, text=True, timeout=1500, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-5000:]
    keys = json.loads((on_slurm / "results" / "tiny" / "base" / "summary.json").read_text())["stage_keys"]
    target = f"results/thermal/{keys['thermal']}/thermal.h5"
    here = subprocess.run(
        [*SNAKEMAKE, target, "--directory", str(local), "--cores", "2", "--configfile", str(local / "tiny.yaml")],
        capture_output=True, text=True, timeout=900, stdin=subprocess.DEVNULL,
    )
    assert here.returncode == 0, (here.stdout + here.stderr)[-4000:]
    return {"slurm": on_slurm, "local": local, "keys": keys, "output": output, "env": cluster}


def test_every_job_but_the_local_rules_went_through_sbatch(runs):
    output = runs["output"]
    remote = re.findall(r"^rule (\w+):", output, re.MULTILINE)
    local = set(re.findall(r"^localrule (\w+):", output, re.MULTILINE))
    assert {"geometry", "dem", "thermal"} <= set(remote)
    assert {"all", "figures", "htc_table", "variant_summary"} <= local and not local & set(remote)
    jobs = sacct(runs["env"], "-X", "--format=JobIDRaw,Comment,State,AllocCPUS")
    rules = [re.match(r"rule_(\w+?)_wildcards", comment).group(1) for _, comment, _, _ in jobs]
    assert sorted(rules) == sorted(remote), "the jobs SLURM accounted for are not the workflow's non-local jobs"
    assert {state for _, _, state, _ in jobs} == {"COMPLETED"}
    submitted = re.findall(r"has been submitted with SLURM jobid (\d+)", output)
    assert sorted(submitted) == sorted(job_id for job_id, *_ in jobs)


def test_the_dem_ran_as_one_two_task_mpi_job_under_srun(runs):
    env = runs["env"]
    (dem_job,) = [job_id for job_id, comment in sacct(env, "-X", "--format=JobIDRaw,Comment") if comment.startswith("rule_dem_")]
    steps = sacct(env, "-j", dem_job, "--format=JobID,NTasks,State")
    launched = [(step, int(tasks)) for step, tasks, _ in steps if re.fullmatch(rf"{dem_job}\.\d+", step)]
    assert len(launched) == 2 and all(tasks == 2 for _, tasks in launched), steps  # settle and flow, 2 ranks each
    work = runs["slurm"] / "results" / "dem" / runs["keys"]["dem"]
    assert "ranks = 2 (srun)" in (work / "dem.log").read_text()
    for screen in (work / "work" / "settle" / "screen.txt", work / "work" / "flow" / "screen.1.txt"):
        (grid,) = re.findall(r"(\d+) by (\d+) by (\d+) MPI processor grid", screen.read_text())
        assert np.prod([int(n) for n in grid]) == 2


def datasets(path):
    found = {}
    with h5py.File(path) as f:
        f.visititems(lambda name, obj: found.__setitem__(name, obj[...]) if isinstance(obj, h5py.Dataset) else None)
    return found


@pytest.mark.parametrize("stage, file", [("dem", "positions.h5"), ("thermal", "thermal.h5")])
def test_results_equal_a_local_run_bit_for_bit(runs, stage, file):
    """Same decks, same rank count and decomposition: srun and mpirun give the same LIGGGHTS run, so
    the DEM frames and then every thermal output are identical to the last bit."""
    rel = Path("results") / stage / runs["keys"][stage] / file
    on_slurm, local = datasets(runs["slurm"] / rel), datasets(runs["local"] / rel)
    assert on_slurm.keys() == local.keys() and len(on_slurm) > 1
    for name, values in on_slurm.items():
        np.testing.assert_array_equal(values, local[name], err_msg=f"{rel}:{name}")


def test_figures_were_made_on_the_submitting_host(runs):
    for name in FIGURES:
        assert (runs["slurm"] / "results" / "tiny" / "base" / "figures" / f"{name}.png").stat().st_size > 10_000
