"""Ray-tracing throughput: rays per second in packed beds (dpht.radiation.raytrace).

Beds: 4,096 spheres at solid fraction 0.45; 3,704 at 0.60 and the same packing tiled 3 x 3 x 3
(100,008 spheres; a tiled periodic packing is itself one), all fully periodic, emissivity 0.86,
4,096 emitters (or all) x 250 rays. The cost per ray should not depend on the bed size (uniform
grid walk): compare the two beds at 0.60. Best of three timings, after a warm-up that compiles the
kernels. Uses numba's default thread count (NUMBA_NUM_THREADS).

    python benchmarks/raytrace.py          # last line: "rays/s: VALUE" for the 4,096 bed
    python benchmarks/raytrace.py --tiny   # 512 and 400 spheres, 64 emitters x 50 rays (the tests)
"""

import argparse
import time

import numba
import numpy as np

from dpht.radiation.packing import pack
from dpht.radiation.raytrace import trace

EMISSIVITY = 0.86
# Beds: (spheres at 0.45, spheres at 0.60 tiled 3 x 3 x 3), emitters, rays per emitter.
SIZES = {"default": (4096, 3704, 4096, 250), "tiny": (512, 400, 64, 50)}


def rays_per_second(positions, box, emitters, rays):
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        result = trace(positions, 1.0, EMISSIVITY, rays, box=box, periodic=(True,) * 3, emitters=emitters, seed=1)
        best = min(best, time.perf_counter() - start)
    return rays * emitters.size / best, result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tiny", action="store_true", help="small beds, few rays (the tests)")
    n_small, n_cell, n_emitters, rays = SIZES["tiny" if parser.parse_args(argv).tiny else "default"]
    print(f"numba threads: {numba.get_num_threads()}")
    small = pack(n_small, 0.45, seed=1)
    trace(small.positions[:50], 1.0, EMISSIVITY, 10)  # compile (or load the cache)
    rate_small, result = rays_per_second(small.positions, small.box, np.arange(n_small), rays)
    self_absorbed = result.counts.diagonal().sum() / (rays * n_small)
    print(f"{n_small:,} spheres, phi 0.45: {rate_small:.3g} rays/s ({1e9 / rate_small:.0f} ns per ray, "
          f"self-absorption {self_absorbed:.4f}, lost {result.lost_counts.sum()})")  # fmt: skip

    cell = pack(n_cell, 0.60, seed=2)
    rate_cell, _ = rays_per_second(cell.positions, cell.box, np.arange(len(cell.positions)), rays)
    print(f"{len(cell.positions):,} spheres, phi 0.60: {rate_cell:.3g} rays/s ({1e9 / rate_cell:.0f} ns per ray)")
    length = cell.box[1] - cell.box[0]
    shifts = np.array([[a, b, c] for a in range(3) for b in range(3) for c in range(3)]) * length
    large = (cell.positions[None, :, :] + shifts[:, None, :]).reshape(-1, 3)
    box = np.array([cell.box[0], cell.box[0] + 3 * length])
    emitters = np.random.default_rng(0).choice(len(large), n_emitters, replace=False)
    rate_large, _ = rays_per_second(large, box, np.sort(emitters), rays)
    print(f"{len(large):,} spheres, phi 0.60: {rate_large:.3g} rays/s ({1e9 / rate_large:.0f} ns per ray; "
          f"cost per ray {rate_cell / rate_large:.2f} x that of the {len(cell.positions):,} bed)")  # fmt: skip
    print(f"rays/s: {rate_small:.4g}")


if __name__ == "__main__":
    main()
