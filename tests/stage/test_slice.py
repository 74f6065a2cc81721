"""The travelling slice (thermal.slice): frame reuse, the wall temperature at the height reached, no
reset at the periodic boundary, energy bookkeeping; and the driven DEM deck (dem.drive)."""

import json
import shutil

import h5py
import numpy as np
import pytest

from dpht import config
from dpht.errors import ConfigError
from dpht.thermal.slice import Slice, cycled
from test_thermal_stage import DEM_STEP, DUMP_INTERVAL, T_COLD, run_stage, scene  # noqa: F401 (fixture)

VELOCITY = 0.05  # m/s
Z_SWITCH = 0.02  # m: the wall is hot above this height and cold below


def test_mirror_reuse_never_jumps_and_wrap_restarts():
    mirror = cycled(4, 12, "mirror")
    assert mirror.tolist() == [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1]
    assert cycled(4, 9, "wrap").tolist() == [0, 1, 2, 3, 0, 1, 2, 3, 0]
    assert cycled(1, 3, "mirror").tolist() == [0, 0, 0]
    long = cycled(7, 100, "mirror")
    assert np.abs(np.diff(long)).max() == 1 and long.min() == 0 and long.max() == 6


def test_slice_duration_and_frames():
    s = Slice(velocity=0.0137, inlet_height=0.66, distance=0.66, frames="mirror")
    assert s.duration == pytest.approx(48.175, rel=1e-4)
    assert s.n_frames(0.01) == 4819  # t = 0 ... 48.18 s: the last frame is past the distance
    assert float(s.height(0.645 / 0.0137)) == pytest.approx(0.015)


def test_thermal_slice_needs_a_drive():
    cfg = config.load("config/config.yaml")
    c = config.variant(cfg, "base")
    c["thermal"]["slice"] = {"inlet_height": 0.04, "distance": 0.036}
    with pytest.raises(ConfigError, match="dem.drive"):
        config.thermal_spec(c)
    c["dem"]["drive"] = {"velocity": 0.08}
    assert config.thermal_spec(c)["thermal"]["slice"] == {"inlet_height": 0.04, "distance": 0.036, "frames": "mirror",
                                                          "velocity": 0.08}


@pytest.fixture(scope="module")
def driven(scene, tmp_path_factory):  # noqa: F811
    """The scene's inputs with positions periodic along z and recycling nothing (a periodic bed)."""
    folder, s, tables = scene
    copy = tmp_path_factory.mktemp("driven")
    for name in ("positions.h5", "walls.h5", "rdf.h5", *(p.name for p in tables.values())):
        shutil.copy(folder / name, copy / name)
    with h5py.File(copy / "positions.h5", "r+") as f:
        f.attrs["recycled"] = [False, False, False]
    return copy, s, {kind: copy / p.name for kind, p in tables.items()}


def test_a_slice_reads_a_recycling_dem_run_as_periodic(scene, travelling):  # noqa: F811
    """A driven DEM recycles along z like an orifice flow (the same run may stand for a whole tube,
    whose particles re-enter at the inlet temperature); a travelling slice resets nobody and keeps
    heat periodic across z whatever the positions file says."""
    out, _, distance = travelling
    walls = {"hot": {"temperature": f"where(z > {Z_SWITCH}, 900.0, 300.0)"}}
    recycled, _ = run_stage(scene, "slice_of_recycling", walls=walls,
                            slice={"inlet_height": 0.03, "distance": distance, "frames": "mirror", "velocity": VELOCITY})
    with h5py.File(out) as a, h5py.File(recycled) as b:
        np.testing.assert_array_equal(a["temperature"][...], b["temperature"][...])
        assert np.all(b["energy/recycled"][...] == 0.0)


@pytest.fixture(scope="module")
def travelling(driven):
    """The sinking bed of test_thermal_stage as a slice travelling from z = 0.03 m down 0.02 m past a
    wall that is hot (900 K) above Z_SWITCH and cold (300 K) below; 12 DEM frames reused."""
    distance = 0.02
    walls = {"hot": {"temperature": f"where(z > {Z_SWITCH}, 900.0, 300.0)"}}
    out, summary = run_stage(driven, "slice", walls=walls,
                             slice={"inlet_height": 0.03, "distance": distance, "frames": "mirror", "velocity": VELOCITY})
    return out, summary, distance


