"""The sheared periodic box's config sections for the tests (dpht.dem.sheared): a 15-diameter box
(the paper's) for rendering and checks, :func:`spec_with` for variants."""

from __future__ import annotations

import copy

SPEC = {
    "particles": {"diameter": 1.0e-3, "density": 2000.0, "youngs_modulus_dem": 5.0e6, "poisson_ratio": 0.3,
                  "conductivity": 2.0, "specific_heat": "500.0 + 0.0 * T"},
    "contact": {"restitution": {"pp": 0.8, "pw": 0.5}, "friction": {"pp": 0.5, "pw": 0.3},
                "rolling_friction": {"pp": 0.1, "pw": 0.2}},
    "dem": {"timestep": 1.0e-5, "settle_time": 0.02, "dump_interval": 250, "seed": 32452843},
    "sheared_box": {"size": 15, "solid_fraction": 0.45, "peclet": 0.25, "reference_temperature": 300.0,
                    "steady_strain": 1.0, "strain": 3.0},
}  # fmt: skip


def spec_with(**sections) -> dict:
    """SPEC with the keys of each named section replaced: ``spec_with(dem={"seed": 10007})``."""
    spec = copy.deepcopy(SPEC)
    for section, values in sections.items():
        spec[section].update(values)
    return spec
