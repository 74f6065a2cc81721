"""Results checked by their content before the workflow plans (dpht.integrity), published files as
verified copies (dpht.util.files.publish), and stage caches that look at the data, not at a stored
digest. Without Snakemake: the stage runs' manifests written by dpht.integrity.recorded around
stand-in stage bodies that write real files; the whole workflow, damaged and run again, is in
tests/workflow/test_faults.py."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from dpht import integrity
from dpht.dem import dumps, liggghts
from dpht.plan import Plan, path
from dpht.thermal.checkpoint import fingerprint
from dpht.util.files import publish
from test_dumps import gather, synthetic_run
from test_workflow import TINY


@pytest.fixture
def laid_out(tmp_path, monkeypatch):
    """The tiny plan's geometry, DEM, thermal and figures runs as files under ``tmp_path``, each
    written inside ``recorded`` as the stage process does (paths relative to the working folder)."""
    monkeypatch.chdir(tmp_path)
    plan = Plan(TINY)
    keys = plan.keys["base"]
    files = {"walls": path("geometry", keys["geometry"], "walls.h5"), "positions": path("dem", keys["dem"], "positions.h5"),
             "thermal": path("thermal", keys["thermal"], "thermal.h5"), "png": "results/tiny/base/figures/cross_section.png"}  # fmt: skip

    def stage(name, log, inputs, outputs, payload):
        for file in outputs.values():
            os.makedirs(os.path.dirname(file), exist_ok=True)
        with integrity.recorded(name, log, inputs, outputs):
            for key, file in outputs.items():
                if file.endswith(".h5"):
                    with h5py.File(file, "w") as f:
                        f["data"] = np.arange(20000.0) * payload
                else:
                    with open(file, "wb") as f:
                        f.write(b"\x89PNG" + bytes(range(256)) * 40 * payload)

    stage("geometry", path("geometry", keys["geometry"], "geometry.log"), {}, {"walls": files["walls"]}, 1)
    stage("dem", path("dem", keys["dem"], "dem.log"), {"walls": files["walls"]}, {"positions": files["positions"]}, 2)
    stage("thermal", path("thermal", keys["thermal"], "thermal.log"), {"positions": files["positions"], "walls": files["walls"]},
          {"thermal": files["thermal"]}, 3)  # fmt: skip
    stage("figures", "results/tiny/base/figures/figures.log", {"thermal": files["thermal"]}, {"cross_section": files["png"]}, 1)
    return plan, files


def test_each_stage_run_records_its_outputs_and_inputs(laid_out):
    plan, files = laid_out
    manifest = json.loads(integrity.manifest_path(path("thermal", plan.keys["base"]["thermal"], "thermal.log")).read_text())
    assert manifest["stage"] == "thermal" and set(manifest["inputs"]) == {files["positions"], files["walls"]}
    assert manifest["outputs"][files["thermal"]]["sha256"] == integrity.digest(files["thermal"])
    assert integrity.check(plan) == ([], [])  # nothing to do on intact results


@pytest.mark.parametrize("damage", ["delete", "truncate", "flip bytes", "alter data in place"])
@pytest.mark.parametrize("which", ["walls", "positions", "thermal", "png"])
def test_a_missing_cut_or_altered_result_is_moved_aside_and_made_a_target(laid_out, which, damage):
    plan, files = laid_out
    file = files[which]
    data = open(file, "rb").read()
    if damage == "delete":
        os.unlink(file)
    elif damage == "truncate":
        open(file, "wb").write(data[: len(data) // 2])
    elif damage == "flip bytes":  # inside the file, its size and time kept
        stat = os.stat(file)
        with open(file, "r+b") as f:
            f.seek(len(data) // 2)
            f.write(bytes(b ^ 0xFF for b in data[len(data) // 2: len(data) // 2 + 64]))
        os.utime(file, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    elif file.endswith(".h5"):  # valid HDF5, other numbers
        with h5py.File(file, "r+") as f:
            f["data"][5] = -1.0
    else:
        open(file, "wb").write(data[::-1])
    before = sorted(p for p in os.listdir(os.path.dirname(file)))
    dry_targets, dry_warnings = integrity.check(plan, dry_run=True)
    assert sorted(os.listdir(os.path.dirname(file))) == before, "a dry run changed files"
    targets, warnings = integrity.check(plan)
    assert targets == dry_targets == [file]
    assert len(warnings) == 1 and file in warnings[0] and len(dry_warnings) == 1 and "dry run" in dry_warnings[0]
    if damage != "delete":
        assert not os.path.exists(file) and os.path.exists(file + integrity.DAMAGED_SUFFIX)
        assert "moved to" in warnings[0]
    assert all(os.path.exists(f) for f in files.values() if f != file), "an intact result was touched"


def test_only_files_whose_stat_changed_are_hashed_unless_all_are_asked_for(laid_out, monkeypatch):
    """Intact results are not hashed; a file rewritten with its own bytes, or copied over (another
    inode), is hashed and found intact; asked for all, each recorded file is hashed, once."""
    plan, files = laid_out
    hashed = []
    digest = integrity.digest
    monkeypatch.setattr(integrity, "digest", lambda file: hashed.append(str(file)) or digest(file))
    assert integrity.check(plan) == ([], []) and hashed == []
    time.sleep(0.05)  # file times advance by the kernel's clock tick (a few ms)
    data = open(files["positions"], "rb").read()
    open(files["positions"], "wb").write(data)
    os.replace(files["png"], files["png"] + ".tmp")
    open(files["png"], "wb").write(open(files["png"] + ".tmp", "rb").read())
    os.unlink(files["png"] + ".tmp")
    assert integrity.check(plan) == ([], []) and sorted(hashed) == sorted([files["positions"], files["png"]])
    hashed.clear()
    assert integrity.check(plan, hash_all=True) == ([], []) and sorted(hashed) == sorted(files.values())


def test_what_the_stat_fast_path_trusts(laid_out):
    """Bytes changed where the kernel does not see it (the file's size, inode and times as recorded;
    here the record altered instead) pass the fast path and are found by hashing every file."""
    plan, files = laid_out
    log = path("thermal", plan.keys["base"]["thermal"], "thermal.log")
    manifest = integrity.manifest_path(log)
    record = json.loads(manifest.read_text())
    record["outputs"][files["thermal"]]["sha256"] = "0" * 64
    manifest.write_text(json.dumps(record))
    assert integrity.check(plan, dry_run=True) == ([], [])
    targets, warnings = integrity.check(plan, dry_run=True, hash_all=True)
    assert targets == [files["thermal"]] and "altered" in warnings[0]


def test_a_deleted_intermediate_folder_is_made_again_when_a_later_result_read_it(laid_out):
    """results/thermal/<key>/ removed whole (its manifest with it): the figures run's manifest says
    it read thermal.h5, so it is made again."""
    import shutil

    plan, files = laid_out
    shutil.rmtree(os.path.dirname(files["thermal"]))
    targets, warnings = integrity.check(plan)
    assert targets == [files["thermal"]]
    assert "missing (read by the run of results/tiny/base/figures/figures)" in warnings[0]


def test_results_of_another_plan_are_reported_never_made_targets(laid_out):
    plan, files = laid_out
    other = Plan({**TINY, "particles": {**TINY["particles"], "conductivity": 3.0}})
    assert other.keys["base"]["thermal"] != plan.keys["base"]["thermal"]
    with open(files["thermal"], "ab") as f:
        f.write(b"junk")
    os.unlink(files["png"])  # the same variant's figure: a target of both plans
    targets, warnings = integrity.check(other)
    assert targets == [files["png"]] and os.path.exists(files["thermal"])
    assert any(files["thermal"] in w and "left as it is" in w for w in warnings)


def test_a_changed_source_file_makes_the_results_read_from_it_again(laid_out, tmp_path):
    """A file no stage writes (a shipped table, a file the config names) that changed after a run read
    it: that run's outputs are made again."""
    plan, files = laid_out
    source = tmp_path / "given_table.h5"
    source.write_bytes(b"table one")
    thermal_log = path("thermal", plan.keys["base"]["thermal"], "thermal.log")
    with integrity.recorded("thermal", thermal_log, {"rdf": str(source), "positions": files["positions"]}, {"thermal": files["thermal"]}):
        pass
    source.write_bytes(b"table two")
    targets, warnings = integrity.check(plan)
    assert targets == [files["thermal"]] and f"made from {source}" in warnings[0]


