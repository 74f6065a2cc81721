"""Cost of the thermal stage's checkpoints on a real scene: the stage run with its rows in one
segment (a checkpoint only at the end, what the default of 500 frames gives the default scene's
151 frames) against a checkpoint every 10 frames and every frame, paired runs alternated.

    python benchmarks/thermal_checkpoints.py [--config config/config.yaml] [--run .] [--repeat 3]

``--run`` is the folder of a completed ``snakemake --cores 2`` of that config (its positions,
walls and tables are read; the outputs go to a temporary folder). The last line printed is
``checkpoint every 10 frames: +X% wall time`` (median of the paired ratios). ``--tiny`` (the tests)
runs one timed round on a completed run of the tiny scene (``--config .test/config/config.yaml``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

from dpht import config
from dpht.plan import Plan, path
from dpht.stages import effects_decided
from dpht.thermal import stage

SETTINGS = {"one segment": 10**9, "every 10 frames": 10, "every frame": 1}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default="config/config.yaml")
    parser.add_argument("--run", default=".", help="folder of a completed workflow run of that config")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--tiny", action="store_true", help="one timed round (the tests, on the tiny scene's run)")
    args = parser.parse_args(argv)
    if args.tiny:
        args.repeat = 1
    plan = Plan(config.load(args.config))
    key = plan.keys["base"]["thermal"]
    spec = json.loads(plan.spec_json(key))
    for name in config.THERMAL_RUN_SETTINGS:
        spec["thermal"].pop(name, None)

    def screened(screening_key):  # the run's screening decisions, as the workflow reads them
        return json.loads((Path(args.run) / path("screening", screening_key, "screening.json")).read_text())["decisions"]

    inputs = {name: str(Path(args.run) / file) for name, file in plan.thermal_inputs(key, screened).items()}
    spec, _ = effects_decided(spec, inputs)
    seconds = {name: [] for name in SETTINGS}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeat + 1):  # the first round warms numba's cache and the page cache
            for name, frames in SETTINGS.items():
                out = Path(tmp) / f"{repeat}-{frames}" / "thermal.h5"
                out.parent.mkdir()
                started = time.perf_counter()
                stage.run(spec, inputs["positions"], inputs["walls"], {"pfp": inputs["pfp"], "pfw": inputs["pfw"]}, out,
                          rdf_table=inputs.get("rdf"), xdmf=out.with_suffix(".xdmf"), threads=2,
                          checkpoints=stage.Checkpoints(frames=frames))  # fmt: skip
                if repeat:
                    seconds[name].append(time.perf_counter() - started)
    base = seconds["one segment"]
    for name, values in seconds.items():
        print(f"{name:>16}: {', '.join(f'{v:.2f}' for v in values)} s")
    for name in ("every frame", "every 10 frames"):
        ratio = statistics.median(v / b for v, b in zip(seconds[name], base))
        print(f"checkpoint {name}: {100 * (ratio - 1):+.1f}% wall time")


if __name__ == "__main__":
    main()
