"""RDF tables from Monte Carlo ray tracing (dpht.radiation.raytrace); the RDF matrix of one bed
(the ``rdf`` command) is in dpht.radiation.bed_rdf.

Tables (DPHT paper, Sections 3.6-3.7; the file format, and which solid fraction indexes which
table, is dpht.closures.rdf):

* particle-particle (pp), indexed by the *bulk* solid fraction: a periodic random packing
  (dpht.radiation.packing) at that solid fraction; ``emitters`` random particles emit ``rays`` rays
  each; the RDF of every pair (i, j), zero-count pairs included, is binned by the centre distance
  d_ij (minimum image) and averaged over the pairs in each bin: the mean D_ij that Eq. 25 needs.
* particle-wall (pw), indexed by the *near-wall* solid fraction, the solid fraction within one
  particle diameter of the wall, which is what the thermal stage reads it with (the DEM report
  measures it at the tube wall, dpht.dem.report): a slab packed between two flat hard walls,
  periodic along the other two axes, whose near-wall band is packed to exactly that solid fraction
  (the particles layer against the walls as in a real bed). Both walls are gray diffuse planes with
  the wall emissivity; each emitter contributes its RDF to each wall at its centre-to-wall
  distance (Eq. 26).

Every entry is measured. A bin's value is a ratio of sums over emitters, sum_i S_i / sum_i P_i
(S_i: the emitter's RDFs in the bin, P_i: its number of pairs or walls there); its standard error
is the delta-method (cluster) estimate across emitters, so it includes the Monte Carlo noise and
the spread between local arrangements. Each entry must come from at least ``MIN_SAMPLES`` emitters
and reach its table's stated standard error (``PP_STDERR``, ``PW_STDERR``); the table records both
per entry, and a build that cannot reach them stops naming the entries.

Hard-wall packings stratify: a dense first layer at contact, a second near 2.6-2.8 R, and almost no
particle in between (at near-wall 0.59, 0-3 of 4,500 per 0.1 R bin between 1.1 and 2.25 R). Test
particles cannot be inserted there either: a sphere fits nowhere in 2e5 random tries at any wall
distance once the bulk passes 0.45 (measured), as the Widom insertion probability of dense hard
spheres vanishes. So the emitters of such bins are *pinned* spheres (dpht.radiation.packing.Pins):
extra slabs, packed to the same near-wall solid fraction, in which spheres are held at wall
distances drawn uniformly in the bins that lack samples while the others pack around them. Each is
a bed conditioned on a particle at that distance, which is exactly what the entry is the mean over
(for an equilibrium hard-sphere fluid the conditional distribution of the others is the one a
pinned sphere produces); where both kinds of emitter exist they agree within their errors (tests,
``rdf_table_pinned_emitters`` in ``python -m dpht verify``). Pinned slabs are added until every
entry is measured well enough.

Distance bins follow the curvature of the RDF: 0.01 R at contact, where the RDF falls fastest,
0.025 R around the shadowing dip at two diameters (pairs with a third particle in between), 0.05 R
over the second shell and 0.1-0.5 R in the far field where it decays smoothly. The binning error of
each entry is measured on the same samples: the largest difference, beyond three of its standard
errors, between the table's linear interpolation and a ``FINE_BIN`` (0.01 R) binned trace over the
interval between the neighbouring entries (0 where they agree within the noise). The previous
0.25 R bins beyond 2.75 R overestimated the RDF at 4 R, solid fraction 0.64, by 1.6 times.

Default build (5 bulk and 6 near-wall solid fractions, one emissivity pair): 4,500-sphere
packings, 2,000 emitters x 2,000 rays per bed, plus 10-18 pinned slabs (500-900 pinned emitters)
per near-wall solid fraction; 8.0 minutes on the 2 cores here while other jobs ran (the packings
run two at a time; the old 0.25 R-binned, gap-interpolated build took 2.5). Measured for particle
emissivity 0.65 and wall 0.6: every entry from at least 20 emitters (pp at least 102); largest
standard error 5.0e-4 pp, 4.0e-3 pw (the stated ones); largest binning error 1.3e-4 pp (at 4.55 R,
0.35), 1.0e-4 pw. Distances are in radii.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np
from scipy.spatial import cKDTree

from dpht.closures.rdf import FORMAT, RDFTable, RDFTables
from dpht.defaults import default
from dpht.errors import DPHTError
from dpht.radiation import packing, raytrace

# pw: near-wall. Unpinned slabs reach 0.59 (bulk 0.64), slabs with pins jam above about 0.55; the
# DEM beds here measure 0.54 in flow (dpht.dem.report), the paper's 0.5405.
PW_SOLID_FRACTIONS = (0.20, 0.30, 0.40, 0.47, 0.51, 0.55)
# A build the caller does not size (thermal.rdf_build: bulk solid_fractions, rays, emitters,
# n_particles, seed) takes the config's defaults.
BUILD = {key: default(f"thermal.rdf_build.{key}") for key in ("solid_fractions", "rays", "emitters", "n_particles", "seed")}


def _steps(start, *pieces):
    """Bin edges from ``start`` through pieces (stop, width): uniform ``width`` up to ``stop``."""
    edges = [start]
    for stop, width in pieces:
        n = int(round((stop - edges[-1]) / width))
        edges += list(np.linspace(edges[-1], stop, n + 1)[1:])
    return np.round(np.array(edges), 9)


# Bin edges in radii, from the curvature (see the module docstring).
PP_EDGES = _steps(2.0, (2.04, 0.01), (2.1, 0.02), (3.8, 0.05), (4.2, 0.025), (6.0, 0.1), (15.0, 0.25))
PW_EDGES = _steps(1.0, (1.04, 0.01), (1.1, 0.02), (1.5, 0.05), (3.0, 0.1), (6.0, 0.2), (15.0, 0.5))
FINE_BIN = 0.01  # radii: the reference binning of the binning error
BINNING_NOISE = 3.0  # standard errors of the fine reference that a difference must exceed to count
FINE_MIN_SAMPLES = 10  # emitters a fine bin needs for its standard error to be trusted
MIN_SAMPLES = 20  # emitters behind every entry
PP_STDERR = 5e-4  # stated standard error of every pp entry (0.8 % of the contact value)
PW_STDERR = 4e-3  # of every pw entry (about 2 % of the contact value)
SLAB_ASPECT = (1.0, 1.0, 2.0)
# Pinned slabs: at least PIN_SLAB_THICKNESS radii between the walls and twice the farthest pin's
# distance plus PIN_SLAB_CLEARANCE radii, a square lattice of pins PIN_SPACING radii apart on each
# wall (clear of each other's first-layer disturbance).
PIN_SLAB_THICKNESS = 20.0
PIN_SLAB_CLEARANCE = 6.0
PIN_SPACING = 5.0
PIN_LATTICE = 5  # pins per row: the slab is PIN_LATTICE * PIN_SPACING radii wide
MAX_PIN_SLABS = 60  # per solid fraction
PIN_ATTEMPTS = 3  # seeds tried for a pinned slab that jams
_PIN_SD_GUESS = 0.02  # spread of one emitter's wall RDF, before any is measured


@dataclass(frozen=True)
class Samples:
    """RDF samples of one table row: emitter index (cluster), distance (radii) and value each."""

    cluster: np.ndarray
    distance: np.ndarray
    value: np.ndarray
    n_clusters: int

    def __add__(self, other: "Samples") -> "Samples":
        return Samples(
            np.concatenate([self.cluster, other.cluster + self.n_clusters]),
            np.concatenate([self.distance, other.distance]),
            np.concatenate([self.value, other.value]),
            self.n_clusters + other.n_clusters,
        )


def binned_mean(cluster, distance, value, edges, n_clusters):
    """Mean of ``value`` per distance bin, its cluster-robust standard error, and the number of
    clusters (emitters) with samples in the bin.

    cluster: emitter index (0 .. n_clusters-1) of each sample. Returns (mean, stderr, samples) per
    bin; bins without samples have NaN mean and standard error, bins with one cluster NaN stderr.
    """
    n_bins = len(edges) - 1
    b = np.digitize(distance, edges) - 1
    keep = (b >= 0) & (b < n_bins)
    index = cluster[keep] * n_bins + b[keep]
    s = np.bincount(index, value[keep], n_clusters * n_bins).reshape(n_clusters, n_bins)
    p = np.bincount(index, None, n_clusters * n_bins).reshape(n_clusters, n_bins)
    pairs = p.sum(axis=0)
    samples = np.count_nonzero(p, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s.sum(axis=0) / pairs
        resid = s - mean * p
        stderr = np.sqrt(samples / (samples - 1.0) * np.sum(resid**2, axis=0)) / pairs
    stderr[samples < 2] = np.nan
    return mean, stderr, samples


@dataclass(frozen=True)
class Row:
    """One solid fraction's entries: value, standard error, emitters and binning error per bin."""

    rdf: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    binning_error: np.ndarray

    @classmethod
    def measure(cls, data: Samples, edges: np.ndarray) -> "Row":
        mean, stderr, samples = binned_mean(data.cluster, data.distance, data.value, edges, data.n_clusters)
        return cls(mean, stderr, samples, binning_error(data, edges, mean))

    def short(self, target: float) -> np.ndarray:
        """Mask of the entries with fewer than MIN_SAMPLES emitters or a standard error above ``target``."""
        return (self.samples < MIN_SAMPLES) | ~(self.stderr <= target)


