"""The manual builds without a warning, and the README cannot drift from it.

- the Sphinx build of docs/ with warnings as errors (the config-key and CLI pages generated from the
  schema and the parser included, and the example gallery, whose scripts run in it);
- every key of the config schema has a description;
- every time the README quotes is the one the manual's timings table gives, for the same command;
- every measured number the README quotes (%, K, g/s, errors) is in the manual;
- the worked example of "Your own design" passes the pre-flight check.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
PERFORMANCE = DOCS / "manual" / "performance.md"

sys.path.insert(0, str(DOCS / "_ext"))
import generated_pages  # noqa: E402

# A wall time as the docs write it: "46 min 7 s", "2 min 44.5 s", "1.1 min", "3 h".
DURATION = re.compile(r"(?<![\d.,])\d+(?:\.\d+)?\s(?:h|min)(?:\s\d+(?:\.\d+)?\ss\b)?")


def table(text: str, heading: str) -> list[dict[str, str]]:
    """The rows of the first Markdown table after ``heading``, as {column header: cell}."""
    lines = text[text.index(heading) :].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in re.split(r"(?<!\\)\|", line.strip())[1:-1]])
    header, body = rows[0], rows[2:]
    return [dict(zip(header, row)) for row in body]


def plain(text: str) -> str:
    """Text with Markdown emphasis dropped and the minus sign written as a hyphen."""
    return text.replace("**", "").replace("−", "-")


@pytest.mark.docs
def test_manual_builds_without_warnings(tmp_path):
    """sphinx-build -W: a broken link, a missing anchor, a page in no toctree or a bad docstring fails."""
    result = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "-d", str(tmp_path / "doctrees"),
         str(DOCS), str(tmp_path / "html")],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-5000:]
    html = tmp_path / "html"
    config_keys = (html / "guide" / "configuration.html").read_text()
    for key in ("particles.diameter", "thermal.walls", "geometry.mixers[type=radial].angle", "variants"):
        assert key in config_keys, key
    assert "calibrate-orifice" in (html / "guide" / "cli.html").read_text()
    # The gallery: every example ran (sphinx-gallery, on docs/examples/data/) and drew its figures.
    examples = sorted(p.stem for p in (DOCS / "examples").glob("plot_*.py"))
    assert len(examples) >= 4 and (html / "gallery" / "index.html").is_file()
    for name in examples:
        page = (html / "gallery" / f"{name}.html").read_text()
        assert f"sphx_glr_{name}_001.png" in page, f"{name}: no figure in its page"
        assert (html / "_images" / f"sphx_glr_{name}_001.png").stat().st_size > 10_000, name


def test_every_schema_key_has_a_description():
    assert generated_pages.leaves_without_description() == []


def test_unit_is_read_from_a_description():
    assert generated_pages.split_unit("m, z of the plate's top face") == ("m", "z of the plate's top face")
    assert generated_pages.split_unit("particle diameter in m") == ("m", "particle diameter")
    assert generated_pages.split_unit("W/(m K): a number") == ("W/(m K)", "a number")
    assert generated_pages.split_unit("s of heating") == ("s", "s of heating")
    assert generated_pages.split_unit("open fraction of the cross-section") == ("", "open fraction of the cross-section")


def test_readme_times_are_the_timings_table():
    """Each row of the README's time table matches a row of the manual's, command, time and date."""
    readme = README.read_text()
    timings = table(PERFORMANCE.read_text(), "## Timings")
    quoted = table(readme, "How long they take")
    assert quoted, "the README's table of times is missing"
    for row in quoted:
        command = re.search(r"`([^`]+)`", row["command"]).group(1)
        matches = [
            t for t in timings
            if command in t["command"] and plain(row["wall time"]) in plain(t["wall time"]) and row["measured"] == t["measured"]
        ]  # fmt: skip
        assert matches, f"README: {command} took {row['wall time']} ({row['measured']}): not in {PERFORMANCE.name}'s Timings"
    # No other time in the README: every duration it writes is one of the table's.
    table_times = {d for t in timings for d in DURATION.findall(plain(t["wall time"]))}
    for duration in DURATION.findall(plain(readme)):
        assert duration in table_times, f"README quotes {duration!r}, which the manual's Timings table does not give"


def test_readme_numbers_are_in_the_manual():
    """A measured number the README quotes (a percentage, a temperature, a flow, an error) has its source in the manual."""
    readme = plain(README.read_text())
    manual = plain(" ".join(p.read_text() for p in DOCS.rglob("*.md") if "_build" not in p.parts))
    numbers = re.findall(r"[+-]?\d+(?:\.\d+)?(?:e-\d+)?\s?(?:%|K\b|g/s)|\d\.\d+e-\d+", readme)
    assert len(numbers) > 20
    missing = [n for n in numbers if n not in manual and n.replace(" ", "") not in manual.replace(" ", "")]
    assert not missing, f"README numbers not found in the manual: {missing}"


def test_readme_is_short_and_names_the_ci_command():
    readme = README.read_text()
    assert len(readme.splitlines()) <= 250
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert ci == "make test" and "make test" in readme


@pytest.mark.slow
def test_worked_example_passes_the_check(tmp_path):
    """The variants file of "Your own design" is a config the workflow accepts."""
    page = (DOCS / "guide" / "your-design.md").read_text()
    block = re.search(r"```yaml\n(# my_variants\.yaml.*?)```", page, re.S).group(1)
    example = tmp_path / "my_variants.yaml"
    example.write_text(block)
    result = subprocess.run(
        [sys.executable, "-m", "dpht", "check", "config/config.yaml", str(example)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert "3 variant(s)" in result.stdout
