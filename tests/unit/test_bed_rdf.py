"""python -m dpht rdf (dpht.radiation.bed_rdf): overlaps, output folder and negative numbers are
checked before any ray is traced (issue 11, item 7)."""

import numpy as np
import pytest

from dpht.__main__ import main
from dpht.errors import DPHTError
from dpht.radiation.bed_rdf import check_overlaps

R = 5e-4


def cli(tmp_path, centres, *extra, out=None):
    positions = tmp_path / "bed.txt"
    positions.write_text("\n".join(" ".join(repr(float(v)) for v in c) for c in centres) + "\n")
    out = tmp_path / "rdf.csv" if out is None else out
    return main(["rdf", str(positions), "--emissivity", "0.8", "--rays", "400", "--out", str(out), *extra]), out


def test_an_overlap_of_80_percent_is_refused_naming_the_pair(tmp_path, capsys):
    """It used to trace silently and give the neighbour an RDF of 0.000 (about 0.055 expected)."""
    code, out = cli(tmp_path, [(0, 0, 0), (1.2 * R, 0, 0), (5 * R, 0, 0)], "--radius", str(R))
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert "1 pairs of spheres overlap by more than --max-overlap = 0.05 radii, e.g. rows 0 and 1 by 0.8 R" in err


def test_contact_overlaps_are_traced(tmp_path):
    """A DEM contact (0.03 R) is traced: the neighbour gets about the touching pair's RDF, the view
    factor (1 - cos 30 deg) / 2 = 0.067 absorbed at 0.8 with reflections: about 0.055."""
    code, out = cli(tmp_path, [(0, 0, 0), (1.97 * R, 0, 0)], "--radius", str(R), "--rays", "20000")
    assert code == 0
    table = np.loadtxt(out, delimiter=",")
    assert table.shape == (2, 4)
    assert table[0, 1] == pytest.approx(0.055, abs=0.006)  # 3.5 standard errors of 20,000 rays


def test_overlaps_across_a_periodic_boundary_and_with_plane_walls():
    box = np.array([[0.0, 0.0, 0.0], [0.01, 0.01, 0.01]])
    across = np.array([[0.0002, 0.005, 0.005], [0.0098 - 0.5 * R, 0.005, 0.005]])  # 1.3 R apart through x = 0
    check_overlaps(across, R, 0.05, box=box, periodic=(False, False, False))  # not periodic: far apart
    with pytest.raises(DPHTError, match="rows 0 and 1 by 0.7 R"):
        check_overlaps(across, R, 0.05, box=box, periodic=(True, False, False))
    with pytest.raises(DPHTError, match="--wall-plane number 1 cuts 1 spheres .* row 0 by 0.6 R"):
        check_overlaps(across, R, 0.05, planes=[((0.0, 0.0, 0.0), (-1.0, 0.0, 0.0))])


def test_a_missing_output_folder_is_named_before_tracing(tmp_path, capsys):
    code, _ = cli(tmp_path, [(0, 0, 0)], "--radius", str(R), out=tmp_path / "no" / "rdf.csv")
    assert code == 2 and f"the folder {tmp_path / 'no'} does not exist" in capsys.readouterr().err
    code, _ = cli(tmp_path, [(0, 0, 0)], "--radius", str(R), out=tmp_path)
    assert code == 2 and "is a folder" in capsys.readouterr().err


def test_negative_numbers_need_no_equals_sign(tmp_path, capsys):
    code, _ = cli(tmp_path, [(0, 0, 0)], "--radius", "-5e-4")
    assert code == 2 and "--radius must be positive (a length in m); got -0.0005" in capsys.readouterr().err
    code, out = cli(tmp_path, [(0, 0, 0)], "--radius", str(R), "--wall-plane", "0", "0", "-1e-3", "0", "0", "-1e-3")
    assert code == 0 and np.loadtxt(out, delimiter=",").shape == (3,)