def test_slice_reuses_frames_and_resets_nobody(travelling):
    out, summary, distance = travelling
    dt = DEM_STEP * DUMP_INTERVAL
    with h5py.File(out) as f:
        time, dem_frame = f["time"][...], f["dem_frame"][...]
        E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
    n = Slice(VELOCITY, 0.03, distance, "mirror").n_frames(dt)
    assert time.size == n == summary["frames"] and n > 12  # longer than the DEM record
    np.testing.assert_allclose(time, dt * np.arange(n))
    assert dem_frame.tolist() == cycled(12, n, "mirror").tolist()
    assert np.all(Rc == 0.0)  # particles cross the periodic boundary, but the slice keeps them
    dE, dW = np.diff(E), np.diff(W)
    assert np.max(np.abs(dE - dW)) <= 1e-12 * np.abs(dW).max()


def test_slice_wall_temperature_follows_its_height(travelling):
    """The wall heats the cold bed while the slice is above Z_SWITCH and cools it after."""
    out, _, _ = travelling
    with h5py.File(out) as f:
        time, heat, T = f["time"][...], f["wall_heat"][...].sum(axis=1), f["temperature"][...]
        spec = json.loads(f.attrs["spec"])
    assert spec["thermal"]["slice"]["velocity"] == VELOCITY
    height = 0.03 - VELOCITY * (time[:-1] + 0.5 * np.diff(time))  # mid-interval, where the stage evaluates it
    hot, cold = height > Z_SWITCH, height < Z_SWITCH
    assert hot.sum() >= 5 and cold.sum() >= 5
    assert np.all(heat[:-1][hot] > 0) and np.all(heat[:-1][cold] < 0)
    assert np.nanmax(T) <= 900.0 + 1e-3 and np.nanmin(T) >= T_COLD - 1e-3


def test_slice_reuses_only_the_start_of_its_record(driven, travelling):
    """thermal.slice.record: the first 5 dump intervals of the 12-frame record are mirrored, as a
    6-frame DEM run would be; a record longer than the DEM's is an error naming the key."""
    from dpht.errors import DPHTError

    _, _, distance = travelling
    dt = DEM_STEP * DUMP_INTERVAL
    walls = {"hot": {"temperature": f"where(z > {Z_SWITCH}, 900.0, 300.0)"}}
    path = {"inlet_height": 0.03, "distance": distance, "frames": "mirror", "velocity": VELOCITY}
    out, _ = run_stage(driven, "slice_record", walls=walls, slice={**path, "record": 5 * dt})
    with h5py.File(out) as f:
        dem_frame = f["dem_frame"][...]
    assert dem_frame.tolist() == cycled(6, Slice(VELOCITY, 0.03, distance, "mirror").n_frames(dt), "mirror").tolist()
    with pytest.raises(DPHTError, match="thermal.slice.record"):
        run_stage(driven, "slice_record_too_long", walls=walls, slice={**path, "record": 12 * dt})


def test_a_slice_record_the_dem_run_cannot_give_is_found_before_any_job():
    from dpht import preflight

    c = config.variant(config.load("config/watkins.yaml"), "watkins_slice")
    assert preflight.scene_problems(c) == []
    for record, problem in ((2 * c["dem"]["flow_time"], "longer than the DEM's record"), (1e-4, "shorter than one thermal step")):
        c["thermal"]["slice"]["record"] = record
        assert [p for p in preflight.scene_problems(c) if p.startswith("thermal.slice.record") and problem in p], record


def test_a_slice_without_a_drive_velocity_is_found_before_any_job():
    """A travelling slice moves at dem.drive.velocity: the pre-flight check names the keys for a
    mass_flow drive (whose velocity depends on the packed bed; the Watkins slice loaded to its weight
    is a valid DEM run with it) and for a driven tube with its orifice (not loaded, then)."""
    from dpht import preflight

    c = config.variant(config.load("config/watkins.yaml"), "watkins_slice")
    drive = c["dem"]["drive"]
    assert drive["wall_stress"] == "weight"
    for other in ({"mass_flow": 0.00288}, {"velocity": drive.pop("velocity"), "orifice": True}):
        c["dem"]["drive"] = {**{k: v for k, v in drive.items() if k != "wall_stress" or "orifice" not in other}, **other}
        problems = preflight.scene_problems(c)
        assert [p for p in problems if p.startswith("thermal.slice: needs dem.drive.velocity")] == problems, other
