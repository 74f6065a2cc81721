"""Static beds for the frozen-bed mode (``thermal.frozen_bed``): a packing as a positions file.

The thermal stage reads particles from a positions file (:mod:`dpht.dem.dumps`); a frozen bed holds
one of its frames fixed (:meth:`dpht.thermal.stage.Schedule.frozen_bed`). That frame may come from a
DEM run (the workflow today uses the DEM's frame ``thermal.frozen_bed.frame``, 0 by default: the
settled bed at the start of the flow phase) or, with no DEM at all, from the project's packing
generator (:func:`dpht.radiation.packing.pack`) written here as a one-frame positions file. This is
the seam where a workflow that skips the DEM flow phase for static scenes plugs in.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpht.dem.dumps import DumpFrame, write_positions
from dpht.radiation.packing import Packing


def write_packed_bed(path: str | Path, packing: Packing, *, density: float) -> None:
    """Write ``packing`` (positions in m) as a positions file of one frame; ``density`` kg/m^3.

    Periodic axes of the packing stay periodic; the box is the packing's.
    """
    positions = np.asarray(packing.positions, dtype=np.float64)
    ids = np.arange(1, len(positions) + 1, dtype=np.int64)
    frame = DumpFrame(0, np.asarray(packing.box[0], float), np.asarray(packing.box[1], float), tuple(packing.periodic),
                      ids, positions, np.zeros(positions.shape, dtype=np.int32))  # fmt: skip
    write_positions(Path(path), [frame], radius=packing.radius, density=density, timestep=1.0, dump_interval=1)
