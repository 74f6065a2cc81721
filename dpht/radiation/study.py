"""DPHT paper, Section 4 (Table 1, Fig. 9): four particle-particle radiation models in one static bed.

Scene: a random packing of equal spheres (:mod:`dpht.radiation.packing`) between two hard walls normal to x,
periodic along y and z (so the hot and cold slabs cannot see each other through a periodic
boundary), bulk solid fraction ``solid_fraction``. Particles with centre x > ``hot_x`` are held at
``hot_temperature``, those with x < ``cold_x`` at ``cold_temperature``; the ones between are free.
Radiation between particles is the only heat transfer.

Every model gives the heat into particle i (W) as

    q_i = eps A sigma [ (T_i^p + (M T^p)_i)^(4/p) - T_i^4 ]

with a sparse generator matrix M (zero row sums) and a power p:

* ``dba``: distance-based approximation, Eq. 25. M = D - diag(D 1), D_ij the tabulated RDF at the
  pair's centre distance and the bed's solid fraction (pairs closer than ``radiation_cutoff``
  radii), p = 4. The same tables and pairs as the production kernel (:mod:`dpht.thermal.kernels`).
* ``monte_carlo``: Eq. 25 with the RDF matrix of this very bed from ray tracing
  (:mod:`dpht.radiation.raytrace`), symmetrised, S = (D + D^T) / 2: M = S - diag(S 1), p = 4.
* ``krause``: Krause et al. (2017), Eq. 29 with Eq. 28: T_env^4 = mean of T_j^4 over the particles
  within ``environment_cutoff`` radii (centre to centre): M = W - I, W the row-averaging matrix, p = 4.
* ``musser``: Musser (2011), Eqs. 27-28: T_env = mean of T_j over the same neighbours: M = W - I, p = 1.

For symmetric M (dba, monte_carlo) the columns also sum to zero, so sum_i q_i = 0 for any
temperatures: energy is conserved pair by pair. W is not symmetric (each particle averages over
its own neighbour count), so Krause and Musser create or destroy heat.

Steady state of the free particles: q_i = 0 is linear in x = T^p, (M x)_i = 0 for free i, solved
directly (sparse LU) with the held particles as boundary values. Transient (Fig. 9): temperatures
start linear in x between the slabs and the free particles advance by explicit Euler steps,
dT_i/dt = q_i / (m c_p), with the held particles reset each step; the step is the conductance bound
of :mod:`dpht.thermal.integrate` (dt * sum_j G_ij <= m c_p, with G <= 4 eps A sigma T_hot^3 per unit of M),
which keeps every model's update a convex combination (maximum principle). For DBA the rates come
from the compiled production kernel (:func:`dpht.thermal.integrate.evaluate`).

Heat rates scale with the bed's y-z cross-section; rates per m^2 of it compare beds of different
widths.
"""

from __future__ import annotations

import csv
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from dpht.thermal import integrate, model as thermal_model, neighbors
from dpht.radiation import packing, raytrace
from dpht.closures import rdf
from dpht.closures.contact import STEFAN_BOLTZMANN
from dpht.errors import ConfigError, DPHTError

log = logging.getLogger("dpht")

HOT, FREE, COLD = 1, 0, -1
MODELS = ("musser", "krause", "dba", "monte_carlo")
LABELS = {"musser": "Musser", "krause": "Krause", "dba": "DBA", "monte_carlo": "Monte Carlo"}
# DPHT paper, Table 1 (17,563 particles; the Musser rate did not converge).
PAPER_TABLE_1 = {
    "musser": {"rate_W": None, "error": None, "generation_W": -0.404},
    "krause": {"rate_W": 0.432, "error": -0.153, "generation_W": -0.0048},
    "dba": {"rate_W": 0.515, "error": 0.016, "generation_W": 0.0},
    "monte_carlo": {"rate_W": 0.509, "error": None, "generation_W": 0.0},
}
PAPER_PARTICLES = 17_563

