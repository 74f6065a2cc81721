"""End to end: the real workflow (gmsh, LIGGGHTS, numba thermal stage, pyvista) on a tiny scene."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht.thermal import integrate, model as thermal_model, neighbors
from dpht.verification import reference, scenes
from dpht.dem.dumps import PositionsFile
from dpht.thermal.kernels import MODES
from geometry.walls import load_walls

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


def shipped_rdf_table(particle_emissivity, wall_emissivity):
    """The RDF table committed in tables/rdf/ for these emissivities (no ray tracing in the tests)."""
    for path in sorted((ROOT / "tables" / "rdf").glob("*.h5")):
        with h5py.File(path) as f:
            if (f.attrs["particle_emissivity"], f.attrs["wall_emissivity"]) == (particle_emissivity, wall_emissivity):
                return str(path)
    raise AssertionError(f"no shipped RDF table for emissivities {particle_emissivity}, {wall_emissivity}")


def write_config(path, overrides):
    """The default config with ``overrides`` merged in, the shipped RDF table, and no Section 4 study."""
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())

    def merge(base, extra):
        for key, value in extra.items():
            if isinstance(value, dict) and isinstance(base.get(key), dict):
                merge(base[key], value)
            else:
                base[key] = value

    merge(cfg, overrides)
    del cfg["radiation_study"]
    cfg["thermal"]["rdf_table"] = shipped_rdf_table(float(cfg["particles"]["emissivity"]), float(cfg["wall"]["emissivity"]))
    path.write_text(yaml.safe_dump(cfg))


def snakemake(workdir, *args, config="tiny.yaml"):
    """Run the workflow in ``workdir`` with the config file ``workdir/config`` (see write_config)."""
    return subprocess.run(
        [*SNAKEMAKE, "--directory", str(workdir), *args, "--configfile", str(workdir / config)],
        capture_output=True,
        text=True,
        timeout=900,
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("workflow")
    write_config(workdir / "tiny.yaml", TINY)
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
    write_config(run / "changed.yaml", changed)
    dry = snakemake(run, "--dry-run", config="changed.yaml")
    table = (dry.stdout + dry.stderr).split("Job stats:")[1].split("total")[0]
    jobs = {line.split()[0] for line in table.splitlines()[3:] if line.strip()}
    assert jobs == {"htc_table", "thermal", "figures", "variant_summary", "all"}


def test_misspelt_key_stops_with_the_key_named(tmp_path):
    write_config(tmp_path / "tiny.yaml", {"thermal": {"inlet_temperatur": 300.0}})
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode != 0
    assert "thermal.inlet_temperatur: unknown key (did you mean 'inlet_temperature'?)" in result.stderr
    assert "Traceback" not in result.stderr


def real_frame(run):
    keys = json.loads((run / "results" / "base" / "summary.json").read_text())["stage_keys"]
    with PositionsFile(run / "results" / "dem" / keys["dem"] / "positions.h5") as dem:
        frame = dem.frame(dem.n_frames // 2)
        box = (np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"]), np.asarray(dem.attrs["periodic"], bool))
    return frame.positions[~frame.lost].astype(np.float64), box, run / "results" / "geometry" / keys["geometry"] / "walls.h5"


def test_cell_list_equals_brute_force_on_a_real_frame(run):
    positions, (lo, hi, periodic), _ = real_frame(run)
    assert periodic.tolist() == [False, False, True]
    for cutoff in (1.5e-3, 3.5e-3):
        cells = neighbors.build(positions, cutoff, box_lo=lo, box_hi=hi, periodic=periodic)
        found = {tuple(sorted(p)) for p in zip(*neighbors.pairs(cells, cutoff))}
        reference_pairs = set(zip(*neighbors.brute_force_pairs(positions, cutoff, box_lo=lo, box_hi=hi, periodic=periodic)))
        assert found == reference_pairs and len(found) > len(positions)


def test_all_modes_on_a_real_frame_match_the_brute_force_reference(run):
    positions, (lo, hi, periodic), walls_h5 = real_frame(run)
    walls = load_walls(walls_h5)
    s = scenes.spec(list(MODES), walls={"heated_wall": {"temperature": 900.0}, "adiabatic_wall": "adiabatic", "orifice": "adiabatic"})
    model = thermal_model.build(s, walls, scenes.htc_tables(s), scenes.synthetic_rdf())
    T = model.enthalpy.temperature(model.enthalpy.enthalpy(np.random.default_rng(0).uniform(300, 800, len(positions))))
    frame = integrate.prepare_frame(model, positions, lo, hi, periodic)
    rates = integrate.Rates(np.zeros(len(positions)), np.zeros(len(positions)), np.zeros((len(walls.area), 3)))
    integrate.evaluate(model, frame, T[frame.particles], rates)
    q = np.zeros(len(positions))
    q[frame.particles] = rates.q
    # The reference knows no periodic images: compare particles away from the periodic boundary.
    inner = (positions[:, 2] > lo[2] + model.pair_cutoff) & (positions[:, 2] < hi[2] - model.pair_cutoff)
    q_ref, heat_ref = reference.heat_rates(model, positions, T, walls)
    assert np.max(np.abs(q - q_ref)[inner]) <= 1e-10 * np.max(np.abs(q_ref))
    # Wall heat involves no particle pairs, so it matches for every particle.
    np.testing.assert_allclose(rates.element_heat.sum(axis=0), heat_ref, rtol=1e-10)


def test_xdmf_opens_as_a_time_series_in_vtk(run):
    """ParaView reads XDMF with VTK's reader: every frame, every particle, the temperatures."""
    vtk = pytest.importorskip("vtkmodules.vtkIOXdmf2")
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

    thermal, _ = thermal_file(run)
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(thermal.with_suffix(".xdmf")))
    reader.UpdateInformation()
    steps = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    with h5py.File(thermal) as f:
        times = f["time"][...]
        last = f["temperature"][-1]
    np.testing.assert_allclose(steps, times)
    reader.UpdateTimeStep(steps[-1])
    grid = reader.GetOutputDataObject(0)
    assert grid.GetNumberOfPoints() == last.size
    low, high = grid.GetPointData().GetArray("temperature").GetRange()
    assert low == pytest.approx(np.nanmin(last)) and high == pytest.approx(np.nanmax(last))


