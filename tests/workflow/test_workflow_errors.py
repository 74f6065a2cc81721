"""What a user sees when things go wrong under Snakemake: config problems before any job, with the
file and line; a failing stage's own message, once, as the error Snakemake shows."""

import json
import re
import subprocess
from pathlib import Path

import h5py
import pytest

from dpht import config, stages
from dpht.closures import rdf
from dpht.plan import Plan, figure
from test_workflow import SNAKEMAKE, end_to_end, write_config


def snakemake(workdir, *args, timeout=300):
    return subprocess.run([*SNAKEMAKE, "--directory", str(workdir), *args], capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


def test_config_problems_stop_the_workflow_before_any_job(tmp_path):
    write_config(tmp_path / "tiny.yaml", {"thermal": {"htc_table": {"temperature_range": [350.0, 1000.0]}}})
    result = snakemake(tmp_path, "--configfile", str(tmp_path / "tiny.yaml"))
    assert result.returncode != 0
    assert "the config cannot run (checked before any job started)" in result.stderr
    assert f"{tmp_path / 'tiny.yaml'}:" in result.stderr and "thermal.htc_table.temperature_range" in result.stderr
    assert "Traceback" not in result.stderr and "Job stats" not in result.stdout + result.stderr
    assert not (tmp_path / "results").exists()


def test_a_variant_name_with_a_space_is_named(tmp_path):
    """Issue 11, item 6: it ended in an unexplained MissingInputException."""
    write_config(tmp_path / "tiny.yaml", {"variants": {"base": {}, "my variant": {}}})
    result = snakemake(tmp_path, "--dry-run", "--configfile", str(tmp_path / "tiny.yaml"))
    assert result.returncode != 0
    assert "variants: the name 'my variant' is not allowed" in result.stderr
    assert "MissingInputException" not in result.stderr


def test_a_yaml_error_in_the_default_config_names_file_and_line(tmp_path):
    """Snakemake's own message for config/config.yaml names neither (issue 11, item 8)."""
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text("particles:\n  diameter: 1.0e-3\n    density: 3560\n")
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode != 0
    assert "config/config.yaml, line 3, column 12: not valid YAML: mapping values are not allowed" in result.stderr


def test_a_failing_stage_shows_its_own_message_once(tmp_path):
    """Issue 11, item 8: the stage's message was printed twice, then buried under a RuleException
    holding the whole command and its JSON. Here the figures stage fails on foreign inputs (HDF5
    files of no known format, marked up to date with --touch; files that cannot be read at all the
    workflow would set aside and make again, dpht.integrity). Every effect is switched on, so that
    no screening decides the thermal stage's inputs."""
    write_config(tmp_path / "tiny.yaml", {"thermal": {"effects": "all"}})
    plan = Plan(config.load(tmp_path / "tiny.yaml"))
    inputs = list(plan.figures_inputs("base").values())
    for file in inputs:
        (tmp_path / file).parent.mkdir(parents=True, exist_ok=True)
        h5py.File(tmp_path / file, "w").close()
    touched = snakemake(tmp_path, "--touch", *inputs, "--configfile", str(tmp_path / "tiny.yaml"))
    assert touched.returncode == 0, touched.stderr[-3000:]
    result = snakemake(tmp_path, figure("base", "cross_section", plan.name), "--configfile", str(tmp_path / "tiny.yaml"))
    assert result.returncode != 0
    text = result.stdout + result.stderr
    message = f"dpht: error in stage figures: {plan.figures_inputs('base')['walls']}: not a wall table"
    assert text.count(message) == 1, text
    error = text.index("RuleException")
    assert text.index(message) - error < 200  # the first lines of the error are the message
    assert text.index(message) < text.index("Error in rule figures")
    assert "(log: results/tiny/base/figures/figures.log)" in text
    assert "--spec" not in text and "CalledProcessError" not in text


def test_stage_errors_go_to_the_log_and_become_the_rules_error(tmp_path, capsys):
    log = tmp_path / "x.log"
    io = '{"input": {"thermal": "%s"}, "output": {"summary": "%s"}}' % (tmp_path / "none.json", tmp_path / "s.json")
    bad = '{"stage_keys": {}}'
    code = stages.run("variant_summary", bad, io, str(log), errors_to_log_only=True)
    assert code == 1
    assert "dpht: error" not in capsys.readouterr().err  # the workflow shows it, from the log
    failure = stages.failure("variant_summary", log, code)
    assert str(failure).startswith("dpht: error in stage variant_summary: unexpected FileNotFoundError")
    assert str(failure).endswith(f"(log: {log})")
    assert "no message" in str(stages.failure("thermal", tmp_path / "missing.log", -9))


@end_to_end
def test_a_near_wall_solid_fraction_just_beyond_the_pw_table_is_read_at_its_edge(tmp_path):
    """The tiny scene with dem.seed 10009 measures a flowing near-wall solid fraction of 0.5588 (its
    settled bed: 0.501, so the settled bed does not predict it), beyond the shipped PW RDF table's
    0.2-0.55 by less than dpht.closures.rdf.SOLID_FRACTION_MARGIN: the screening and the thermal
    stage warn, naming the value and the table's range, read the table at 0.55, and the thermal
    summary records it. (Further out the screening refuses: tests/unit/test_screening.py.)"""
    write_config(tmp_path / "tiny.yaml", {"dem": {"seed": 10009}})
    result = snakemake(tmp_path, "--configfile", str(tmp_path / "tiny.yaml"), timeout=900)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    found = re.search(r"thermal: warning: thermal.solid_fraction.near_wall = measured: the DEM run measured (0\.\d{4}) "
                      r"\(results/dem/\w{12}/summary.json\), just outside the PW RDF table's solid fractions 0.2-0.55 "
                      r"\(pw_radiation\): its factors are read at 0.55", text)  # fmt: skip
    assert found and 0.55 < float(found.group(1)) <= 0.55 + rdf.SOLID_FRACTION_MARGIN, text[-3000:]
    (summary,) = (tmp_path / "results" / "thermal").glob("*/summary.json")
    near_wall = json.loads(summary.read_text())["solid_fraction"]["near_wall"]
    assert near_wall["value"] == pytest.approx(float(found.group(1)), abs=5e-5) and near_wall["rdf_read_at"] == 0.55