SPEC_KEYS = {  # key: (lower bound, strict) for numbers; the study's config section
    "particles": (8, False), "length": (0.0, True), "radius": (0.0, True), "emissivity": (0.0, True),
    "solid_fraction": (0.0, True), "hot_x": (None, False), "cold_x": (None, False),
    "hot_temperature": (0.0, True), "cold_temperature": (0.0, True), "radiation_cutoff": (2.0, True),
    "environment_cutoff": (2.0, True), "rays": (1, False), "batches": (1, False), "density": (0.0, True),
    "specific_heat": (0.0, True), "duration": (0.0, True), "seed": (0, False),
}  # fmt: skip
_INTEGER_KEYS = ("particles", "rays", "batches", "seed")


def check_spec(spec: dict, section: str = "radiation_study") -> dict:
    """The study's parameters, checked; raises ConfigError naming ``section.key``.

    Lengths in m, temperatures in K, cutoffs in radii, density kg/m^3, specific heat J/(kg K),
    duration s; ``rays`` per particle in total over ``batches`` independent traces.
    """
    missing = sorted(set(SPEC_KEYS) - set(spec))
    unknown = sorted(set(spec) - set(SPEC_KEYS))
    if missing or unknown:
        raise ConfigError(f"{section}: missing keys {missing}, unknown keys {unknown}")
    out = {}
    for key, (low, strict) in SPEC_KEYS.items():
        value = spec[key]
        integer = key in _INTEGER_KEYS
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and int(value) != value):
            raise ConfigError(f"{section}.{key}: expected {'an integer' if integer else 'a number'}, got {value!r}")
        if not math.isfinite(value) or (low is not None and (value <= low if strict else value < low)):
            raise ConfigError(f"{section}.{key}: expected {'>' if strict else '>='} {low}, got {value!r}")
        out[key] = int(value) if integer else float(value)
    if out["emissivity"] > 1.0:
        raise ConfigError(f"{section}.emissivity: expected <= 1, got {out['emissivity']}")
    if not out["cold_x"] < out["hot_x"]:
        raise ConfigError(f"{section}: cold_x ({out['cold_x']}) must be below hot_x ({out['hot_x']})")
    if not out["cold_temperature"] < out["hot_temperature"]:
        raise ConfigError(f"{section}: cold_temperature must be below hot_temperature")
    if out["rays"] % out["batches"]:
        raise ConfigError(f"{section}.rays ({out['rays']}) must be a multiple of batches ({out['batches']})")
    return out


# --------------------------------------------------------------------------------------------
# The bed


@dataclass(frozen=True)
class Bed:
    """A packed bed centred on x = 0, hard walls at box[:, 0], periodic along y and z."""

    positions: np.ndarray  # (N, 3) m
    radius: float  # m
    box: np.ndarray  # [[lo], [hi]] m
    region: np.ndarray  # (N,) HOT, FREE or COLD
    solid_fraction: float  # bulk, measured

    periodic = (False, True, True)  # a class constant, not a field

    @property
    def cross_section(self) -> float:
        """y-z area of the bed (m^2): heat rates per unit of it compare beds of different widths."""
        size = self.box[1] - self.box[0]
        return float(size[1] * size[2])

    def squared_distances(self, i, j) -> np.ndarray:
        """Squared centre distances (m^2) of pairs (i, j), minimum image along y and z."""
        gap = self.positions[i] - self.positions[j]
        size = self.box[1] - self.box[0]
        gap[:, 1:] -= size[1:] * np.round(gap[:, 1:] / size[1:])
        return np.einsum("ij,ij->i", gap, gap)

    def pairs(self, cutoff: float):
        """Pairs closer than ``cutoff`` (m), each once: ``(i, j)``."""
        cells = neighbors.build(self.positions, cutoff, box_lo=self.box[0], box_hi=self.box[1], periodic=self.periodic)
        return neighbors.pairs(cells, cutoff)


