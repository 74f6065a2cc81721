"""End to end: the real workflow (gmsh, LIGGGHTS, numba thermal stage, pyvista) on a tiny scene."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht.dumps import PositionsFile

ROOT = Path(__file__).resolve().parent.parent
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"), "--cores", "2"]

# About 420 particles of 1 mm in an 8 mm tube, 0.3 s of flow: a minute or two of real LIGGGHTS.
TINY = {
    "geometry": {
        "tube": {"inner_diameter": 8.0e-3, "length": 0.02, "orifice_height": 0.002, "orifice_diameter": 6.0e-3, "heated": [0.002, 0.016]},
        "mesh_size": 1.0,
    },
    "dem": {"fill_height": 0.008, "settle_time": 0.05, "flow_time": 0.3, "dump_interval": 500, "restart_interval": 4000},
    "thermal": {"initial_temperature": 300.0, "inlet_temperature": 300.0, "walls": {"heated_wall": {"temperature": "900"}}},
}
T_WALL, T_INLET = 900.0, 300.0

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed"),
]


def snakemake(workdir, *args, overrides="tiny.yaml"):
    """Run the workflow in ``workdir`` on the default config overridden by ``workdir/overrides``."""
    configs = [str(ROOT / "config" / "config.yaml"), str(workdir / overrides)]
    return subprocess.run(
        [*SNAKEMAKE, "--directory", str(workdir), *args, "--configfile", *configs],
        capture_output=True,
        text=True,
        timeout=900,
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("workflow")
    (workdir / "tiny.yaml").write_text(yaml.safe_dump(TINY))
    result = snakemake(workdir)
    assert result.returncode == 0, result.stderr[-4000:]
    return workdir


def test_outputs_exist(run):
    summary = json.loads((run / "results" / "base" / "summary.json").read_text())
    for name in ("cross_section", "wall_heat_flux", "wall_heat_history", "temperature_profiles", "htc_curves"):
        assert (run / "results" / "base" / "figures" / f"{name}.png").stat().st_size > 10_000
    assert summary["dem"]["particles"] > 300
    assert summary["dem"]["orifice_crossings"] > 0, "particles never flowed through the orifice"
    keys = summary["stage_keys"]
    assert (run / "results" / "thermal" / keys["thermal"] / "thermal.xdmf").is_file()


def thermal_file(run):
    keys = json.loads((run / "results" / "base" / "summary.json").read_text())["stage_keys"]
    return run / "results" / "thermal" / keys["thermal"] / "thermal.h5", run / "results" / "dem" / keys["dem"] / "positions.h5"


def test_particles_heat_towards_the_wall_and_never_beyond(run):
    thermal, positions = thermal_file(run)
    with h5py.File(thermal) as f:
        T = f["temperature"][...]
        assert np.nanmin(T) >= T_INLET - 1e-3
        assert np.nanmax(T) <= T_WALL + 1e-3
        assert np.nanmean(T[-1]) > np.nanmean(T[0]) + 1.0
        last = T[-1]
    with PositionsFile(positions) as dem:
        pos = dem.frame(dem.n_frames - 1).positions
    r = np.hypot(pos[:, 0], pos[:, 1])
    heated = (pos[:, 2] > 0.004) & (pos[:, 2] < 0.016)
    near_wall = heated & (r > 4.0e-3 - 1.2e-3)
    centre = heated & (r < 2.0e-3)
    assert np.nanmean(last[near_wall]) > np.nanmean(last[centre]) + 5.0


def test_energy_balance_closes_every_frame(run):
    thermal, _ = thermal_file(run)
    with h5py.File(thermal) as f:
        e = f["energy/particles"][...]
        wall = f["energy/wall"][...]
        recycled = f["energy/recycled"][...]
    change = np.diff(e)
    sources = np.diff(wall) + np.diff(recycled)
    assert np.max(np.abs(change - sources)) <= 1e-9 * max(np.max(np.abs(wall)), 1e-12)
    assert wall[-1] > 0


def test_second_run_does_nothing_and_thermal_change_skips_dem(run):
    again = snakemake(run, "--dry-run")
    assert again.returncode == 0
    assert "Nothing to be done" in again.stdout + again.stderr
    changed = json.loads(json.dumps(TINY))
    changed["particles"] = {"conductivity": 3.0}
    (run / "changed.yaml").write_text(yaml.safe_dump(changed))
    dry = snakemake(run, "--dry-run", overrides="changed.yaml")
    table = (dry.stdout + dry.stderr).split("Job stats:")[1].split("total")[0]
    jobs = {line.split()[0] for line in table.splitlines()[3:] if line.strip()}
    assert jobs == {"htc_table", "thermal", "figures", "variant_summary", "all"}


def test_misspelt_key_stops_with_the_key_named(tmp_path):
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump({"thermal": {"inlet_temperatur": 300.0}}))
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode != 0
    assert "thermal.inlet_temperatur: unknown key (did you mean 'inlet_temperature'?)" in result.stderr
    assert "Traceback" not in result.stderr
