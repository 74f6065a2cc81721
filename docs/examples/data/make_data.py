"""Makes the data of the example gallery (docs/examples/): the tiny scene of the tests
(.test/config/config.yaml) with a coarser wall mesh and a quarter of its frames, run by the workflow
as a design of two variants, ``air`` (the scene as it is) and ``vacuum`` (no gas: no conduction
through the gas gap). Kept here: the DEM positions, the wall table and the thermal output of
``air``, and the comparison of the two (``variants.csv``, ``variants.totals.csv``).

Run from anywhere, with the project's environment (LIGGGHTS; a minute or two):
``python docs/examples/data/make_data.py``. The examples read only the files it writes.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

DATA = Path(__file__).resolve().parent
ROOT = DATA.parents[2]
sys.path.insert(0, str(ROOT))

from dpht import config  # noqa: E402

OVERRIDES = {
    "name": "gallery",
    "geometry": {"mesh_size": 2.0},  # wall triangles of about two diameters: a smaller wall table
    "dem": {"dump_interval": 2000},  # a frame every 20 ms: 16 frames in the 0.3 s of flow
    # On the coarser wall the DEM run's near-wall solid fraction (0.57) leaves the shipped RDF table's range.
    "thermal": {"solid_fraction": {"near_wall": 0.5}},
    "variants": {"air": {}, "vacuum": {"thermal": {"gas_pressure": 0.0}}},
}


def main() -> None:
    test = ROOT / ".test" / "config" / "config.yaml"
    cfg = yaml.safe_load(test.read_text())
    # The shipped RDF table, by its path in the repository (the working folder links tables/rdf).
    cfg["thermal"]["rdf_table"] = os.path.relpath((test.parent.parent / cfg["thermal"]["rdf_table"]).resolve(), ROOT)
    del cfg["variants"]
    cfg = config.merge(cfg, OVERRIDES)
    with tempfile.TemporaryDirectory(prefix="dpht-gallery-") as folder:
        work = Path(folder)
        (work / "config").symlink_to(ROOT / "config")  # the Snakefile's config/config.yaml
        (work / "tables").mkdir()
        (work / "tables" / "rdf").symlink_to(ROOT / "tables" / "rdf")
        (work / "gallery.yaml").write_text(yaml.safe_dump(cfg))
        subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"), "--cores", "2",
                        "--directory", str(work), "--configfile", str(work / "gallery.yaml")], check=True)  # fmt: skip
        run = work / "results" / "gallery"
        keys = json.loads((run / "air" / "summary.json").read_text())["stage_keys"]
        files = {
            "positions.h5": work / "results" / "dem" / keys["dem"] / "positions.h5",
            "walls.h5": work / "results" / "geometry" / keys["geometry"] / "walls.h5",
            "thermal.h5": work / "results" / "thermal" / keys["thermal"] / "thermal.h5",
            "variants.csv": run / "comparison" / "variants.csv",
            "variants.totals.csv": run / "comparison" / "variants.totals.csv",
        }
        for name, source in files.items():
            shutil.copyfile(source, DATA / name)
            print(f"{DATA / name}: {(DATA / name).stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
