"""Hard cases of the thermal integrators (issue: numerical stability), each run by every integrator.

Every case checks, for each registered integrator (:mod:`dpht.thermal.integrators`):

- no NaN or inf;
- the maximum principle (no sources): every temperature within [min, max] of the initial, inlet and
  wall temperatures, to 1e-6 K (TR-BDF2 is not run here: it does not keep it, see
  :mod:`dpht.thermal.implicit` and the tests);
- energy: per frame, particle energy change = wall heat, to 1e-12 relative (of the frame's largest
  particle energy change);
- agreement: the final temperatures of each integrator at the case's step against a converged
  reference (explicit at 1/64 of the step) within 5% of the temperature range (:data:`AGREEMENT`):
  the steps are far beyond the explicit limit, where a first-order scheme's transient error is a
  few per cent;
- convergence: the implicit (backward Euler) error against that reference at the step, half and a
  quarter of it falls by at least a factor 1.6 per halving (first order).

A case returns its worst check as a fraction of that check's tolerance (so it passes at <= 1) and
:func:`report` gives every number. The steady frozen bed compares with the direct Newton solution
of the bed's steady conductance network (:func:`dpht.verification.reference.steady_state`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dpht.closures.heat_capacity import specific_heat_at
from dpht.thermal import integrate, integrators, network
from dpht.thermal.modes import NAMES
from dpht.verification import reference, scenes
from dpht.verification.cases.thermal import two_sphere_conductance, two_sphere_gap
from dpht.verification.harness import case

CONDUCTION = ["pp_contact", "pw_contact", "pfp", "pfw"]
RADIATION = ["pp_radiation", "pw_radiation"]
UNIT = "of tolerance"
BOUND_SLACK = 1e-6  # K
ENERGY_TOLERANCE = 1e-12  # relative, per frame
AGREEMENT = 0.05  # of the temperature range
# Integrators run by every case, with the implicit scheme that keeps the maximum principle.
RUNS = {name: {"integrator": name, "implicit": {"scheme": "backward_euler"}} for name in integrators.NAMES}


@dataclass
class Run:
    T: np.ndarray  # K, final, positions' order
    energy_error: float  # largest relative per-frame error
    finite: bool
    low: float  # K, lowest temperature seen
    high: float


@dataclass
class Outcome:
    checks: list = field(default_factory=list)  # (name, value, tolerance)

    def check(self, name: str, value: float, tolerance: float) -> None:
        self.checks.append((name, float(value), float(tolerance)))

    @property
    def worst(self) -> float:
        return max((v / t if t > 0 else (0.0 if v <= 0 else math.inf) for _, v, t in self.checks), default=math.inf)

    def lines(self) -> list[str]:
        return [f"{name:<44s} {value:11.4g}  tolerance {tol:9.3g}" for name, value, tol in self.checks]


def run(model, positions, h0, dt: float, steps: int, thermal: dict, box=None) -> Run:
    """``steps`` frames of ``dt`` on fixed ``positions`` with the integrator of ``thermal``."""
    lo, hi, periodic = (None, None, (False, False, False)) if box is None else box
    frame = integrate.prepare_frame(model, positions, lo, hi, periodic)
    integrator = integrators.create(thermal["integrator"], model, thermal)
    h = h0.copy()
    error, low, high = 0.0, math.inf, -math.inf
    with network.threads_for(frame.particles.size):  # these beds are tiny: one thread is faster
        for _ in range(steps):
            h_before = h.copy()
            report = integrator.advance(frame, h, dt)
            change = model.mass * (math.fsum(h) - math.fsum(h_before))
            wall = dt * math.fsum(report.element_heat.ravel())
            # relative to the frame's gross exchange: wall heat in and out, particle energy up and down
            scale = max(dt * float(np.abs(report.element_heat).sum()), model.mass * float(np.abs(h - h_before).sum()), 1e-300)
            error = max(error, abs(change - wall) / scale)
            T = model.enthalpy.temperature(h)
            low, high = min(low, float(T.min(initial=math.inf))), max(high, float(T.max(initial=-math.inf)))
    return Run(model.enthalpy.temperature(h), error, bool(np.all(np.isfinite(h))), low, high)


def hard_case(model, positions, T0, dt, steps, bounds, box=None, reference_step=None) -> Outcome:
    """Run every integrator and the checks of the module docstring."""
    out = Outcome()
    agreement = AGREEMENT * (bounds[1] - bounds[0])
    h0 = model.enthalpy.enthalpy(T0)
    fine = reference_step or dt / 64
    n_fine = max(1, round(dt / fine))
    ref = run(model, positions, h0, dt / n_fine, steps * n_fine, RUNS["explicit"], box)
    for name, thermal in RUNS.items():
        r = run(model, positions, h0, dt, steps, thermal, box)
        out.check(f"{name}: non-finite", 0.0 if r.finite else 1.0, 0.0)
        out.check(f"{name}: below/above bounds (K)", max(bounds[0] - r.low, r.high - bounds[1], 0.0), BOUND_SLACK)
        out.check(f"{name}: energy (relative per frame)", r.energy_error, ENERGY_TOLERANCE)
        out.check(f"{name}: max |T - converged| (K)", np.max(np.abs(r.T - ref.T), initial=0.0), agreement)
    errors = [np.max(np.abs(run(model, positions, h0, dt / k, steps * k, RUNS["implicit"], box).T - ref.T), initial=0.0)
              for k in (1, 2, 4)]  # fmt: skip
    if errors[0] > 1e-9:  # a case whose answer does not depend on the step has nothing to converge
        out.check("implicit: 1 / (error reduction per halving)", max(errors[1] / errors[0], errors[2] / errors[1]), 1 / 1.6)
    return out


def _walled(modes, walls_T, *, radius=scenes.RADIUS, shape=(5, 5, 4), initial=300.0, spacing=1.98, seed=0, **particles):
    """A lattice bed between two Dirichlet planes (z = 0 at ``walls_T[0]``, the top at
    ``walls_T[1]``, None: adiabatic)."""
    positions, height = scenes.lattice_bed(shape, radius=radius, spacing=spacing, seed=seed)
    conditions = {z: ("adiabatic" if T is None else {"temperature": T}) for z, T in zip(("hot", "cold"), walls_T)}
    temps = [initial, *(T for T in walls_T if T is not None)]
    s = scenes.spec(modes, walls=conditions, initial_temperature=initial, inlet_temperature=initial)
    s["particles"].update(diameter=2 * radius, **particles)
    s["thermal"]["htc_table"]["temperature_range"] = [250.0, max(1400.0, max(temps) + 10)]
    walls = scenes.slab_walls(height, half=shape[0] * spacing * radius)
    model = scenes.build_model(s, walls, scenes.synthetic_rdf() if set(modes) & set(RADIATION) else None)
    return model, positions, walls, (min(temps), max(temps))


def _explicit_step(model, positions) -> float:
    """The explicit stability step (s) of the bed at its initial temperatures."""
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    rates = integrate.Rates.for_frame(model, frame)
    integrate.evaluate(model, frame, np.full(frame.particles.size, model.initial_temperature), rates)
    return model.mass * model.enthalpy.cp_min / max(float(rates.g.max(initial=0.0)), 1e-300)


CASES = {}


def hard(name, description):
    """Register a hard case both with the verification harness and in :data:`CASES` (for the tests)."""

    def register(build):
        CASES[name] = build

        @case(name, description, UNIT)
        def verify():
            out = build()
            for line in out.lines():  # every number behind the one the harness prints
                print("    " + line)
            return out.worst, 1.0

        return build

    return register


@hard("stability_fine_powder", "50 um particles at a 0.02 s step (4.9 explicit limits): bounds, energy, agreement")
def fine_powder() -> Outcome:
    model, positions, _, bounds = _walled(CONDUCTION, (600.0, None), radius=25e-6)
    out = hard_case(model, positions, np.full(len(positions), 300.0), 0.02, 5, bounds)
    out.check("explicit limit / 0.02 s (the step is >= 4 limits)", _explicit_step(model, positions) / 0.02, 0.25)
    return out


@hard("stability_metal_particles", "k_p = 50 W/(m K): bounds, energy, agreement")
def metal() -> Outcome:
    model, positions, _, bounds = _walled(CONDUCTION, (600.0, 300.0), conductivity=50.0)
    return hard_case(model, positions, np.full(len(positions), 300.0), 2.0, 4, bounds)


@hard("stability_polymer_particles", "k_p = 0.1 W/(m K): bounds, energy, agreement")
def polymer() -> Outcome:
    model, positions, _, bounds = _walled(CONDUCTION, (600.0, 300.0), conductivity=0.1)
    return hard_case(model, positions, np.full(len(positions), 300.0), 2.0, 4, bounds)


def _conductance_sums(model, positions, T: float) -> float:
    """Sum over particles of their conductance sums (W/K) at the uniform temperature ``T`` (K)."""
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    rates = integrate.Rates.for_frame(model, frame)
    integrate.evaluate(model, frame, np.full(frame.particles.size, T), rates)
    return float(rates.g.sum())


@hard("stability_radiation_1300K", "a 1,100 K bed under a 1,300 K wall, radiation dominant (> 1/2 of the conductances): "
                                   "bounds, energy, agreement")  # fmt: skip
def radiation_bed() -> Outcome:
    model, positions, walls, bounds = _walled(list(NAMES), (1300.0, None), initial=1100.0)
    out = hard_case(model, positions, np.full(len(positions), 1100.0), 0.5, 4, bounds)
    radiative = _walled(RADIATION, (1300.0, None), initial=1100.0)[0]
    share = _conductance_sums(radiative, positions, 1200.0) / _conductance_sums(model, positions, 1200.0)
    out.check("1 - radiation's share of the conductances at 1,200 K", 1.0 - share, 0.5)
    return out


@hard("stability_slab_contrast", "two slabs at 300 K and 1,800 K (PP contact and radiation, no walls): bounds, energy, agreement")
def slab_contrast() -> Outcome:
    positions, _ = scenes.lattice_bed((4, 4, 4))
    s = scenes.spec(["pp_contact", "pp_radiation"], walls={}, initial_temperature=300.0, inlet_temperature=1800.0)
    model = scenes.build_model(s, None, scenes.synthetic_rdf())
    T0 = np.where(positions[:, 2] > np.median(positions[:, 2]), 1800.0, 300.0)
    return hard_case(model, positions, T0, 0.5, 3, (300.0, 1800.0))


@hard("stability_deep_overlaps", "centre distances below 1.6 radii and particles through the wall: finite, bounded, conserved")
def deep_overlaps() -> Outcome:
    model, positions, _, bounds = _walled(list(NAMES), (700.0, None), spacing=1.5, shape=(4, 4, 3))
    positions = positions - [0.0, 0.0, 0.9 * scenes.RADIUS]  # the lowest layer's centres 0.35 R from (or through) z = 0
    positions[::7, 2] = -0.2 * scenes.RADIUS  # some centres behind the wall plane
    return hard_case(model, positions, np.full(len(positions), 300.0), 0.5, 4, bounds)


@hard("stability_few_particles", "a single particle, two particles, and isolated particles: two-sphere backward Euler exact")
def few_particles() -> Outcome:
    out = Outcome()
    s = scenes.spec(["pp_contact"], walls={}, initial_temperature=300.0, inlet_temperature=500.0)
    model = scenes.build_model(s)
    single = run(model, np.zeros((1, 3)), model.enthalpy.enthalpy(np.array([400.0])), 1.0, 3, RUNS["implicit"])
    out.check("single particle: change (K)", abs(single.T[0] - 400.0), 1e-12)
    two = np.array([[0.0, 0.0, 0.0], [1.98 * scenes.RADIUS, 0.0, 0.0]])
    G = two_sphere_conductance(s, 1.98 * scenes.RADIUS)
    C = model.mass * s["particles"]["specific_heat"]
    dt = 5.0 * C / G  # 5 times the pair's explicit limit
    for name, thermal in RUNS.items():
        r = run(model, two, model.enthalpy.enthalpy(np.array([300.0, 500.0])), dt, 4, thermal)
        out.check(f"two particles, {name}: mean drift (K)", abs(r.T.mean() - 400.0), 1e-9)
        out.check(f"two particles, {name}: bounds (K)", max(300.0 - r.low, r.high - 500.0, 0.0), BOUND_SLACK)
    be = run(model, two, model.enthalpy.enthalpy(np.array([300.0, 500.0])), dt, 4, RUNS["implicit"])
    exact = two_sphere_gap(200.0, G, C, dt, 4, implicit=True)
    out.check("two particles, backward Euler gap vs (1 + 2 G dt/C)^-n", abs((be.T[1] - be.T[0]) / exact - 1.0), 1e-9)
    isolated = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])
    for name, thermal in RUNS.items():
        r = run(model, isolated, model.enthalpy.enthalpy(np.array([300.0, 400.0, 500.0])), 10.0, 2, thermal)
        out.check(f"isolated particles, {name}: change (K)", np.max(np.abs(r.T - [300.0, 400.0, 500.0])), 1e-9)
    return out


@hard("stability_out_of_range_lookups", "overlaps below the PFP/PFW tables' first distance (no DEM softening): "
                                       "clamped, counted as a brute-force search finds them, finite, bounded, conserved")  # fmt: skip
def out_of_range() -> Outcome:
    """Temperatures outside the tables are refused before work starts (the tables must cover the
    scene's temperatures, :func:`dpht.thermal.model.build`); the stage counts any particle that
    still leaves them (a scheme without a maximum principle can), tested in the test suite."""
    E_real = scenes.spec()["particles"]["youngs_modulus_real"]
    model, positions, walls, bounds = _walled(CONDUCTION, (1000.0, None), spacing=1.7, shape=(4, 4, 3), youngs_modulus_dem=E_real)
    positions = positions - [0.0, 0.0, 0.7 * scenes.RADIUS]  # the lowest layer 0.3 R from the wall
    pairs = int(np.count_nonzero(reference.all_pairs(model, positions)[2] < model.tables["pfp"].x0))
    contacts = int(np.count_nonzero(reference.wall_contacts(model, positions, walls)[2] < model.tables["pfw"].x0))
    out = Outcome()
    out.check(f"brute force: {pairs} pairs, {contacts} contacts below the tables (>= 1 each)", float(min(pairs, contacts) < 1), 0.0)
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    for name, thermal in RUNS.items():
        h = model.enthalpy.enthalpy(np.full(len(positions), 300.0))
        clamped = integrators.create(name, model, thermal).advance(frame, h, 1.0).stats["clamped"]
        out.check(f"{name}: |PFP clamped - brute force|", abs(clamped["pfp_distance"] - pairs), 0.0)
        out.check(f"{name}: |PFW clamped - brute force|", abs(clamped["pfw_distance"] - contacts), 0.0)
    T0 = np.full(len(positions), 300.0)
    out.checks += hard_case(model, positions, T0, 2.0, 4, bounds).checks
    return out


def convergence_orders(steps=(2, 4, 8)) -> dict:
    """Measured order of every integrator (and TR-BDF2) over 1 s on a wall-heated cluster with
    temperature-dependent c_p, from the errors at 1 s / steps against TR-BDF2 at 1/256 s:
    ``log2(e(1 s / 4) / e(1 s / 8))``, and the errors."""
    s = scenes.spec(CONDUCTION, walls={"hot": {"temperature": 700.0}})
    s["particles"]["specific_heat"] = "271.5 * T_C**0.1719"
    model = scenes.build_model(s, scenes.plane_walls())
    positions = scenes.random_cluster(n=200, seed=2)
    h0 = model.enthalpy.enthalpy(np.random.default_rng(3).uniform(300, 500, len(positions)))
    t_end = 1.0  # below the explicit limit (~1.3 s), so explicit takes the frame step itself
    runs = {**RUNS, "tr_bdf2": {"integrator": "implicit", "implicit": {"scheme": "tr_bdf2"}}}
    ref = run(model, positions, h0, t_end / 256, 256, runs["tr_bdf2"]).T
    out = {}
    for name, thermal in runs.items():
        errors = [float(np.max(np.abs(run(model, positions, h0, t_end / n, n, thermal).T - ref))) for n in steps]
        out[name] = {"order": math.log2(errors[-2] / errors[-1]), "errors": errors, "range": float(ref.max() - ref.min())}
    return out


def stiff_chain():
    """A lattice with gas gaps holding a chain of five deeply overlapping metal particles (no DEM
    softening) above a 600 K wall: (model, positions, h0). A few particles are stiff."""
    positions, _ = scenes.lattice_bed((8, 8, 6), spacing=2.1, jitter=0.0)
    positions[:5] = positions[0] + np.arange(5)[:, None] * [0.8 * scenes.RADIUS, 0.0, 0.0]
    s = scenes.spec(CONDUCTION, walls={"hot": {"temperature": 600.0}})
    s["particles"].update(conductivity=50.0, youngs_modulus_dem=s["particles"]["youngs_modulus_real"])
    model = scenes.build_model(s, scenes.plane_walls())
    return model, positions, model.enthalpy.enthalpy(np.random.default_rng(1).uniform(300, 500, len(positions)))


def multirate_order(steps=(4, 8, 16)) -> tuple[float, list, int]:
    """Multirate's measured order where its levels differ (:func:`stiff_chain`), frames of 0.8 s /
    steps against explicit at 0.8 s / 4096: (order from the last two, errors in K, the finest level
    at the smallest step)."""
    model, positions, h0 = stiff_chain()
    ref = run(model, positions, h0, 0.8 / 4096, 4096, RUNS["explicit"]).T
    errors = [float(np.max(np.abs(run(model, positions, h0, 0.8 / n, n, RUNS["multirate"]).T - ref))) for n in steps]
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    finest = integrators.create("multirate", model).advance(frame, h0.copy(), 0.8 / steps[-1]).stats["finest_level"]
    return math.log2(errors[-2] / errors[-1]), errors, int(finest)


@hard("stability_convergence_orders", "measured order of every integrator (TR-BDF2 too) against TR-BDF2 at 1/256 of "
                                      "the frame: 1 within 0.3, TR-BDF2 2 within 0.4, all within 5% at 1/8; "
                                      "multirate's where its levels differ")  # fmt: skip
def orders() -> Outcome:
    out = Outcome()
    for name, measured in convergence_orders().items():
        expected = 2 if name == "tr_bdf2" else integrators.BY_NAME[name].order  # the registry's: implicit is backward Euler
        out.check(f"{name}: |order {measured['order']:.3f} - {expected}|", abs(measured["order"] - expected), 0.4 if expected == 2 else 0.3)
        out.check(f"{name}: error at 1/8 s / range", measured["errors"][-1] / measured["range"], AGREEMENT)
    order, _, finest = multirate_order()
    out.check(f"multirate, finest level {finest}: |order {order:.3f} - 1|", abs(order - 1.0), 0.3)
    out.check("multirate: levels short of 3 at the smallest step", max(3 - finest, 0), 0.0)
    return out


@hard("stability_variable_cp", "c_p varying by a factor of two across the scene (300-900 K): bounds, energy, agreement")
def variable_cp() -> Outcome:
    model, positions, _, bounds = _walled(CONDUCTION, (900.0, 300.0), specific_heat="500.0 + 500.0 * (T - 300.0) / 600.0")
    out = hard_case(model, positions, np.full(len(positions), 300.0), 2.0, 4, bounds)
    cp = [specific_heat_at(T, model.enthalpy.T0, model.enthalpy.dT, model.enthalpy.h) for T in (300.0, 900.0)]
    out.check("c_p(900 K) / c_p(300 K) - 2", abs(cp[1] / cp[0] - 2.0), 1e-3)
    return out


@hard("frozen_bed_steady_state", "1 mm bed, all modes, 1 s steps for 3,600 s between a 1,000 K and a 300 K wall "
                                 "= direct Newton steady solution (K)")  # fmt: skip
def frozen_steady() -> Outcome:
    """Explicit and implicit end on the steady state to 1e-6 K. Multirate's fixed point is the steady
    state only to first order in the step (pairs of different levels see the temperatures of
    different moments of the frame): from the steady state, it settles within 1% of the range at
    1 s, and at 0.5 s (where every particle is on level 0) no farther than explicit."""
    out = Outcome()
    model, positions, walls, bounds = _walled(list(NAMES), (1000.0, 300.0), shape=(4, 4, 4))
    steady, last = reference.steady_state(model, positions, walls, np.full(len(positions), 650.0))
    out.check("Newton reference: last correction (K)", last, 1e-9)
    h0 = model.enthalpy.enthalpy(np.full(len(positions), 300.0))
    for name in ("explicit", "implicit"):
        r = run(model, positions, h0, 1.0, 3600, RUNS[name])
        out.check(f"{name}: max |T - steady| (K)", np.max(np.abs(r.T - steady)), 1e-6)
        out.check(f"{name}: bounds (K)", max(bounds[0] - r.low, r.high - bounds[1], 0.0), BOUND_SLACK)
        out.check(f"{name}: energy (relative per frame)", r.energy_error, ENERGY_TOLERANCE)
    h_steady = model.enthalpy.enthalpy(steady)
    offsets = [np.max(np.abs(run(model, positions, h_steady, dt, round(200 / dt), RUNS["multirate"]).T - steady)) for dt in (1.0, 0.5)]
    out.check("multirate at 1 s: max |T - steady| / range", offsets[0] / (bounds[1] - bounds[0]), 0.01)
    out.check("multirate: offset(0.5 s) / offset(1 s) (first order)", offsets[1] / offsets[0], 0.6)
    return out
