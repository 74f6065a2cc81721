"""The hand-over field's file (:class:`dpht.chain.field.Field` in HDF5), what one segment of a chain
writes and the next segment's thermal stage reads: root attributes ``format``, ``rings``,
``sectors``, ``tube_radius`` (m) and ``cup_temperature`` (K); datasets ``temperature`` (cells,
1 + K) K, ``weight`` (cells,), ``count`` (cells,) and ``shell_weight`` (K,)."""

from __future__ import annotations

import h5py
import numpy as np

from dpht.chain.field import CrossSection, Field
from dpht.util.files import replacing
from dpht.util.h5 import open_checked

FORMAT = "dpht-handover-1"


def save_field(path, field: Field) -> None:
    """Write ``field`` to ``path`` (replaced atomically)."""
    with replacing(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(format=FORMAT, rings=field.grid.rings, sectors=field.grid.sectors, tube_radius=field.grid.radius,
                       cup_temperature=field.cup_temperature)  # fmt: skip
        for name in ("temperature", "weight", "count", "shell_weight"):
            f.create_dataset(name, data=getattr(field, name))


def load_field(path) -> Field:
    """The field in ``path`` (DPHTError naming the file when it is no hand-over field)."""
    with open_checked(path, FORMAT, "a hand-over field") as f:
        grid = CrossSection(int(f.attrs["rings"]), int(f.attrs["sectors"]), float(f.attrs["tube_radius"]))
        arrays = {name: f[name][...] for name in ("temperature", "weight", "count", "shell_weight")}
        return Field(grid, np.asarray(arrays["temperature"], dtype=np.float64), arrays["weight"], arrays["count"],
                     float(f.attrs["cup_temperature"]), arrays["shell_weight"])  # fmt: skip
