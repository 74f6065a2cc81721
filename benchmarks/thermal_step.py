"""Thermal-stage throughput: particle-steps per second and memory per particle, all six modes.

Dense beds (solid fraction 0.6, 1 mm particles) in a periodic tube with a faceted wall at a fixed
temperature; radiation cutoff 7 radii. One "particle-step" is one particle advanced by one frame:
the frame's cell list and wall contacts plus one evaluation of every enabled mode.

    python benchmarks/thermal_step.py            # N = 1e4, 1e5, 1e6 and the all-pairs reference at 1e4
    python benchmarks/thermal_step.py --n 100000 # one size
    python benchmarks/thermal_step.py --modes conduction   # the four conduction modes only
    python benchmarks/thermal_step.py --shells 5 10 20      # resolved particles against lumped
    python benchmarks/thermal_step.py --network --n 100000  # the network's conductance pass
    python benchmarks/thermal_step.py --tiny     # N = 3,000, two steps, no reference (the tests)

The last line printed is ``particle-steps/s: VALUE`` (for the last size run); with ``--shells``,
``resolved/lumped at n = 10: VALUE`` (time per particle-step, or the last shell count given); with
``--network``, ``network pass ms: VALUE`` (the median pass without slopes, last size).

``--network`` times the conductance pass of :mod:`dpht.thermal.network` on the bed's frame (the
pairs listed once, as the implicit and multirate integrators and the screening do): every pair's
and wall contact's conductance at the bed's temperatures, without slopes (Picard, the screening)
and with them (Newton), the two alternated pass by pass; it reports the median of each, wall and
CPU time (of all threads: on a loaded machine, and with ``NUMBA_NUM_THREADS=1``, the steadier).

``--shells`` (intra-particle conduction, :mod:`dpht.thermal.intraparticle`) times the lumped step
and the resolved step with each shell count on the same bed and frames, interleaved step by step
(A/B paired, so the machine's drift cancels), and reports the median time per particle-step, the
extra time over lumped and the ratio. The step (1e-4 s) needs no sub-steps for either model.
"""

from __future__ import annotations

import argparse
import ctypes
import dataclasses
import gc
import statistics
import time
from pathlib import Path

import numba
import numpy as np

from dpht.thermal import integrate, model as thermal_model, network
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


def step(model, positions, box, h, rates=None, shells=None):
    """One thermal step as the thermal stage takes it: frame preparation (cell list, wall
    distances) and one evaluation of every mode (and the shells' implicit step when resolved).
    Returns the work arrays and the frame."""
    frame = integrate.prepare_frame(model, positions, *box)
    if rates is None or rates.q.size != frame.particles.size:
        rates = integrate.Rates.for_frame(model, frame)
    report = integrate.advance(model, frame, h, 1e-4, rates, shells=shells)
    if report.substeps != 1:
        raise RuntimeError(f"the benchmark step took {report.substeps} sub-steps: the comparison would not be per step")
    return rates, frame


def measure_shells(n: int, repeats: int, counts, modes="all") -> float:
    """Lumped against resolved steps on one bed, interleaved (module docstring); returns the ratio
    of the last shell count."""
    positions, box, walls = bed(n)
    n = len(positions)
    lumped, h0 = thermal_model_for(walls, n, modes)
    variants = {"lumped": (lumped, None)}
    for count in counts:
        model = thermal_model.resolved(dataclasses.replace(lumped, shell_count=count))
        variants[f"n = {count}"] = (model, np.repeat(h0[:, None], count, axis=1))
    moved = positions + np.random.default_rng(2).uniform(-0.1, 0.1, positions.shape) * 2 * RADIUS
    moved[:, 2] %= box[1][2]
    frames = (positions, moved)
    state = {name: [h0.copy(), None] for name in variants}
    for name, (model, shells) in variants.items():  # compile, and size the work arrays
        state[name][1] = step(model, positions, box, state[name][0], None, shells)[0]
    times = {name: [] for name in variants}
    for k in range(repeats):
        for name, (model, shells) in variants.items():
            start = time.perf_counter()
            state[name][1] = step(model, frames[(k + 1) % 2], box, state[name][0], state[name][1], shells)[0]
            times[name].append(time.perf_counter() - start)
    base = statistics.median(times["lumped"]) / n
    print(f"N = {n:,d}  threads {numba.get_num_threads()}  {repeats} interleaved steps per variant, median per particle-step:")
    ratio = 1.0
    for name, samples in times.items():
        per = statistics.median(samples) / n
        ratio = per / base
        print(f"  {name:<8s} {per * 1e9:8.1f} ns   extra {(per - base) * 1e9:7.1f} ns   ratio {ratio:5.2f}", flush=True)
    return ratio


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


def measure_network(n: int, repeats: int, modes="all") -> float:
    """The network's conductance pass on the bed's frame (module docstring); returns the median
    time (s) without slopes."""
    positions, walls, model, box, h = setup(n, modes)
    frame = integrate.prepare_frame(model, positions, *box)
    net = network.assemble(model, frame)
    T = integrate.temperatures(model, h, frame.particles)[0]
    variants = {"without slopes": None, "with slopes": network.Slopes.of(net)}
    times = {name: ([], []) for name in variants}  # wall and CPU (all threads) seconds
    for k in range(repeats + 1):  # the first pass of each compiles or loads its kernel
        for name, slopes in variants.items():
            start, cpu = time.perf_counter(), time.process_time()
            network.conductances(model, net, T, slopes)
            if k:
                times[name][0].append(time.perf_counter() - start)
                times[name][1].append(time.process_time() - cpu)
    print(f"N = {frame.particles.size:>9,d}  pairs {net.pairs.first.size:>11,d}  contacts {net.contacts.particle.size:>7,d}  "
          f"threads {numba.get_num_threads()}  " + "  ".join(f"{name} {statistics.median(wall) * 1e3:8.2f} ms "
                                                          f"(CPU {statistics.median(cpu) * 1e3:.2f} ms)"
                                                          for name, (wall, cpu) in times.items()), flush=True)  # fmt: skip
    return statistics.median(times["without slopes"][0])


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
    parser.add_argument("--shells", type=int, nargs="+", help="resolved particles with these shell counts against lumped")
    parser.add_argument("--network", action="store_true", help="time the network's conductance pass instead of the step")
    parser.add_argument("--tiny", action="store_true", help="N = 3,000, two steps, no reference (the tests)")
    args = parser.parse_args(argv)
    if args.tiny:
        args.n, args.repeats, args.no_reference = [3000], 2, True
    if args.shells:
        n = (args.n or [100_000])[-1]
        ratio = measure_shells(n, args.repeats or max(5, int(2e6 // n)), args.shells, args.modes)
        print(f"resolved/lumped at n = {args.shells[-1]}: {ratio:.3g}")
        return
    sizes = args.n or [10_000, 100_000, 1_000_000]
    if args.network:
        seconds = 0.0
        for n in sizes:
            seconds = measure_network(n, args.repeats or max(2, int(1e7 // n)), args.modes)
        print(f"network pass ms: {seconds * 1e3:.4g}")
        return
    rate = 0.0
    for n in sizes:
        repeats = args.repeats or max(2, int(2e7 // n))
        rate = measure(n, repeats, args.modes)
    if not args.n and not args.no_reference:
        measure_reference(10_000)
    print(f"particle-steps/s: {rate:.4g}")


if __name__ == "__main__":
    main()