def test_publish_is_a_verified_copy_never_a_hard_link(tmp_path):
    work, out = tmp_path / "work.h5", tmp_path / "out.h5"
    work.write_bytes(os.urandom(100_000))
    publish(work, out)
    assert out.read_bytes() == work.read_bytes()
    assert os.stat(out).st_ino != os.stat(work).st_ino and os.stat(work).st_nlink == 1
    with open(out, "r+b") as f:  # damage to the published file stays there
        f.seek(50_000)
        f.write(b"\0" * 1000)
    assert out.read_bytes() != work.read_bytes()
    publish(work, out)
    assert out.read_bytes() == work.read_bytes()


def _positions(tmp_path):
    synthetic_run(tmp_path)
    out = tmp_path / "positions.h5"
    gather(tmp_path, out)
    with h5py.File(out, "r+") as h5:
        h5.attrs["source_key"] = "k"
        h5.attrs["summary"] = "{}"
        h5.attrs[dumps.CONTENT_DIGEST] = dumps.content_digest(h5)
    return out


def test_thermal_fingerprint_hashes_the_frames_not_the_stored_digest(tmp_path):
    positions = _positions(tmp_path)
    before = fingerprint({"a": 1}, positions, [])
    with h5py.File(positions, "r+") as h5:  # frames changed in place, the stored digest kept
        h5["positions"][1, 0, 0] += 1e-3
    assert fingerprint({"a": 1}, positions, []) != before


