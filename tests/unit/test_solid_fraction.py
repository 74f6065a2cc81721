"""Solid fractions measured by the DEM run (``thermal.solid_fraction: measured``, the default): the
HTC and thermal stages read the flowing bed's bulk and near-wall values from the run's summary, the
thermal summary records what it used and where from, a value the tables cannot take stops the run
before it starts, and a bed whose packing varies over the run is reported."""

from __future__ import annotations

import json
import logging

import h5py
import numpy as np
import pytest

from dpht import config, stages
from dpht.closures import htc
from dpht.errors import ConfigError, DPHTError
from dpht.thermal import model as thermal_model
from dpht.verification import scenes
from test_thermal_stage import run_stage, scene  # noqa: F401  (the stage's synthetic scene fixture)

N_FRAMES = 12  # of the synthetic scene


def dem_summary(path, bulk=0.58, near_wall=0.52, per_frame=None):
    """A DEM run summary with the solid fractions the thermal stage reads (dpht.dem.report)."""
    per_frame = per_frame or {"bulk": [bulk] * N_FRAMES, "near_wall": [near_wall] * N_FRAMES}
    path.write_text(json.dumps({"solid_fraction": {"flowing": {"bulk": bulk, "near_wall": near_wall, "frames": [6, 11]},
                                                   "per_frame": per_frame}}))  # fmt: skip
    return path


def measured(dem="0123456789ab"):
    return {region: {"measured": dem, "region": region} for region in ("bulk", "near_wall")}


def test_measured_values_are_the_dem_runs_and_are_recorded(scene, tmp_path):  # noqa: F811
    """A run with measured solid fractions equals one given the same numbers, differs from one at
    other numbers (the RDF tables are read at them), and says in its summary what it used."""
    source = dem_summary(tmp_path / "summary.json")
    out, summary = run_stage(scene, "measured", solid_fraction=measured(), dem_summary=source)
    same, same_summary = run_stage(scene, "given", solid_fraction={"bulk": 0.58, "near_wall": 0.52})
    other, _ = run_stage(scene, "other", solid_fraction={"bulk": 0.58, "near_wall": 0.60})
    with h5py.File(out) as a, h5py.File(same) as b, h5py.File(other) as c:
        assert np.array_equal(a["temperature"][...], b["temperature"][...], equal_nan=True)  # a lost particle is NaN
        assert np.array_equal(a["wall_heat"][...], b["wall_heat"][...])
        assert not np.array_equal(a["wall_heat"][...], c["wall_heat"][...])
    record = summary["solid_fraction"]
    assert record["bulk"] == {"value": 0.58, "source": f"{source}: solid_fraction.flowing.bulk", "dem_frames": [6, 11],
                              "thermal_frames": {"mean": 0.58, "std": 0.0, "frames": [0, N_FRAMES - 1]}}  # fmt: skip
    assert record["near_wall"]["value"] == 0.52 and same_summary["solid_fraction"]["near_wall"]["source"] == "config"


def test_a_measured_value_just_outside_the_rdf_table_is_read_at_its_edge(scene, tmp_path, caplog):  # noqa: F811
    """A near-wall value measured 0.006 above the synthetic PW table's last solid fraction (0.64),
    within dpht.closures.rdf.SOLID_FRACTION_MARGIN, gives the wall heat of the value 0.64 given,
    bit for bit, with a warning and the edge in the summary; 0.651 is refused."""
    source = dem_summary(tmp_path / "dense.json", near_wall=0.646)
    out, summary = run_stage(scene, "dense", solid_fraction=measured(), dem_summary=source)
    edge, _ = run_stage(scene, "edge", solid_fraction={"bulk": 0.58, "near_wall": 0.64})
    with h5py.File(out) as a, h5py.File(edge) as b:
        assert np.array_equal(a["wall_heat"][...], b["wall_heat"][...])
    assert summary["solid_fraction"]["near_wall"]["rdf_read_at"] == 0.64
    assert "measured 0.6460" in caplog.text and "just outside the PW RDF table's solid fractions 0.45-0.64" in caplog.text
    with pytest.raises(ConfigError, match=r"measured 0.6510 .* outside the PW RDF table's solid fractions 0.45-0.64 "
                                          r"\(by more than 0.01; pw_radiation\)"):
        run_stage(scene, "denser", solid_fraction=measured(), dem_summary=dem_summary(tmp_path / "denser.json", near_wall=0.651))