def _dem_processes(folder):
    """PIDs of processes (LIGGGHTS, mpirun) whose working directory lies inside ``folder``."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and str(Path(proc / "cwd").resolve()).startswith(str(folder)):
                found.append(int(proc.name))
        except OSError:
            continue
    return found


def test_workflow_killed_mid_flow_resumes_the_dem_run(tmp_path):
    """SIGKILL the whole workflow during the flow (a lost machine), unlock, re-run: the DEM
    continues from its last restart file and the frames have no gap and no duplicate."""
    slow = json.loads(json.dumps(TINY))
    slow["dem"].update(flow_time=0.6, restart_interval=2000)
    write_config(tmp_path / "tiny.yaml", slow)
    command = [*SNAKEMAKE, "--directory", str(tmp_path), "--configfile", str(tmp_path / "tiny.yaml")]
    child = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    restarts = []
    while time.monotonic() < deadline and child.poll() is None and len(restarts) < 2:
        restarts = list(tmp_path.glob("results/dem/*/work/flow/restart/flow.*.restart"))
        time.sleep(0.2)
    assert child.poll() is None and len(restarts) >= 2, "the flow ended before it could be killed"
    os.killpg(child.pid, signal.SIGKILL)
    child.wait()
    for pid in _dem_processes(tmp_path.resolve()):  # MPI ranks live in their own process group
        os.kill(pid, signal.SIGKILL)
    assert subprocess.run([*command[:-2], "--unlock", *command[-2:]], capture_output=True).returncode == 0
    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    keys = json.loads((tmp_path / "results" / "base" / "summary.json").read_text())["stage_keys"]
    log = (tmp_path / "results" / "dem" / keys["dem"] / "dem.log").read_text()
    assert "resuming from" in log
    with PositionsFile(tmp_path / "results" / "dem" / keys["dem"] / "positions.h5") as dem:
        steps = dem.steps
        assert dem.n_frames == 121  # 0.6 s of flow, a frame every 500 steps of 1e-5 s, both ends
    np.testing.assert_array_equal(np.diff(steps), 500)