def test_dem_stage_does_not_reuse_a_positions_file_whose_frames_changed(tmp_path):
    positions = _positions(tmp_path)
    assert liggghts._existing(positions, "k") == {}
    with h5py.File(positions, "r+") as h5:
        h5["positions"][2, 3, 1] = 0.0
    assert liggghts._existing(positions, "k") is None


def test_a_damaged_file_written_beside_the_outputs_makes_its_stage_run_again(laid_out):
    """A figure's CSV or JSON, not a declared output: its run's first output is made again."""
    plan, files = laid_out
    log = "results/tiny/base/figures/figures.log"
    with integrity.recorded("figures", log, {"thermal": files["thermal"]}, {"cross_section": files["png"]}):
        with open("results/tiny/base/figures/engineering.json", "w") as f:
            f.write('{"wall_heat_W": 1.5}\n')
    with open("results/tiny/base/figures/engineering.json", "w") as f:
        f.write('{"wall_heat_W": 9.5}\n')
    dry = integrity.check(plan, dry_run=True)
    assert os.path.exists(files["png"])
    targets, warnings = integrity.check(plan)
    assert targets == dry[0] == [files["png"]] and not os.path.exists(files["png"])
    assert "engineering.json is damaged" in warnings[0] and os.path.exists("results/tiny/base/figures/engineering.json.damaged")


# --- tables validated on load ---------------------------------------------------------------------

SHIPPED_RDF = sorted((Path(__file__).resolve().parents[2] / "tables" / "rdf" / "shipped").glob("*.h5"))[0]


@pytest.mark.parametrize("dataset, index, value, message", [
    ("pp/rdf", (0, 0), np.nan, r"dataset /pp/rdf has 1 bad entry .* is nan\); expected radiation distribution factors: finite values in \[0, 1\]"),
    ("pw/rdf", (1, 2), -0.2, r"dataset /pw/rdf .* is -0.2\)"),
    ("pp/stderr", (0, 1), np.inf, r"dataset /pp/stderr"),
    ("pw/solid_fraction", (1,), 0.0, r"dataset /pw/solid_fraction is not strictly increasing"),
])  # fmt: skip
def test_an_rdf_table_with_entries_out_of_range_is_refused_naming_file_and_dataset(tmp_path, dataset, index, value, message):
    from dpht.closures import rdf
    from dpht.errors import DPHTError

    table = tmp_path / "table.h5"
    table.write_bytes(SHIPPED_RDF.read_bytes())
    rdf.load(table)
    with h5py.File(table, "r+") as f:
        f[dataset][index] = value
    with pytest.raises(DPHTError, match=f"{table}: " + message):
        rdf.load(table)