def make_bed(s: dict) -> Bed:
    """Pack ``s["particles"]`` spheres so that the bed is ``s["length"]`` long in x (the y-z
    cross-section square), and label the hot, free and cold regions."""
    R, n, length = s["radius"], s["particles"], s["length"]
    width = math.sqrt(n * packing.SPHERE_VOLUME * R**3 / (s["solid_fraction"] * length))
    widest = 3 * max(s["radiation_cutoff"], s["environment_cutoff"]) * R
    if width < widest:  # the periodic pair search needs three cutoffs
        raise ConfigError(
            f"radiation_study.particles: {n} particles in a bed {length} m long give a cross-section "
            f"{width:.4g} m wide; the periodic axes need at least {widest:.4g} m (3 cutoffs): use more particles"
        )
    pack = packing.pack(n, s["solid_fraction"], radius=R, aspect=(1.0, width / length, width / length),
                        wall_axis=0, seed=s["seed"])  # fmt: skip
    shift = np.array([0.5 * (pack.box[0, 0] + pack.box[1, 0]), 0.0, 0.0])
    positions = pack.positions - shift
    x = positions[:, 0]
    region = np.where(x > s["hot_x"], HOT, np.where(x < s["cold_x"], COLD, FREE)).astype(np.int8)
    for name, value in (("hot", HOT), ("free", FREE), ("cold", COLD)):
        if not np.any(region == value):
            raise ConfigError(
                f"radiation_study: the {name} region is empty (bed x from {x.min():.4g} to {x.max():.4g} m, "
                f"cold_x {s['cold_x']}, hot_x {s['hot_x']})"
            )
    return Bed(positions, R, pack.box - shift, region, pack.solid_fraction)


def initial_temperatures(bed: Bed, s: dict) -> np.ndarray:
    """Held particles at their slab temperature, free ones linear in x between the slabs (K)."""
    x = bed.positions[:, 0]
    f = (x - s["cold_x"]) / (s["hot_x"] - s["cold_x"])
    T = s["cold_temperature"] + f * (s["hot_temperature"] - s["cold_temperature"])
    T[bed.region == HOT] = s["hot_temperature"]
    T[bed.region == COLD] = s["cold_temperature"]
    return T


# --------------------------------------------------------------------------------------------
# The four models


@dataclass(frozen=True)
class RadiationModel:
    """q_i = coefficient [(T_i^p + (M T^p)_i)^(4/p) - T_i^4] (W), see the module docstring."""

    name: str
    generator: scipy.sparse.csr_matrix  # M, zero row sums
    power: int  # p: 4 (linear in T^4) or 1 (Musser)
    coefficient: float  # eps A sigma, W/K^4

    def heat_rates(self, T: np.ndarray) -> np.ndarray:
        """Heat into each particle (W) at temperatures ``T`` (K)."""
        if self.power == 4:
            return self.coefficient * (self.generator @ T**4)
        environment = T + self.generator @ T
        return self.coefficient * (environment**4 - T**4)

    def conductance_bound(self, T_max: float) -> float:
        """Largest sum of conductances of any particle (W/K) while all T <= ``T_max``: the secant
        conductance of T^4 is at most 4 T_max^3 per unit weight, and a row's weights sum to -M_ii."""
        return 4.0 * self.coefficient * T_max**3 * float(np.max(-self.generator.diagonal()))


def radiation_coefficient(s: dict) -> float:
    """eps_p A_p sigma (W/K^4), Eqs. 25 and 28."""
    return s["emissivity"] * 4.0 * math.pi * s["radius"] ** 2 * STEFAN_BOLTZMANN