def binning_error(data: Samples, edges: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Per entry: the largest difference, beyond BINNING_NOISE of its standard errors, between the
    table's linear interpolation through the bin centres and a FINE_BIN binned trace of the same
    samples, over the fine bins between the neighbouring entries' centres that hold at least
    FINE_MIN_SAMPLES emitters (0: within the noise, or no fine bin measured well enough to tell)."""
    centres = 0.5 * (edges[1:] + edges[:-1])
    fine = _steps(edges[0], (edges[-1], FINE_BIN))
    f_mean, f_err, f_samples = binned_mean(data.cluster, data.distance, data.value, fine, data.n_clusters)
    f_centre = 0.5 * (fine[1:] + fine[:-1])
    full = np.isfinite(mean)
    table = np.interp(f_centre, centres[full], mean[full])
    with np.errstate(invalid="ignore"):
        excess = np.where(f_samples >= FINE_MIN_SAMPLES, np.abs(table - f_mean) - BINNING_NOISE * f_err, 0.0)
    excess = np.maximum(excess, 0.0)
    span_lo = np.concatenate([[edges[0]], centres[:-1]])
    span_hi = np.concatenate([centres[1:], [edges[-1]]])
    first = np.searchsorted(f_centre, span_lo)
    last = np.searchsorted(f_centre, span_hi, side="right")
    return np.array([excess[a:b].max() if b > a else 0.0 for a, b in zip(first, last)])


def _seeds(seed, *path):
    """Independent seeds (packing, trace) for the bed at ``path`` (kind code, solid fraction number, ...)."""
    return np.random.SeedSequence([seed, *path]).generate_state(2, np.uint64)


def _names(edges, mask):
    centres = 0.5 * (edges[1:] + edges[:-1])
    return ", ".join(f"{c:.3g}" for c in centres[mask])


# --------------------------------------------------------------------------------------------
# Particle-particle rows


def pp_samples(pack: packing.Packing, emissivity, rays, chosen, seed) -> tuple[Samples, float]:
    """PP RDF samples of the emitters ``chosen`` in one periodic packing, and the mean fraction of
    their rays absorbed within the last bin edge (self-absorption included)."""
    r = pack.radius
    length = pack.box[1] - pack.box[0]
    d_max = PP_EDGES[-1] * r
    result = raytrace.trace(
        pack.positions, r, emissivity, rays, box=pack.box, periodic=(True,) * 3, emitters=chosen, seed=int(seed)
    )
    tree = cKDTree(np.mod(pack.positions - pack.box[0], length), boxsize=length)
    neighbours = tree.query_ball_point(np.mod(pack.positions[chosen] - pack.box[0], length), d_max)
    cluster = np.repeat(np.arange(chosen.size), [len(nb) for nb in neighbours])
    i = chosen[cluster]
    j = np.concatenate([np.asarray(nb, dtype=np.int64) for nb in neighbours])
    gap = pack.positions[i] - pack.positions[j]
    gap -= length * np.round(gap / length)
    distance = np.linalg.norm(gap, axis=1) / r
    value = np.asarray(result.matrix[i, j]).ravel()
    captured = float(np.bincount(cluster, value, chosen.size).mean())
    pair = i != j
    return Samples(cluster[pair], distance[pair], value[pair], chosen.size), captured


def pp_row(pack: packing.Packing, emissivity, rays, emitters, seed, target=PP_STDERR) -> tuple[Row, float]:
    """PP entries (PP_EDGES) of one periodic packing: ``emitters`` random particles emit; if an
    entry misses MIN_SAMPLES or the standard error ``target``, the rest of the packing's
    particles emit too."""
    length = pack.box[1] - pack.box[0]
    if length.min() < 2 * PP_EDGES[-1] * pack.radius:
        raise DPHTError(
            f"n_particles too small: the periodic box is {length.min() / pack.radius:.1f} radii wide, pair "
            f"distances up to {PP_EDGES[-1]:g} radii need at least {2 * PP_EDGES[-1]:g}"
        )
    order = np.random.default_rng(int(seed)).permutation(len(pack.positions))
    data, captured = pp_samples(pack, emissivity, rays, np.sort(order[:emitters]), seed)
    row = Row.measure(data, PP_EDGES)
    if row.short(target).any() and emitters < order.size:
        more, more_captured = pp_samples(pack, emissivity, rays, np.sort(order[emitters:]), seed)
        n1, n2 = data.n_clusters, more.n_clusters
        data, captured = data + more, (n1 * captured + n2 * more_captured) / (n1 + n2)
        row = Row.measure(data, PP_EDGES)
    short = row.short(target)
    if short.any():
        raise DPHTError(
            f"RDF table pp at solid fraction {pack.solid_fraction:.3f}: {data.n_clusters} emitters leave the entries "
            f"at {_names(PP_EDGES, short)} radii short of {MIN_SAMPLES} emitters or standard error {target:g}; "
            f"use more rays or particles"
        )
    return row, captured


# --------------------------------------------------------------------------------------------
# Particle-wall rows


def _slab_walls(slab: packing.Packing, wall_emissivity):
    lo, hi = slab.box[0, 2], slab.box[1, 2]
    return [raytrace.PlaneWall((0, 0, lo), (0, 0, 1), wall_emissivity), raytrace.PlaneWall((0, 0, hi), (0, 0, -1), wall_emissivity)]


def _wall_distances(slab: packing.Packing) -> np.ndarray:
    """(n, 2) centre distances (radii) to the walls at box[0, 2] and box[1, 2]."""
    z = slab.positions[:, 2]
    return np.stack([z - slab.box[0, 2], slab.box[1, 2] - z], axis=1) / slab.radius


def pw_slab_samples(slab: packing.Packing, emissivity, wall_emissivity, rays, emitters, seed) -> Samples:
    """PW samples of one slab between walls normal to z: ``emitters`` random particles within the
    last bin edge of a wall emit; each contributes its RDF to each wall at its distance."""
    to_wall = _wall_distances(slab)
    candidates = np.flatnonzero(to_wall.min(axis=1) < PW_EDGES[-1])
    rng = np.random.default_rng(int(seed))
    chosen = np.sort(rng.choice(candidates, size=min(emitters, candidates.size), replace=False))
    result = raytrace.trace(
        slab.positions, slab.radius, emissivity, rays, walls=_slab_walls(slab, wall_emissivity), box=slab.box,
        periodic=(True, True, False), emitters=chosen, seed=int(seed),
    )  # fmt: skip
    cluster = np.repeat(np.arange(chosen.size), 2)
    return Samples(cluster, to_wall[chosen].ravel(), result.walls[chosen].ravel(), chosen.size)


def pinned_slab(phi, distances, seed) -> packing.Packing:
    """A thin slab packed to near-wall solid fraction ``phi`` with up to 2 * PIN_LATTICE^2 spheres
    pinned at the wall ``distances`` (radii), the lattice on each wall shifted by half a spacing
    from the other's."""
    k = len(distances)
    side = PIN_LATTICE * PIN_SPACING
    thickness = max(PIN_SLAB_THICKNESS, 2 * float(np.max(distances)) + PIN_SLAB_CLEARANCE)
    # The near-wall match sizes the box for close packing: at least these dimensions in radii.
    n = int(round(side * side * thickness * packing.RANDOM_CLOSE_PACKING / packing.SPHERE_VOLUME))
    grid = (np.arange(PIN_LATTICE) + 0.5) / PIN_LATTICE
    u, v = np.meshgrid(grid, grid, indexing="ij")
    slots = np.column_stack([u.ravel(), v.ravel()])
    slots = np.concatenate([slots, np.mod(slots + 0.5 / PIN_LATTICE, 1.0)])
    high = np.arange(len(slots)) >= len(slots) // 2
    pins = packing.Pins(slots[:k], np.asarray(distances, dtype=float), high[:k])
    aspect = (side / thickness, side / thickness, 1.0)
    return packing.pack(n, phi, aspect=aspect, wall_axis=2, seed=int(seed), match="near_wall", pins=pins,
                        bulk_margin=1.0)  # fmt: skip


def pinned_samples(slab: packing.Packing, emissivity, wall_emissivity, rays, seed) -> Samples:
    """PW samples of the pinned spheres of ``slab``: each emits and contributes its RDF to its own wall."""
    n = len(slab.positions)
    pins = np.arange(n - slab.n_pinned, n)
    result = raytrace.trace(
        slab.positions, slab.radius, emissivity, rays, walls=_slab_walls(slab, wall_emissivity), box=slab.box,
        periodic=(True, True, False), emitters=pins, seed=int(seed),
    )  # fmt: skip
    to_wall = _wall_distances(slab)[pins]
    own = np.argmin(to_wall, axis=1)
    k = np.arange(pins.size)
    return Samples(k, to_wall[k, own], result.walls[pins][k, own], pins.size)


def _pin_distances(row: Row, short: np.ndarray, target, per_slab, rng) -> np.ndarray:
    """Wall distances for new pinned spheres, uniform in each short bin: as many as each needs to
    reach MIN_SAMPLES and (from its spread so far) the standard error ``target``, plus enough in
    proportion to fill the last slab's lattice (a slab costs the same however many pins it holds)."""
    have = row.samples[short]
    spread = np.where(have >= 2, np.nan_to_num(row.stderr[short], nan=0.0) * np.sqrt(have), _PIN_SD_GUESS)
    need = np.maximum(np.maximum(MIN_SAMPLES - have, np.ceil(1.2 * (spread / target) ** 2) - have), 2)
    total = per_slab * int(np.ceil(need.sum() / per_slab))
    need = np.floor(need * total / need.sum()).astype(int)
    need[: total - need.sum()] += 1
    lo, hi = PW_EDGES[:-1][short], PW_EDGES[1:][short]
    return rng.permutation(np.concatenate([rng.uniform(a, b, k) for a, b, k in zip(lo, hi, need)]))


def _in_parallel(jobs):
    """Results of the zero-argument callables ``jobs``, in order, run on numba's threads: the
    packings release the GIL, and each has its own seed, so the results do not depend on it."""
    with ThreadPoolExecutor(max_workers=max(1, numba.get_num_threads())) as pool:
        return list(pool.map(lambda job: job(), jobs))


def _pinned_slab_retrying(phi, distances, seed, path, say) -> packing.Packing:
    for attempt in range(PIN_ATTEMPTS):  # pins make jamming likelier near the densest targets
        try:
            return pinned_slab(phi, distances, _seeds(seed, *path, attempt)[0])
        except DPHTError as error:
            say(f"near-wall {phi:.3f}: pinned slab {path}, attempt {attempt + 1}: {error}")
    raise DPHTError(f"RDF table pw at near-wall solid fraction {phi}: {PIN_ATTEMPTS} seeds of pinned slab {path} jammed")


def pw_slab(phi, n_particles, seed, k) -> packing.Packing:
    """The unpinned slab of ``n_particles`` for near-wall solid fraction number ``k``, ``phi``."""
    return packing.pack(n_particles, phi, aspect=SLAB_ASPECT, wall_axis=2, seed=int(_seeds(seed, 1, k)[0]), match="near_wall")


def pw_row(slab, emissivity, wall_emissivity, rays, emitters, seed, k, say, target=PW_STDERR):
    """PW entries (PW_EDGES) at the near-wall solid fraction of ``slab`` (from :func:`pw_slab`):
    its particles emit, then pinned slabs for the entries it leaves short of MIN_SAMPLES or the
    standard error ``target``. Returns the row and a dict of what it took."""
    phi = slab.solid_fraction
    s_trace = _seeds(seed, 1, k)[1]
    data = pw_slab_samples(slab, emissivity, wall_emissivity, rays, emitters, s_trace)
    unpinned = data.n_clusters
    row = Row.measure(data, PW_EDGES)
    rng = np.random.default_rng(int(s_trace))
    per_slab = 2 * PIN_LATTICE**2
    slabs = 0
    while (short := row.short(target)).any():
        if slabs >= MAX_PIN_SLABS:
            raise DPHTError(
                f"RDF table pw at near-wall solid fraction {phi:g}: the entries at {_names(PW_EDGES, short)} radii "
                f"stay short of {MIN_SAMPLES} emitters or standard error {target:g} after {slabs} pinned slabs"
            )
        distances = _pin_distances(row, short, target, per_slab, rng)
        chunks = [distances[first : first + per_slab] for first in range(0, distances.size, per_slab)]
        paths = [(2, k, slabs + j) for j in range(len(chunks))]
        pinned = _in_parallel([
            lambda c=c, path=path: _pinned_slab_retrying(phi, c, seed, path, say) for c, path in zip(chunks, paths)
        ])  # fmt: skip
        for bed, path in zip(pinned, paths):
            data = data + pinned_samples(bed, emissivity, wall_emissivity, rays, _seeds(seed, *path)[1])
        slabs += len(chunks)
        row = Row.measure(data, PW_EDGES)
        say(f"near-wall {phi:.3f}: {slabs} pinned slabs so far, {int(row.short(target).sum())} entries short")
    bulk = packing.slab_solid_fraction(
        slab.positions, slab.radius, slab.box[0, 2] + 4 * slab.radius, slab.box[1, 2] - 4 * slab.radius, 2,
        float(np.prod(slab.box[1, :2] - slab.box[0, :2])),
    )  # fmt: skip
    return row, {"pinned_slabs": slabs, "pinned_emitters": data.n_clusters - unpinned,
                 "bulk_solid_fraction": bulk}  # fmt: skip


def build_tables(
    particle_emissivity: float,
    wall_emissivity: float,
    solid_fractions=tuple(BUILD["solid_fractions"]),
    *,
    pw_solid_fractions=PW_SOLID_FRACTIONS,
    rays: int = BUILD["rays"],
    n_particles: int = BUILD["n_particles"],
    emitters: int = BUILD["emitters"],
    seed: int = BUILD["seed"],
    stderr=(PP_STDERR, PW_STDERR),
    format: str = FORMAT,
    progress=None,
) -> RDFTables:
    """Trace packed beds and tabulate PP RDFs versus distance at the bulk ``solid_fractions`` and
    PW RDFs at the near-wall ``pw_solid_fractions``.

    rays: rays per emitter; emitters: emitting particles per bed; n_particles: spheres per packing
    (the periodic PP box must be at least 30 radii wide). stderr: the standard error every pp and
    pw entry must reach (stated in the table; pinned emitters are added for pw entries, more
    emitters of the packing for pp ones, and a build that cannot reach them stops). format: the table format the caller
    expects (part of the workflow's cache key); only the current one can be built. progress:
    called with a message per step. Write the result with ``dpht.closures.rdf.save``.
    """
    if format != FORMAT:
        raise DPHTError(f"RDF tables of format {format!r} cannot be built; this builder writes {FORMAT!r}")
    raytrace.check_emissivity("particle_emissivity", particle_emissivity, allow_zero=False)
    raytrace.check_emissivity("wall_emissivity", wall_emissivity, allow_zero=True)
    phis = _check_fractions("solid_fractions", solid_fractions, packing.RANDOM_CLOSE_PACKING)
    pw_phis = _check_fractions("pw_solid_fractions", pw_solid_fractions, 0.6)
    needed = int(np.ceil(phis[-1] * (2 * PP_EDGES[-1]) ** 3 / packing.SPHERE_VOLUME))
    if n_particles < needed:
        raise DPHTError(
            f"n_particles = {n_particles} is too small: a periodic box at solid fraction {phis[-1]} must be "
            f"{2 * PP_EDGES[-1]:g} radii wide for pair distances up to {PP_EDGES[-1]:g} radii; use >= {needed}"
        )
    if emitters < MIN_SAMPLES:
        raise DPHTError(f"emitters = {emitters}: every entry needs at least {MIN_SAMPLES} emitters")
    say = progress or (lambda message: None)
    pp_rows, pw_rows, notes = [], [], []
    beds = _in_parallel([lambda k=k, phi=phi: packing.pack(n_particles, phi, seed=int(_seeds(seed, 0, k)[0]))
                         for k, phi in enumerate(phis)])  # fmt: skip
    say(f"{len(beds)} periodic packings done")
    for k, (phi, bed) in enumerate(zip(phis, beds)):
        row, captured = pp_row(bed, particle_emissivity, rays, emitters, _seeds(seed, 0, k)[1], stderr[0])
        pp_rows.append(row)
        say(f"bulk {phi:.3f}: pp done ({captured:.4f} of the rays absorbed within {PP_EDGES[-1]:g} R)")
    slabs = _in_parallel([lambda k=k, phi=phi: pw_slab(phi, n_particles, seed, k) for k, phi in enumerate(pw_phis)])
    say(f"{len(slabs)} slabs between walls done")
    for k, (phi, slab) in enumerate(zip(pw_phis, slabs)):
        row, note = pw_row(slab, particle_emissivity, wall_emissivity, rays, emitters, seed, k, say, stderr[1])
        pw_rows.append(row)
        notes.append(f"near-wall {phi:g}: slab bulk {note['bulk_solid_fraction']:.3f}, {note['pinned_emitters']} pinned "
                     f"emitters in {note['pinned_slabs']} slabs")  # fmt: skip
        say(f"{notes[-1]}; pw done")
    source = (
        f"dpht.radiation.tables: Monte Carlo ray tracing, {rays} rays per emitter, {emitters} emitters per bed in "
        f"Lubachevsky-Stillinger packings of {n_particles} spheres (pp periodic at the bulk solid fraction; pw slabs "
        f"between walls packed to the near-wall solid fraction, plus slabs with pinned emitters: {'; '.join(notes)}), "
        f"seed {seed}"
    )
    return RDFTables(
        _table(PP_EDGES, phis, pp_rows, rays, stderr[0]),
        _table(PW_EDGES, pw_phis, pw_rows, rays, stderr[1]),
        float(particle_emissivity),
        float(wall_emissivity),
        source,
    )


def _check_fractions(name, values, high):
    phis = np.asarray(values, dtype=float)
    if phis.ndim != 1 or phis.size == 0 or np.any(np.diff(phis) <= 0) or phis[0] <= 0 or phis[-1] > high:
        raise DPHTError(f"{name} must increase strictly within (0, {high}]; got {phis.tolist()}")
    return phis


def _table(edges, phis, rows: list[Row], rays, target) -> RDFTable:
    return RDFTable(
        0.5 * (edges[1:] + edges[:-1]),
        phis,
        np.array([r.rdf for r in rows]),
        np.array([r.stderr for r in rows]),
        rays,
        samples=np.array([r.samples for r in rows]),
        binning_error=np.array([r.binning_error for r in rows]),
        stderr_target=target,
        min_samples=MIN_SAMPLES,
    )


def monotone_violations(table: RDFTable, n_sigma: float = 3.0):
    """(solid fraction, d1, d2) where the RDF rises from d1 to the next distance d2 by more than
    ``n_sigma`` combined standard errors. The RDF falls with distance except just past the
    shadowing dip at two diameters in dense beds (0.64: 9.1e-4 at 4.0 R, 1.1e-3 at 4.05 R), which
    is real."""
    rise = table.rdf[:, 1:] - table.rdf[:, :-1]
    noise = n_sigma * np.hypot(table.stderr[:, 1:], table.stderr[:, :-1])
    k, b = np.nonzero(rise > noise)
    phi, d = table.solid_fraction, table.distance
    return [(float(phi[a]), float(d[c]), float(d[c + 1])) for a, c in zip(k, b)]