@pytest.mark.parametrize("dataset, index, value", [("values", (2, 3), np.nan), ("values", (0, 0), -1.0),
                                                   ("distance", (3,), 0.0), ("temperature", (0,), np.inf)])
def test_an_htc_table_with_entries_out_of_range_is_refused_naming_file_and_dataset(tmp_path, dataset, index, value):
    from dpht.closures import htc
    from dpht.errors import DPHTError

    table = tmp_path / "htc.h5"
    htc.save_table(table, htc.build_table("pfp", radius=5e-4, k_solid=2.0, solid_fraction=0.6, n_distance=8, n_temperature=6))
    htc.load_table(table)
    with h5py.File(table, "r+") as f:
        f[dataset][index] = value
    with pytest.raises(DPHTError, match=f"{table}: dataset {dataset} "):
        htc.load_table(table)


# --- command-line bounds ---------------------------------------------------------------------------


def test_rdf_command_refuses_rays_that_cannot_fit_in_memory_before_tracing(tmp_path, capsys):
    """It used to end in a MemoryError traceback allocating one particle's outcome codes."""
    from dpht.__main__ import main
    from dpht.radiation.bed_rdf import check_memory

    positions = tmp_path / "bed.txt"
    positions.write_text("0 0 0\n0.002 0 0\n")
    out = tmp_path / "rdf.csv"
    code = main(["rdf", str(positions), "--radius", "5e-4", "--emissivity", "0.8", "--rays", str(10**11), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and "Traceback" not in err
    assert "--rays 100000000000 for 2 particles needs about 2.61e+03 GiB" in err and "use at most" in err
    check_memory(2, 10**6, available=2**30)  # fits
    with pytest.raises(Exception, match="use at most 3.*rays per particle"):
        check_memory(2, 10**9, available=2**30 // 10)


def test_dem_ranks_above_the_cores_here_are_warned_with_the_key_and_line(tmp_path, capsys):
    """dem.ranks: 64 with 2 cores ran the DEM on 2 ranks without a word."""
    from dpht import config, preflight
    from test_workflow import tiny_config

    assert preflight.ranks_warnings(config.validate(tiny_config({"dem": {"ranks": 2}})), cores=2) == []
    many = config.validate(tiny_config({"dem": {"ranks": 64}}))
    assert "dem.ranks = 64: this machine has 2 cores" in preflight.ranks_warnings(many, cores=2)[0]
    file = tmp_path / "many.yaml"
    file.write_text(yaml.safe_dump(tiny_config({"dem": {"ranks": os.cpu_count() + 1}})))
    sources = config.Sources([file])
    preflight.check(Plan(config.validate(sources.merged())), sources)
    assert f"dpht: warning: {file}:" in capsys.readouterr().err


# --- stage logs -------------------------------------------------------------------------------------


def test_a_stage_log_keeps_every_attempt_though_snakemake_removes_it(tmp_path):
    """Snakemake removes a job's log before it runs the job again: the attempts before were lost."""
    import logging

    from dpht import stages

    log = tmp_path / "thermal.log"
    try:
        for attempt in range(3):
            assert stages.run("no_such_stage", "{}", "{}", str(log)) == 2
            logging.getLogger().handlers[-1].close()
            log.unlink()  # as Snakemake does when it starts the job again
    finally:
        logging.basicConfig(force=True)
    assert stages.run("no_such_stage", "{}", "{}", str(log)) == 2
    text = log.read_text()
    assert text.count(f"{stages.LOG_HEADER} no_such_stage, pid {os.getpid()}") == 4 and text.count("unknown stage") == 4
    logging.basicConfig(force=True)


def test_a_second_run_of_the_same_job_never_writes_into_the_first_ones_log(tmp_path):
    """Two `snakemake --nolock` running one job: the second attempt logs beside the first's log."""
    import subprocess

    from dpht.util.files import claim_log

    log = tmp_path / "dem.log"
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from dpht.util.files import claim_log; "
                               f"print(claim_log({str(log)!r}), flush=True); time.sleep(30)"],
                              stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == str(log)
        assert claim_log(log) == tmp_path / f"dem.{os.getpid()}.log"
    finally:
        holder.kill()
        holder.wait()
    assert claim_log(log) == log  # free again
