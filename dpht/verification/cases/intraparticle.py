"""Resolved intra-particle conduction against the analytic cooled sphere (ParScale, Section 3.1):
the scene, the series and the outputs are :mod:`dpht.studies.cooled_sphere`."""

from __future__ import annotations

from pathlib import Path

from dpht.studies.cooled_sphere import SHELLS, STEP, errors, parscale_error, simulate, write
from dpht.verification.harness import case

TOLERANCE = 1e-5  # the bound on the mean relative error (ParScale reports 1e-6 mean, 1e-5 max)


@case("cooled-sphere", "ParScale Table 1 sphere cooled through h: profiles at t = 2, 5, 8, 10 s against Crank's "
      f"series, mean relative error of T ({SHELLS} shells, the default; step {STEP:g} s)")  # fmt: skip
def cooled_sphere(out=None):
    notes = []
    profiles = simulate(SHELLS, STEP)
    if out is not None:
        e = write(out, profiles)
        notes.append(f"cooled-sphere: wrote {Path(out) / 'cooled_sphere.csv'}, cooled_sphere_convergence.csv and the "
                     "figures cooled_sphere.png, cooled_sphere_convergence.png")  # fmt: skip
    else:
        e = errors(SHELLS, STEP, profiles)
    notes.append(f"ParScale's measure (RMS error / range of the reference): {parscale_error(profiles):.3e}")
    notes.append(f"max relative error: {float(e.max()):.3e}")
    notes.append(f"mean relative error: {float(e.mean()):.3e}")
    return float(e.mean()), TOLERANCE, notes
