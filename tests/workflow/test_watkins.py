"""The Watkins validation end to end on tiny scenes (real gmsh, LIGGGHTS, thermal stage, figures):
`snakemake watkins` on .test/config/watkins.yaml (a 4 mm slice carried through Eq. 30) and
`snakemake watkins_reduction` on .test/config/watkins_reduction.yaml over the .test tube (the tube
against a slice of it)."""

import csv
import json
import subprocess

import h5py
import numpy as np
import pytest
import yaml

from dpht import config
from dpht.figures.watkins import PAPER_SPLIT_OVERALL
from dpht.plan import Plan
from dpht.studies.watkins import FIGURES as WATKINS_FIGURES
from figure_files import check_figure
from test_workflow import ROOT, SNAKEMAKE, TEST_CONFIG, end_to_end, write_config

# The Watkins scene's numbers beside the paper's (the figures' own CSVs: tests/figure_files.py).
SUMMARY_COLUMNS = ["quantity", "this_work", "dpht_paper", "experiment"]


def _tiny_file(name: str, folder) -> str:
    """.test/config/<name> with its RDF table path made absolute, written into ``folder``."""
    cfg = yaml.safe_load((TEST_CONFIG.parent / name).read_text())
    if "thermal" in cfg and "rdf_table" in cfg["thermal"]:
        cfg["thermal"]["rdf_table"] = str((TEST_CONFIG.parent.parent / cfg["thermal"]["rdf_table"]).resolve())
    (folder / name).write_text(yaml.safe_dump(cfg))
    return str(folder / name)


