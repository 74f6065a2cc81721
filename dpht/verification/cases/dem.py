"""DEM-stage cases: the time-step bound we compute against LIGGGHTS' own check."""

from __future__ import annotations

import tempfile
from pathlib import Path

from dpht.dem.params import DemParams
from dpht.dem.liggghts import liggghts_rayleigh_fraction
from dpht.verification.harness import case

# (diameter m, density kg/m3, DEM Young's modulus Pa, Poisson ratio, time step s): the DPHT paper's
# Section 6 particles (0.3712 mm, Table 2 DEM properties), the default 1 mm scene, a stiff glass bead.
MATERIALS = (
    (0.3712e-3, 3560.0, 5.0e6, 0.30, 3.0e-6),
    (1.0e-3, 3560.0, 5.0e6, 0.30, 1.0e-5),
    (2.0e-3, 2500.0, 6.0e7, 0.22, 5.0e-6),
)


def scene(diameter: float, density: float, youngs: float, poisson: float, timestep: float) -> tuple[dict, dict]:
    """A DEM spec of a plain 10-diameter tube and its geometry summary (no meshes are read)."""
    tube = {
        "inner_diameter": 10 * diameter,
        "length": 20 * diameter,
        "orifice_height": 2 * diameter,
        "orifice_diameter": 6 * diameter,
        "heated": [2 * diameter, 20 * diameter],
    }
    pair = {"pp": 0.5, "pw": 0.5}
    spec = {
        "particles": {"diameter": diameter, "density": density, "youngs_modulus_dem": youngs, "poisson_ratio": poisson},
        "wall": {"youngs_modulus_dem": youngs, "poisson_ratio": poisson},
        "contact": {"restitution": pair, "friction": pair, "rolling_friction": pair},
        "geometry": {"tube": tube},
        "dem": {
            "timestep": timestep,
            "fill_height": 10 * diameter,
            "settle_time": 0.01,
            "flow_time": 0.01,
            "dump_interval": 10,  # the check runs one thermo interval, dump_interval steps
            "restart_interval": 10,
            "seed": 32452843,
        },
    }
    geometry = {"geometry": {"tube": tube}, "zone_names": ["heated_wall", "adiabatic_wall", "orifice"]}
    return spec, geometry


@case("dem_rayleigh_fraction", "dem.timestep / Rayleigh time, ours vs LIGGGHTS' fix check/timestep/gran",
      requires=("liggghts",))
def dem_rayleigh_fraction():
    errors = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, material in enumerate(MATERIALS):
            params = DemParams.from_spec(*scene(*material))
            theirs = liggghts_rayleigh_fraction(params, Path(tmp) / str(k))
            errors.append(abs(theirs * params.rayleigh_time / params.timestep - 1.0))
    return max(errors), 1e-12  # LIGGGHTS prints 15 significant digits here
