"""Thermal-stage throughput: particle-steps per second and memory per particle, all six modes.

Dense beds (solid fraction 0.6, 1 mm particles) in a periodic tube with a faceted wall at a fixed
temperature; radiation cutoff 7 radii. One "particle-step" is one particle advanced by one frame:
the frame's cell list and wall contacts plus one evaluation of every enabled mode.

    python benchmarks/thermal_step.py            # N = 1e4, 1e5, 1e6 and the all-pairs reference at 1e4
    python benchmarks/thermal_step.py --n 100000 # one size
    python benchmarks/thermal_step.py --modes conduction   # the four conduction modes only

The last line printed is ``particle-steps/s: VALUE`` (for the last size run).
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import time
from pathlib import Path

import numba
import numpy as np

from dpht.thermal import integrate, model as thermal_model
from dpht.thermal.modes import NAMES
from dpht.verification import reference, scenes

RADIUS = scenes.RADIUS


def rss_bytes(field: str = "VmRSS") -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"{field} not in /proc/self/status")


def settle_memory() -> int:
    """Return freed heap to the system and reset VmHWM (Linux >= 4.0); returns the RSS then."""
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    Path("/proc/self/clear_refs").write_text("5")
    return rss_bytes()


def bed(n: int):
    positions, tube_radius, length = scenes.dense_tube_bed(n, solid_fraction=0.6)
    box = (np.array([-tube_radius, -tube_radius, 0.0]), np.array([tube_radius, tube_radius, length]), (False, False, True))
    return positions, box, scenes.tube_walls(tube_radius, length, element=2 * RADIUS)


MODE_SETS = {"all": list(NAMES), "conduction": [m for m in NAMES if "radiation" not in m]}


def thermal_model_for(walls, n: int, modes="all"):
    s = scenes.spec(MODE_SETS[modes], walls={"hot": {"temperature": 900.0}}, radiation_cutoff=7.0)
    model = thermal_model.build(s, walls, scenes.htc_tables(s), scenes.synthetic_rdf())
    T = np.random.default_rng(1).uniform(300.0, 800.0, n)
    return model, model.enthalpy.enthalpy(T)


def setup(n: int, modes="all"):
    positions, box, walls = bed(n)
    model, h = thermal_model_for(walls, len(positions), modes)
    return positions, walls, model, box, h


def step(model, positions, box, h, rates=None):
    """One thermal step as the thermal stage takes it: frame preparation (cell list, wall
    distances) and one evaluation of every mode. Returns the work arrays and the frame."""
    frame = integrate.prepare_frame(model, positions, *box)
    if rates is None or rates.q.size != frame.particles.size:
        rates = integrate.Rates.for_frame(model, frame)
    integrate.advance(model, frame, h, 1e-4, rates)
    return rates, frame


def measure(n: int, repeats: int, modes="all") -> float:
    small = setup(5_000, modes)
    step(small[2], small[0], small[3], small[4])  # compile / load the kernels for this mode set
    del small
    positions, box, walls = bed(n)
    n = len(positions)
    before_model = settle_memory()
    model, h = thermal_model_for(walls, n, modes)
    base = settle_memory()  # the frame, the model, the wall index and the enthalpies are in
    model_bytes = base - before_model - h.nbytes
    # Two frames a tenth of a diameter apart, alternated like consecutive frames of a run, so no
    # step finds the previous step's sorted arrays in cache.
    moved = positions + np.random.default_rng(2).uniform(-0.1, 0.1, positions.shape) * 2 * RADIUS
    moved[:, 2] %= box[1][2]
    frames = (positions, moved)
    rates = step(model, positions, box, h)[0]  # no step keeps the last frame alive, as in a run
    start = time.perf_counter()
    for k in range(repeats):
        rates = step(model, frames[(k + 1) % 2], box, h, rates)[0]
    seconds = (time.perf_counter() - start) / repeats
    # Resident per particle beyond the frame: the state (enthalpy) and the peak of one step
    # (the second frame array of this benchmark is counted too, a pessimistic 24 B).
    per_particle = (rss_bytes("VmHWM") - base + h.nbytes) / n
    rate = n / seconds
    print(
        f"N = {n:>9,d}  elements {len(walls.area):>7,d}  threads {numba.get_num_threads()}  "
        f"{seconds * 1e3:9.1f} ms/step  {rate:10.3g} particle-steps/s  {seconds / n * 1e9:7.1f} ns/particle  "
        f"{per_particle:6.0f} B/particle (+ {model_bytes / n:.0f} B/particle of tables and wall index)",
        flush=True,
    )
    return rate


def measure_reference(n: int) -> float:
    positions, walls, model, box, h = setup(n)
    # The reference has no periodic images; time it as is (the count of pairs differs by ~1%).
    T = model.enthalpy.temperature(h)
    start = time.perf_counter()
    reference.heat_rates(model, positions, T, walls)
    seconds = time.perf_counter() - start
    rate = len(positions) / seconds
    print(f"N = {len(positions):>9,d}  all-pairs numpy reference  {seconds:9.1f} s/step  {rate:10.3g} particle-steps/s", flush=True)
    return rate


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, action="append", help="particle count (repeatable); default 1e4, 1e5, 1e6")
    parser.add_argument("--repeats", type=int, default=0, help="steps timed per size (default: ~20 s worth)")
    parser.add_argument("--no-reference", action="store_true", help="skip the all-pairs reference at N = 1e4")
    parser.add_argument("--modes", choices=sorted(MODE_SETS), default="all", help="heat-transfer modes (default: all six)")
    args = parser.parse_args(argv)
    sizes = args.n or [10_000, 100_000, 1_000_000]
    rate = 0.0
    for n in sizes:
        repeats = args.repeats or max(2, int(2e7 // n))
        rate = measure(n, repeats, args.modes)
    if not args.n and not args.no_reference:
        measure_reference(10_000)
    print(f"particle-steps/s: {rate:.4g}")


if __name__ == "__main__":
    main()