def test_a_measured_value_outside_the_rdf_table_stops_before_the_run(scene, tmp_path):  # noqa: F811
    """The synthetic RDF tables cover solid fractions 0.45-0.64: a near-wall value of 0.30 measured
    by the DEM is refused naming the key, the value and the summary file; nothing is written."""
    source = dem_summary(tmp_path / "loose.json", near_wall=0.30)
    message = (r"thermal.solid_fraction.near_wall = measured: the DEM run measured 0.3000 \(.*loose.json\), outside "
               r"the PW RDF table's solid fractions 0.45-0.64 \(by more than 0.01; pw_radiation\)")  # fmt: skip
    with pytest.raises(ConfigError, match=message):
        run_stage(scene, "loose", solid_fraction=measured(), dem_summary=source)
    assert not (scene[0] / "loose.h5").exists()
    with pytest.raises(DPHTError, match=r"nothing.json: the DEM run measured no bulk solid fraction"):
        (tmp_path / "nothing.json").write_text("{}")
        run_stage(scene, "nothing", solid_fraction=measured(), dem_summary=tmp_path / "nothing.json")


def test_another_dem_summary_is_not_taken_for_the_same_run(scene, tmp_path):  # noqa: F811
    """The checkpoints' fingerprint holds what the stage reads of the DEM run: the same output name
    with a summary measuring another solid fraction is computed again, not published from before."""
    first, first_summary = run_stage(scene, "resumed_summary", solid_fraction=measured(), dem_summary=dem_summary(tmp_path / "a.json"))
    with h5py.File(first) as f:
        before = f["wall_heat"][...]
    again, summary = run_stage(scene, "resumed_summary", solid_fraction=measured(),
                               dem_summary=dem_summary(tmp_path / "b.json", near_wall=0.60))  # fmt: skip
    assert (first_summary["solid_fraction"]["near_wall"]["value"], summary["solid_fraction"]["near_wall"]["value"]) == (0.52, 0.60)
    with h5py.File(again) as f:
        assert not np.array_equal(f["wall_heat"][...], before)


def test_a_bed_whose_packing_varies_over_the_run_is_reported(scene, tmp_path, caplog):  # noqa: F811
    """Per-frame values spread by more than 0.02 over the thermal frames (a settling start): a
    warning names the region, the mean and the spread; a steady bed gives none."""
    bulk = list(np.linspace(0.62, 0.54, N_FRAMES))
    source = dem_summary(tmp_path / "varying.json", bulk=0.55, per_frame={"bulk": bulk, "near_wall": [0.52] * N_FRAMES})
    with caplog.at_level(logging.WARNING, logger="dpht"):
        _, summary = run_stage(scene, "varying", solid_fraction=measured(), dem_summary=source)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and "solid fraction" in r.getMessage()]
    assert len(warnings) == 1 and "bulk solid fraction varies" in warnings[0]
    assert f"standard deviation {np.std(bulk):.4f} > 0.02" in warnings[0]
    assert summary["solid_fraction"]["bulk"]["thermal_frames"]["std"] == pytest.approx(np.std(bulk))
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="dpht"):
        run_stage(scene, "steady", solid_fraction=measured(), dem_summary=dem_summary(tmp_path / "steady.json"))
    assert not [r for r in caplog.records if "solid fraction" in r.getMessage()]


def test_the_htc_table_stage_reads_its_solid_fraction_from_the_dem_run(tmp_path):
    spec = scenes.spec(["pfw"])
    table_spec = {**config.htc_spec(spec, "pfw"), "solid_fraction": {"measured": "0123456789ab", "region": "near_wall"}}
    io = {"input": {"dem_summary": str(dem_summary(tmp_path / "summary.json", near_wall=0.5123))},
          "output": {"table": str(tmp_path / "pfw.h5")}, "threads": 1}  # fmt: skip
    assert stages.run("htc_table", json.dumps(table_spec), json.dumps(io), str(tmp_path / "htc.log")) == 0
    table = htc.load_table(tmp_path / "pfw.h5")
    assert table.solid_fraction == 0.5123
    reference = htc.table_from_spec({**table_spec, "solid_fraction": 0.5123})
    assert np.array_equal(table.values, reference.values)
    assert "near_wall solid fraction 0.5123 measured by the DEM run" in (tmp_path / "htc.log").read_text()


def test_the_model_refuses_an_unresolved_measured_value():
    tables = scenes.htc_tables(scenes.spec(["pfp"]))
    with pytest.raises(ConfigError, match=r"thermal.solid_fraction: \['bulk', 'near_wall'\] measured by the DEM run"):
        thermal_model.build(scenes.spec(["pfp"], solid_fraction="measured"), None, tables)