def pairwise_generator(n: int, i, j, weight) -> scipy.sparse.csr_matrix:
    """M = G - diag(G 1) for the symmetric weights G_ij = G_ji = ``weight`` of pairs (i, j), i != j."""
    G = scipy.sparse.coo_matrix((np.concatenate([weight, weight]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                                shape=(n, n)).tocsr()  # fmt: skip
    return (G - scipy.sparse.diags(np.asarray(G.sum(axis=1)).ravel())).tocsr()


def dba_thermal_model(spec: dict, tables: rdf.RDFTables) -> thermal_model.ThermalModel:
    """The production thermal model of the study's bed from ``spec``
    (:func:`dpht.studies.radiation.study_thermal_spec`: its scene's materials, only PP radiation, Eq. 25)."""
    emissivity = spec["particles"]["emissivity"]
    if abs(tables.particle_emissivity - emissivity) > 1e-9:
        raise ConfigError(
            f"radiation_study.emissivity is {emissivity} but the RDF table was traced for particle "
            f"emissivity {tables.particle_emissivity}"
        )
    return thermal_model.build(spec, None, {}, tables)


def dba_model(bed: Bed, tm: thermal_model.ThermalModel) -> RadiationModel:
    """DBA (Eq. 25) with the RDF table, pairs and cutoff of the thermal model ``tm``."""
    i, j = bed.pairs(tm.cutoffs["pp_radiation"])
    u0, du, values = tm.tables["pp_radiation"]  # the RDF over squared distance in radii^2, as the kernel looks it up
    D = np.interp(bed.squared_distances(i, j) / bed.radius**2, u0 + du * np.arange(values.size), values)
    return RadiationModel("dba", pairwise_generator(len(bed.positions), i, j, D), 4, tm.parameters["pp_radiation"].coefficient)


def monte_carlo_model(counts: scipy.sparse.spmatrix, rays: int, coefficient: float) -> RadiationModel:
    """Eq. 25 with the traced RDF matrix ``counts / rays`` (self-absorption dropped), symmetrised."""
    D = scipy.sparse.csr_matrix(counts, dtype=np.float64) / rays
    D.setdiag(0.0)
    S = (0.5 * (D + D.T)).tocoo()
    upper = S.row < S.col
    return RadiationModel("monte_carlo", pairwise_generator(D.shape[0], S.row[upper], S.col[upper], S.data[upper]), 4,
                          coefficient)  # fmt: skip


def environment_models(bed: Bed, cutoff: float, coefficient: float) -> tuple[RadiationModel, RadiationModel]:
    """Musser (Eqs. 27-28) and Krause (Eq. 29) over the neighbours closer than ``cutoff`` (m)."""
    n = len(bed.positions)
    i, j = bed.pairs(cutoff)
    A = scipy.sparse.coo_matrix((np.ones(2 * i.size), (np.concatenate([i, j]), np.concatenate([j, i]))),
                                shape=(n, n)).tocsr()  # fmt: skip
    count = np.asarray(A.sum(axis=1)).ravel()
    if np.any(count == 0):
        k = int(np.flatnonzero(count == 0)[0])
        raise DPHTError(f"particle {k} has no neighbour within {cutoff:g} m: its environment temperature is undefined")
    M = (scipy.sparse.diags(1.0 / count) @ A - scipy.sparse.identity(n)).tocsr()
    return RadiationModel("musser", M, 1, coefficient), RadiationModel("krause", M, 4, coefficient)


# --------------------------------------------------------------------------------------------
# Steady state and heat balance


def steady_state(m: RadiationModel, T: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Temperatures (K) with q_i = 0 for every ``free`` particle, the others as in ``T``.

    q_i = 0 is (M x)_i = 0 with x = T^p: one sparse linear solve for the free x.
    """
    x = T**m.power
    M = m.generator
    Mf = M[free]
    x[free] = scipy.sparse.linalg.splu(Mf[:, free].tocsc()).solve(-(Mf[:, ~free] @ x[~free]))
    if np.any(x[free] <= 0):
        raise DPHTError(f"{m.name}: the steady state has non-positive temperatures")
    return x ** (1.0 / m.power)


def balance(q: np.ndarray, region: np.ndarray) -> dict:
    """Heat leaving the hot region, entering the cold region, their mean ("the" hot-to-cold rate),
    the heat generated (sum of all q, 0 when energy is conserved) and the net heat into the free
    particles (0 at steady state), in W."""
    hot_out = -float(q[region == HOT].sum())
    cold_in = float(q[region == COLD].sum())
    return {
        "hot_out_W": hot_out,
        "cold_in_W": cold_in,
        "rate_W": 0.5 * (hot_out + cold_in),
        "generation_W": float(q.sum()),
        "free_net_W": float(q[region == FREE].sum()),
    }


# --------------------------------------------------------------------------------------------
# Transient (Fig. 9)


def kernel_rates(tm: thermal_model.ThermalModel, bed: Bed):
    """DBA heat rates (W, original order) from the compiled production kernel, as ``T -> q``."""
    frame = integrate.prepare_frame(tm, bed.positions, bed.box[0], bed.box[1], bed.periodic)
    n = len(bed.positions)
    rates = integrate.Rates.for_frame(tm, frame)
    order = frame.particles

    def rates_of(T):
        integrate.evaluate(tm, frame, np.ascontiguousarray(T[order]), rates)
        q = np.empty(n)
        q[order] = rates.q
        return q

    return rates_of


def transient(rates_of, T0: np.ndarray, region: np.ndarray, capacity: float, dt: float, steps: int):
    """Explicit Euler for the free particles, dT/dt = q / capacity (J/K); the held ones stay put.

    ``rates_of(T)`` gives q (W). Returns, at times k dt for k = 0..steps, the heat leaving the hot
    region, entering the cold region and generated (W), shape (steps + 1, 3); and the final
    temperatures (K).
    """
    T = T0.copy()
    free = region == FREE
    history = np.empty((steps + 1, 3))
    for k in range(steps + 1):
        q = rates_of(T)
        history[k] = -q[region == HOT].sum(), q[region == COLD].sum(), q.sum()
        if k < steps:
            T[free] += q[free] * (dt / capacity)
    return history, T


# --------------------------------------------------------------------------------------------
# Driver: one call per workflow rule


def monte_carlo_batches(bed: Bed, s: dict, say):
    """RDF ray counts of every particle of the bed, one sparse matrix per independent batch of
    ``rays / batches`` rays per particle, yielded as traced (x is open: rays leaving through the
    outer faces of the held slabs are lost, which changes no free particle's exchange)."""
    per_batch = s["rays"] // s["batches"]
    seeds = np.random.SeedSequence([s["seed"], 1]).generate_state(s["batches"], np.uint64)
    for b, seed in enumerate(seeds):
        last = [time.monotonic()]

        def report(done, total, b=b):
            if time.monotonic() - last[0] > 15.0 or done == total:
                last[0] = time.monotonic()
                say(f"Monte Carlo batch {b + 1}/{s['batches']}: {done}/{total} particles x {per_batch} rays")

        result = raytrace.trace(bed.positions, bed.radius, s["emissivity"], per_batch, box=bed.box,
                                periodic=bed.periodic, seed=int(seed), progress=report)  # fmt: skip
        yield result.counts


def steady_results(models: dict, T0: np.ndarray, bed: Bed, s: dict) -> dict:
    """Per model: the heat balance at the direct steady state (see :func:`balance`), the largest
    free-particle rate left over relative to one hot particle's emission eps A sigma T_hot^4
    (``free_residual``), and the steady temperatures (K, ``temperature``)."""
    free = bed.region == FREE
    results = {}
    for name, m in models.items():
        T = steady_state(m, T0, free)
        q = m.heat_rates(T)
        results[name] = balance(q, bed.region) | {
            "free_residual": float(np.abs(q[free]).max() / (m.coefficient * s["hot_temperature"] ** 4)),
            "temperature": T,
        }
    return results


def run_study(spec: dict, rdf_table_path, out_dir, progress=None, threads: int | None = None):
    """Build the bed, trace it, solve the four models' steady states and transients, and write
    ``table.csv``, ``table.md`` and ``history.csv`` into ``out_dir``.

    spec: :func:`dpht.studies.radiation.stage_spec`, the study's section (see :func:`check_spec`)
    and the thermal model of its bed. rdf_table_path: RDF tables (:mod:`dpht.closures.rdf`) traced
    for the particle emissivity, covering the solid fraction. progress: called with a message per
    step (default: the ``dpht`` logger). threads: numba threads (default: numba's). Returns a
    JSON-ready summary, the transient's times (s) and its histories (model -> (K, 3) hot-out,
    cold-in, generation in W), which :func:`dpht.figures.radiation_study.radiation_models_figure`
    draws as Fig. 9.
    """
    s = check_spec(spec["study"])
    if threads:
        numba.set_num_threads(threads)
    say = progress or log.info
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    clock = {}
    start = time.monotonic()
    tm = dba_thermal_model(spec["thermal"], rdf.load(rdf_table_path))
    bed = make_bed(s)
    clock["packing_s"] = time.monotonic() - start
    say(f"bed: {len(bed.positions)} particles, box {np.round(bed.box[1] - bed.box[0], 6).tolist()} m, "
        f"{np.count_nonzero(bed.region == FREE)} free ({clock['packing_s']:.1f} s)")  # fmt: skip

    start = time.monotonic()
    coefficient = radiation_coefficient(s)
    T0 = initial_temperatures(bed, s)
    total, batch_rates = None, []
    for counts in monte_carlo_batches(bed, s, say):
        batch = monte_carlo_model(counts, s["rays"] // s["batches"], coefficient)
        batch_rates.append(steady_results({"batch": batch}, T0, bed, s)["batch"]["rate_W"])
        total = counts if total is None else total + counts
    clock["monte_carlo_s"] = time.monotonic() - start

    start = time.monotonic()
    musser, krause = environment_models(bed, s["environment_cutoff"] * s["radius"], coefficient)
    models = {"musser": musser, "krause": krause, "dba": dba_model(bed, tm),
              "monte_carlo": monte_carlo_model(total, s["rays"], coefficient)}  # fmt: skip
    steady = steady_results(models, T0, bed, s)
    clock["steady_s"] = time.monotonic() - start

    start = time.monotonic()
    capacity = s["density"] * packing.SPHERE_VOLUME * s["radius"] ** 3 * s["specific_heat"]
    steps = max(1, math.ceil(s["duration"] * max(m.conductance_bound(s["hot_temperature"]) for m in models.values()) / capacity))
    dt = s["duration"] / steps
    histories = {}
    for name, m in models.items():
        rates_of = kernel_rates(tm, bed) if name == "dba" else m.heat_rates
        histories[name], T_end = transient(rates_of, T0, bed.region, capacity, dt, steps)
        steady[name]["transient_vs_steady_K"] = float(np.abs(T_end - steady[name].pop("temperature")).max())
    clock["transient_s"] = time.monotonic() - start

    mc = steady["monte_carlo"]["rate_W"]
    for row in steady.values():
        row["error"] = row["rate_W"] / mc - 1.0
        row["rate_W_per_m2"] = row["rate_W"] / bed.cross_section
    k = len(batch_rates)
    summary = {
        "particles": len(bed.positions),
        "free_particles": int(np.count_nonzero(bed.region == FREE)),
        "box_m": (bed.box[1] - bed.box[0]).tolist(),
        "cross_section_m2": bed.cross_section,
        "solid_fraction": bed.solid_fraction,
        "rays_per_particle": s["rays"],
        "monte_carlo_batch_rates_W": batch_rates,
        # Batch means: the batches' spread gives the standard error of the total's rate; their
        # offset from it the bias of a rate that is nonlinear in the RDFs (jackknife, bias ~ 1/rays).
        "monte_carlo_rate_stderr_W": float(np.std(batch_rates, ddof=1) / math.sqrt(k)) if k > 1 else None,
        "monte_carlo_rate_bias_W": (float(np.mean(batch_rates)) - mc) / (k - 1) if k > 1 else None,
        "time_step_s": dt,
        "heat_capacity_J_K": capacity,
        "models": steady,
        "seconds": clock,
    }
    write_table(out, summary)
    write_history(out / "history.csv", dt * np.arange(steps + 1), histories)
    say("; ".join(f"{LABELS[k]} {v['rate_W']:.4g} W ({v['error']:+.1%})" for k, v in steady.items()))
    return summary, dt * np.arange(steps + 1), histories


def paper_cross_section(radius: float = 5e-4, solid_fraction: float = 0.58) -> float:
    """y-z area (m^2) of a cube holding the paper's 17,563 particles at its solid fraction: the
    paper gives no box size, so this is how its rates are put per m^2 (an estimate)."""
    return (PAPER_PARTICLES * packing.SPHERE_VOLUME * radius**3 / solid_fraction) ** (2 / 3)


def write_table(out: Path, summary: dict) -> None:
    """``table.csv`` (one row per model, ours and the paper's) and ``table.md`` (like Table 1)."""
    steady, area, paper_area = summary["models"], summary["cross_section_m2"], paper_cross_section()
    keys = ("hot_out_W", "cold_in_W", "rate_W", "rate_W_per_m2", "error", "generation_W", "free_residual",
            "transient_vs_steady_K")  # fmt: skip
    with open(out / "table.csv", "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["model", *keys, "generation_per_rate", "paper_rate_W", "paper_rate_W_per_m2", "paper_error",
                         "paper_generation_W"])  # fmt: skip
        for name in MODELS:
            row, paper = steady[name], PAPER_TABLE_1[name]
            paper_flux = None if paper["rate_W"] is None else paper["rate_W"] / paper_area
            writer.writerow([name, *(repr(row[k]) for k in keys), repr(row["generation_W"] / steady["monte_carlo"]["rate_W"]),
                             paper["rate_W"], paper_flux, paper["error"], paper["generation_W"]])  # fmt: skip

    def cells(f):
        return " | ".join(f(name) for name in MODELS)

    def unbalanced(n):  # hot-out and cold-in differ by more than 1%
        return abs(steady[n]["hot_out_W"] - steady[n]["cold_in_W"]) > 0.01 * abs(steady[n]["rate_W"])

    def pct(v):
        return "-" if v is None else f"{100 * v:+.1f}%"

    paper = PAPER_TABLE_1
    mc_paper = paper["monte_carlo"]["rate_W"]
    noise = ""
    if summary["monte_carlo_rate_stderr_W"] is not None:
        noise = (f" (its rate: standard error {summary['monte_carlo_rate_stderr_W']:.2g} W, estimated bias "
                 f"{summary['monte_carlo_rate_bias_W']:.2g} W)")  # fmt: skip
    lines = [
        f"Particle-particle radiation models in a static bed of {summary['particles']} particles "
        f"({summary['free_particles']} free), cross-section {area * 1e6:.1f} mm^2, Monte Carlo with "
        f"{summary['rays_per_particle']} rays per particle{noise}. Paper: DPHT paper Table 1, 17,563 particles; its "
        f"per-m^2 values assume a cube at solid fraction 0.58 ({paper_area * 1e6:.0f} mm^2).",
        "",
        "| | " + " | ".join(LABELS[n] for n in MODELS) + " |",
        "|---|" + "---:|" * len(MODELS),
        "| Heat leaving the hot region (W) | " + cells(lambda n: f"{steady[n]['hot_out_W']:.4g}") + " |",
        "| Heat entering the cold region (W) | " + cells(lambda n: f"{steady[n]['cold_in_W']:.4g}") + " |",
        "| Steady hot-to-cold rate (W), mean of the two | "
        + cells(lambda n: f"{steady[n]['rate_W']:.4g}" + (" (hot-out != cold-in)" if unbalanced(n) else "")) + " |",
        "| per m^2 of cross-section (W/m^2) | " + cells(lambda n: f"{steady[n]['rate_W_per_m2']:.4g}") + " |",
        "| Error vs Monte Carlo | " + cells(lambda n: "-" if n == "monte_carlo" else pct(steady[n]["error"])) + " |",
        "| Erroneous heat generation (W) | " + cells(lambda n: f"{steady[n]['generation_W']:.3g}") + " |",
        "| generation / Monte Carlo rate | "
        + cells(lambda n: f"{steady[n]['generation_W'] / steady['monte_carlo']['rate_W']:+.3g}") + " |",
        "| Paper: steady rate (W) | "
        + cells(lambda n: "Not converged" if paper[n]["rate_W"] is None else f"{paper[n]['rate_W']:.3g}") + " |",
        "| Paper: per m^2 (W/m^2, estimated) | "
        + cells(lambda n: "-" if paper[n]["rate_W"] is None else f"{paper[n]['rate_W'] / paper_area:.3g}") + " |",
        "| Paper: error vs Monte Carlo | " + cells(lambda n: pct(paper[n]["error"])) + " |",
        "| Paper: erroneous generation (W) | " + cells(lambda n: f"{paper[n]['generation_W']:.3g}") + " |",
        "| Paper: generation / Monte Carlo rate | " + cells(lambda n: f"{paper[n]['generation_W'] / mc_paper:+.3g}") + " |",
        "",
    ]
    (out / "table.md").write_text("\n".join(lines))


def write_history(path: Path, times: np.ndarray, histories: dict) -> None:
    """One row per time step: per model the heat leaving the hot region, entering the cold region
    and the net generation (W)."""
    columns = {"time_s": times}
    for name in MODELS:
        for k, what in enumerate(("hot_out_W", "cold_in_W", "generation_W")):
            columns[f"{name}_{what}"] = histories[name][:, k]
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(columns)
        writer.writerows(zip(*(map(repr, map(float, c)) for c in columns.values())))