@pytest.fixture(scope="module")
def watkins_run(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("watkins")
    write_config(workdir / "tiny.yaml", {"watkins": {"scene": _tiny_file("watkins.yaml", workdir)}, "watkins_reduction": {
        "scene": [str(workdir / "tiny.yaml"), _tiny_file("watkins_reduction.yaml", workdir)]}})  # the tiny tube, its slice
    result = subprocess.run([*SNAKEMAKE, "--directory", str(workdir), "watkins", "watkins_reduction", "--configfile",
                             str(workdir / "tiny.yaml")], capture_output=True, text=True, timeout=2400)  # fmt: skip
    assert result.returncode == 0, result.stderr[-4000:]
    return workdir / "results"


def _rows(path):
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


@end_to_end
def test_watkins_figures_and_tables(watkins_run):
    workdir, studies = watkins_run.parent, watkins_run / "tiny" / "studies"
    plan = Plan(config.load(workdir / "tiny.yaml"))
    pngs = [t for name in ("watkins", "watkins_reduction") for t in plan.study_targets(name) if t.endswith(".png")]
    assert len(pngs) == len(WATKINS_FIGURES) + 1  # and the reduction check's
    for png in pngs:
        check_figure(workdir / png)
    watkins_run = studies / "watkins"
    rows = _rows(watkins_run / "watkins.csv")
    assert rows and list(rows[0]) == SUMMARY_COLUMNS
    numbers = [float(v) for row in rows for k, v in row.items() if k != "quantity" and v not in ("", "nan")]
    assert numbers and np.all(np.isfinite(numbers))
    summary = json.loads((watkins_run / "watkins.json").read_text())
    assert summary["rise_K"] > 0  # the wall of Eq. 30 (230-785 deg C) heats the 30 deg C slice
    split = summary["split_overall_percent"]
    assert set(split) >= set(PAPER_SPLIT_OVERALL) and sum(split.values()) == pytest.approx(100.0)
    fig11 = _rows(watkins_run / "fig11.csv")
    wall = np.array([float(r["wall_temperature_K"]) for r in fig11])
    distance = np.array([float(r["distance_m"]) for r in fig11])
    eq30 = -995.70 * (0.66 - distance) ** 3 + 381.44 * (0.66 - distance) ** 2 - 657.96 * (0.66 - distance) + 1057.8
    np.testing.assert_allclose(wall, eq30, rtol=1e-9)  # Eq. (30) at the height the slice has reached
    assert distance[-1] >= 0.66 - 1e-9
    reduction = json.loads((studies / "watkins_reduction" / "reduction.json").read_text())["slice"]
    assert np.isfinite(reduction["rise_outlet_rel_diff"]) and np.isfinite(reduction["heat_total_rel_diff"])


@end_to_end
def test_watkins_slice_conserves_energy_without_resets(watkins_run):
    results = watkins_run
    (thermal,) = [p for p in (results / "thermal").glob("*/thermal.h5")
                  if "slice" in json.loads(h5py.File(p)["/"].attrs["spec"])["thermal"]
                  and json.loads(h5py.File(p)["/"].attrs["spec"])["thermal"]["slice"]["inlet_height"] == 0.66]
    with h5py.File(thermal) as f:
        E, W, Rc = (f[f"energy/{k}"][...] for k in ("particles", "wall", "recycled"))
        assert f["dem_frame"].shape[0] > f["dem_frame"][...].max() + 1  # the DEM record was reused
    assert np.all(Rc == 0.0)
    assert np.max(np.abs(np.diff(E) - np.diff(W))) <= 1e-12 * np.abs(np.diff(W)).max()


@end_to_end
def test_driven_slices_are_packed_to_their_solid_fraction_without_a_seam(watkins_run):
    """Every particle of a driven slice (dem.drive, 4 mm long: DEM decks/pack.in) is in, and the
    bed has no loose seam where it closes on itself across z = 0 | L."""
    from dpht.dem.dumps import PositionsFile

    slices = 0
    for path in (watkins_run / "dem").glob("*/positions.h5"):
        with PositionsFile(path) as dem:
            lo, hi = np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"])
            if hi[2] - lo[2] > 0.0041:
                continue  # the reduction check's full tube (orifice flow)
            slices += 1
            summary = dem.summary
            assert summary["particles"] == summary["particles_target"] == summary["particles_inserted"]
            assert not summary["jammed"] and summary["lost_particles"]["count"] == 0
            d = 2.0 * float(dem.attrs["radius"])
            z = dem.frame(dem.n_frames - 1).positions[:, 2]
            seam = np.count_nonzero((z < lo[2] + 0.5 * d) | (z > hi[2] - 0.5 * d))  # centres within d of z = 0 | L
            assert seam >= 0.75 * z.size * d / (hi[2] - lo[2]), (seam, z.size)
    assert slices == 2  # the Watkins slice and the reduction check's


@end_to_end
def test_a_loaded_slice_presses_on_the_wall_with_the_stress_of_its_weight(watkins_run):
    """The tiny Watkins slice (dem.drive.wall_stress: weight) is shortened until its wall stress
    reaches Janssen's rho_p phi g D / (4 mu_w), as LIGGGHTS measured it while loading and as the DEM
    summary does from the settled bed; it keeps pressing on the wall while it flows. A weightless
    slice (the reduction check's) does not touch it."""
    from dpht.dem.dumps import PositionsFile
    from dpht.dem.liggghts import read_thermo

    cfg = config.load(watkins_run.parent / "watkins.yaml")
    p, tube = cfg["particles"], cfg["geometry"]["tube"]
    janssen = p["density"] * cfg["dem"]["fill_solid_fraction"] * 9.81 * tube["inner_diameter"] / (4 * cfg["contact"]["friction"]["pw"])
    loads = {}
    for path in (watkins_run / "dem").glob("*/positions.h5"):
        with PositionsFile(path) as dem:
            loads[path.parent.name] = dem.summary["wall_load"]
    loaded = {key: load for key, load in loads.items() if load and load["target_Pa"] > 0}
    weightless = [load for load in loads.values() if load and load["target_Pa"] == 0]
    assert len(loaded) == 1 and weightless and all(load["flowing_Pa"] < 0.05 * janssen for load in weightless)
    (key, load), = loaded.items()
    assert load["target_Pa"] == pytest.approx(janssen, rel=1e-9)
    # One shortening of 0.1% adds at most about 30% at this scale; the loop stops at the first above.
    assert janssen <= load["settled_Pa"] <= 2.0 * janssen and load["flowing_Pa"] >= 0.5 * janssen
    assert 0.0 < 1.0 - load["length_m"] / tube["length"] <= 0.025  # LOAD_INCREMENTS x LOAD_STRAIN at most
    # LIGGGHTS' own wall stress (the loading's thermo column) at the end of the loading = the summary's.
    screen = watkins_run / "dem" / key / "work" / "settle" / "screen.txt"
    text = screen.read_text()
    last = [line.split() for line in text.splitlines() if len(line.split()) == 8 and line.split()[0].isdigit()][-1]
    assert float(last[-1]) == pytest.approx(load["settled_Pa"], rel=1e-6)
    assert read_thermo(screen)[-1]["atoms"] == float(last[1])


def test_shipped_watkins_configs_are_valid():
    for name in ("watkins.yaml", "watkins_paper.yaml"):
        cfg = config.load(ROOT / "config" / name)
        assert cfg["particles"]["diameter"] == 320.0e-6 and cfg["geometry"]["tube"]["inner_diameter"] == 10.82e-3
        eq30 = cfg["thermal"]["walls"]["heated_wall"]["temperature"]
        assert eq30 == "-995.70*z**3 + 381.44*z**2 - 657.96*z + 1057.8"  # DPHT paper, Eq. (30)
