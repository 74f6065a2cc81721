"""The intra-particle study (dpht.studies.intraparticle) on a small bed: the wall-heat difference
between uniform and resolved particles grows with the Biot number, and auto decides both scenes."""

import csv
import math
from pathlib import Path

from dpht import config
from dpht.studies import intraparticle as study

DEFAULT = Path(__file__).resolve().parents[2] / "config" / "config.yaml"


def test_small_sweep_and_auto_scenes(tmp_path):
    cfg = config.load(DEFAULT)
    s = {**cfg["intraparticle_study"], "conductivities": [10.0, 1.0, 0.1], "width": 5.0, "height": 6.5,
         "duration": 0.3, "step": 0.02, "shells": 6}  # fmt: skip
    spec = study.stage_spec(s, cfg)  # the thermal model of cfg, the scene of the study's section
    summary = study.run_study(spec["base"], spec["study"], tmp_path, progress=lambda line: None)
    for series in study.SERIES:
        rows = [r for r in summary["sweep"] if r["series"] == series]
        biot = [r["biot_max"] for r in rows]
        difference = [r["relative_difference"] for r in rows]
        assert len(rows) == 3 and biot == sorted(biot) and difference == sorted(difference) and difference[0] > 0
        assert all(r["wall_energy_resolved_J"] < r["wall_energy_lumped_J"] for r in rows)  # the surface warms first
    stagnant, stream = ([r for r in summary["sweep"] if r["series"] == series] for series in study.SERIES)
    assert all(b["biot_max"] > a["biot_max"] for a, b in zip(stagnant, stream))  # the gas adds h A to G
    assert stream[-1]["relative_difference"] > 2 * stagnant[-1]["relative_difference"]  # its heat crosses the interior
    scenes = {(r["scene"], r["series"]): r for r in summary["auto_scenes"]}
    for series in study.SERIES:
        on, off = scenes["auto_on", series], scenes["auto_off", series]
        assert on["auto_resolved"] and on["biot_max"] > s["biot_threshold"]
        assert not off["auto_resolved"] and off["biot_max"] < s["biot_threshold"]
        assert off["relative_difference"] < on["relative_difference"]
    with open(tmp_path / "biot_sweep.csv") as f:
        assert len(list(csv.DictReader(f))) == 6
    assert (tmp_path / "biot_sweep.png").stat().st_size > 0 and (tmp_path / "auto_scenes.csv").is_file()


def test_crossing_interpolates_between_sweep_points():
    assert math.isclose(study.crossing([0.1, 1.0], [0.001, 0.1], 0.01), 0.1 * 10**0.5, rel_tol=1e-12)
    assert study.crossing([0.1, 1.0], [0.001, 0.002], 0.01) is None
