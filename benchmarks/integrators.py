"""Cost of the time integrators (dpht.thermal.integrators) on a stiff frozen bed and on the default scene.

1. Stiff scene: a frozen bed of 1 mm particles (a jittered simple cubic lattice, ``--layers`` layers
   between a 1,000 K wall below and a 300 K wall above, all six modes, radiation cutoff 7 radii), from
   300 K for 3,600 s. The converged solution at 3,600 s is the bed's steady state (its slowest mode
   decays with a time constant of ~10-50 s; the benchmark measures it and checks that 3,600 s is more
   than 30 of them): reached by implicit backward Euler with 1e6 s steps until the correction is
   below 1e-9 K. Implicit runs 3,600 s in ``--implicit-steps`` equal steps and must end within 1e-3
   of the temperature range of that solution. Explicit sub-stepping at its stability limit is timed
   over a short horizon (``--horizon`` and half of it, to check that its cost is linear in the
   simulated time), and from the converged state, and scaled to 3,600 s by its step count: the
   sub-steps it needs at the initial
   state for the first five time constants (radiation stiffens as the bed heats: a lower bound
   there) and those it needs at the converged state for the rest (the bed is then within 1% of it);
   the cost per sub-step is measured on both.
2. Default scene: the dense tube bed of the default run (2,804 particles, all six modes, a 1,073 K wall,
   0.01 s frames), ``explicit`` against ``auto``, frames alternated between two positions as in a
   run, A/B interleaved in rounds within this process.

    python benchmarks/integrators.py                 # N = 1e5 (100 x 100 x 10)
    python benchmarks/integrators.py --side 30       # a smaller bed for a quick look
    python benchmarks/integrators.py --tiny          # 6 x 6 x 3 and a 400-particle tube, one round (the tests)

The last line printed is ``implicit speed-up on stiff scene: VALUE``.
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

from dpht.thermal import integrate, integrators
from dpht.thermal.modes import NAMES
from dpht.verification import scenes

R = scenes.RADIUS
T_HOT, T_COLD, HORIZON = 1000.0, 300.0, 3600.0


def stiff_bed(side: int, layers: int):
    positions, height = scenes.lattice_bed((side, side, layers), seed=1)
    walls = scenes.slab_walls(height, half=side * 2 * R, n=8)
    s = scenes.spec(list(NAMES), walls={"hot": {"temperature": T_HOT}, "cold": {"temperature": T_COLD}},
                    initial_temperature=T_COLD, inlet_temperature=T_COLD, radiation_cutoff=7.0)  # fmt: skip
    model = scenes.build_model(s, walls, scenes.synthetic_rdf())
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    return model, frame


def timed(integrator, frame, h, dt, steps):
    start = time.perf_counter()
    reports = [integrator.advance(frame, h, dt) for _ in range(steps)]
    return time.perf_counter() - start, reports


def stiff(side: int, layers: int, implicit_steps: int, horizon: float, tolerance: float) -> float:
    model, frame = stiff_bed(side, layers)
    n = frame.particles.size
    h0 = model.enthalpy.enthalpy(np.full(n, T_COLD))
    options = {"scheme": "backward_euler", "tolerance": tolerance, "preconditioner": "amg"}
    # The converged solution: the steady state.
    h_ref = h0.copy()
    reference = integrators.create("implicit", model, {"implicit": {**options, "tolerance": 1e-9}})
    for _ in range(30):
        before = model.enthalpy.temperature(h_ref)
        reference.advance(frame, h_ref, 1e6)
        change = np.max(np.abs(model.enthalpy.temperature(h_ref) - before))
        if change < 1e-9:
            break
    T_ref = model.enthalpy.temperature(h_ref)
    # Slowest decay: two implicit steps of 20 s from the initial state, ratio of distances to steady.
    h = h0.copy()
    probe = integrators.create("implicit", model, {"implicit": options})
    distances = [np.max(np.abs(model.enthalpy.temperature(h) - T_ref))]
    for _ in range(6):
        probe.advance(frame, h, 20.0)
        distances.append(np.max(np.abs(model.enthalpy.temperature(h) - T_ref)))
    factor = distances[-1] / distances[-2]  # backward Euler: 1 / (1 + 20 s / tau)
    tau = 20.0 / (1.0 / factor - 1.0) if 0 < factor < 1 else math.inf
    print(f"stiff bed: {n:,d} particles, {probe.net.pairs.first.size:,d} pairs, {probe.net.contacts.particle.size:,d} wall contacts; "
          f"slowest time constant ~{tau:.3g} s ({HORIZON / tau:.0f} of them in {HORIZON:.0f} s)", flush=True)  # fmt: skip
    # Implicit over the whole horizon.
    h = h0.copy()
    implicit = integrators.create("implicit", model, {"implicit": options})
    seconds_implicit, _ = timed(implicit, frame, h, HORIZON / implicit_steps, implicit_steps)
    error = np.max(np.abs(model.enthalpy.temperature(h) - T_ref)) / (T_HOT - T_COLD)
    print(f"implicit: {implicit_steps} steps of {HORIZON / implicit_steps:.0f} s in {seconds_implicit:.2f} s "
          f"({implicit.stats}); max |T - converged| / (T_hot - T_cold) = {error:.2e}", flush=True)  # fmt: skip
    # Explicit over a short horizon and half of it from the start (linearity), and over the short
    # horizon from the converged state (its sub-steps when the bed is hot), scaled by sub-step counts.
    explicit = integrators.create("explicit", model)
    seconds_half, reports_half = timed(explicit, frame, h0.copy(), 1.0, max(1, round(horizon / 2)))
    seconds_start, reports_start = timed(explicit, frame, h0.copy(), 1.0, max(1, round(horizon)))
    seconds_end, reports_end = timed(explicit, frame, h_ref.copy(), 1.0, max(1, round(horizon)))
    sub_half, sub_start, sub_end = (sum(r.substeps for r in reports) for reports in (reports_half, reports_start, reports_end))
    per_substep = (seconds_start + seconds_end) / (sub_start + sub_end)
    warm = min(5 * tau, HORIZON)  # within 1% of the steady state after 5 time constants
    needed = sub_start / horizon * warm + sub_end / horizon * (HORIZON - warm)
    seconds_explicit = per_substep * needed
    print(f"explicit from the start: {sub_start} sub-steps in {seconds_start:.2f} s over {horizon:.0f} s, {sub_half} in "
          f"{seconds_half:.2f} s over half of it (time ratio {seconds_start / seconds_half:.2f}, sub-step ratio "
          f"{sub_start / sub_half:.2f}); from the converged state {sub_end} sub-steps in {seconds_end:.2f} s; "
          f"{per_substep * 1e3:.1f} ms per sub-step; {HORIZON:.0f} s = {warm:.0f} s at the starting rate + the rest at "
          f"the hot rate = {needed:,.0f} sub-steps, {seconds_explicit:.0f} s", flush=True)  # fmt: skip
    print(f"implicit / explicit time for {HORIZON:.0f} s: {seconds_implicit:.1f} s / {seconds_explicit:.0f} s", flush=True)
    if error > 1e-3:
        print(f"implicit did NOT reach 1e-3 of the converged solution ({error:.2e})")
    return seconds_explicit / seconds_implicit


def default_scene(rounds: int, frames: int, particles: int = 2804) -> float:
    positions, tube_radius, length = scenes.dense_tube_bed(particles, solid_fraction=0.6)
    box = (np.array([-tube_radius, -tube_radius, 0.0]), np.array([tube_radius, tube_radius, length]), (False, False, True))
    walls = scenes.tube_walls(tube_radius, length, element=2 * R)
    s = scenes.spec(list(NAMES), walls={"hot": {"temperature": 1073.15}}, initial_temperature=303.15,
                    inlet_temperature=303.15)  # fmt: skip
    model = scenes.build_model(s, walls, scenes.synthetic_rdf())
    moved = positions + np.random.default_rng(2).uniform(-0.05, 0.05, positions.shape) * 2 * R
    moved[:, 2] %= length
    h0 = model.enthalpy.enthalpy(np.full(len(positions), 303.15))
    totals = {"explicit": 0.0, "auto": 0.0}
    chosen = {}
    for r in range(rounds + 1):  # round 0 compiles and warms up
        for name in (("explicit", "auto") if r % 2 else ("auto", "explicit")):
            integrator = integrators.create(name, model)
            h = h0.copy()
            start = time.perf_counter()
            for k in range(frames):
                frame = integrate.prepare_frame(model, (positions, moved)[k % 2], *box)
                report = integrator.advance(frame, h, 0.01)
                chosen[report.integrator] = chosen.get(report.integrator, 0) + 1
            if r:
                totals[name] += time.perf_counter() - start
    ratio = totals["auto"] / totals["explicit"]
    print(f"default scene ({len(positions):,d} particles, {frames} frames x {rounds} rounds, threads {numba.get_num_threads()}): "
          f"explicit {totals['explicit'] / (rounds * frames) * 1e3:.2f} ms/frame, auto {totals['auto'] / (rounds * frames) * 1e3:.2f} "
          f"ms/frame; auto chose {chosen}", flush=True)  # fmt: skip
    print(f"auto / explicit on the default scene: {ratio:.3f}", flush=True)
    return ratio


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--side", type=int, default=100, help="particles per side of the stiff bed (default 100)")
    parser.add_argument("--layers", type=int, default=10, help="layers of the stiff bed (default 10)")
    parser.add_argument("--implicit-steps", type=int, default=2, help="implicit steps over 3,600 s (default 2)")
    parser.add_argument("--horizon", type=float, default=20.0, help="s of explicit timing (default 20)")
    parser.add_argument("--tolerance", type=float, default=1e-2, help="K, implicit iteration tolerance (default 0.01)")
    parser.add_argument("--rounds", type=int, default=6, help="A/B rounds on the default scene")
    parser.add_argument("--tiny", action="store_true", help="6 x 6 x 3 bed, 400-particle tube, one round (the tests)")
    args = parser.parse_args(argv)
    if args.tiny:
        args.side, args.layers, args.horizon, args.rounds = 6, 3, 2.0, 1
    default_scene(args.rounds, 4 if args.tiny else 40, 400 if args.tiny else 2804)
    speedup = stiff(args.side, args.layers, args.implicit_steps, args.horizon, args.tolerance)
    print(f"implicit speed-up on stiff scene: {speedup:.4g}")


if __name__ == "__main__":
    main()
