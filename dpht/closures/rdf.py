"""Radiation distribution factor (RDF) tables: the file format, loading and interpolation grids.

An RDF table gives, for a particle inside a bed of solid fraction ``phi``, the fraction of the rays
it emits that are absorbed by another particle at centre distance ``d`` (particle-particle, "pp") or
by the wall at centre-to-wall distance ``d`` (particle-wall, "pw"), after any number of diffuse
reflections (DPHT paper, Sections 3.6-3.7, Eqs. 25-26). Distances are stored in particle radii.

Which solid fraction indexes a table is part of the format: the particle-particle table is read
at the *bulk* solid fraction, the particle-wall table at the *near-wall* one, the solid fraction
within one particle diameter of the wall (``SOLID_FRACTION_REGIONS``; dpht.dem.report measures both
in the DEM run the same way), and each group says so in its ``solid_fraction_region`` attribute.

File format (HDF5), one file per particle emissivity and wall emissivity::

    /            attrs: format = "dpht-rdf-2", particle_emissivity, wall_emissivity, source
    /pp/distance         (n_d,)        centre-centre distance / R, strictly increasing (bin centres)
    /pp/solid_fraction   (n_phi,)      strictly increasing
    /pp/rdf              (n_phi, n_d)  RDF, dimensionless
    /pp/stderr           (n_phi, n_d)  one standard error of each entry (0 where exact)
    /pp/samples          (n_phi, n_d)  emitting particles behind each entry (optional: 0 = exact)
    /pp/binning_error    (n_phi, n_d)  estimated error from the bin width (optional)
    /pp                  attrs: rays (rays emitted per particle), solid_fraction_region = "bulk",
                                stderr_target, min_samples (what every built entry reaches)
    /pw/...              the same with centre-to-wall distance / R; solid_fraction_region = "near_wall"

Format "dpht-rdf-1" files (PW tables indexed by the bulk solid fraction of their slab, gaps
interpolated) are refused: rebuild them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.errors import DPHTError
from dpht.util.h5 import check_values, open_checked

FORMAT = "dpht-rdf-2"
SOLID_FRACTION_REGIONS = {
    "pp": ("bulk", "solid fraction of the bed farther than two particle diameters from any wall"),
    "pw": ("near_wall", "solid fraction within one particle diameter of the wall (the band 0 < d_wall < 2 R)"),
}
_ARRAYS = ("distance", "solid_fraction", "rdf", "stderr")
_OPTIONAL = ("samples", "binning_error")


@dataclass(frozen=True)
class RDFTable:
    """RDF versus distance (in radii) and solid fraction, for one kind ("pp" or "pw")."""

    distance: np.ndarray
    solid_fraction: np.ndarray
    rdf: np.ndarray
    stderr: np.ndarray
    rays: int = 0
    samples: np.ndarray | None = None  # emitters behind each entry
    binning_error: np.ndarray | None = None
    stderr_target: float = 0.0  # every built entry's stderr is at most this (0: not stated)
    min_samples: int = 0  # and comes from at least this many emitters

    def __post_init__(self):
        d, phi, v = self.distance, self.solid_fraction, self.rdf
        if d.ndim != 1 or phi.ndim != 1 or v.shape != (phi.size, d.size):
            raise DPHTError(
                f"RDF table shapes disagree: distance {d.shape}, solid_fraction {phi.shape}, "
                f"rdf {v.shape} (expected (n_phi, n_d))"
            )
        if np.any(np.diff(d) <= 0) or np.any(np.diff(phi) <= 0):
            raise DPHTError("RDF table: distance and solid_fraction must be strictly increasing")
        for name in ("stderr", *_OPTIONAL):
            value = getattr(self, name)
            if value is not None and value.shape != v.shape:
                raise DPHTError(f"RDF table: {name} shape {value.shape} != rdf shape {v.shape}")

    def at_solid_fraction(self, phi: float, n_distance: int | None = None):
        """RDF versus distance at solid fraction ``phi`` on a uniform grid: ``(d0, dd, values)``.

        Linear in ``phi`` between the tabulated solid fractions; within :data:`SOLID_FRACTION_MARGIN`
        outside them the nearest edge's, further out an error. The default grid has four points per
        narrowest distance bin, so resampling the piecewise linear table changes it only within a
        quarter of that bin of its nodes.
        """
        lo, hi = self.solid_fraction[0], self.solid_fraction[-1]
        if not covers(self.solid_fraction, phi):
            raise DPHTError(f"solid fraction {phi} is outside the RDF table's range {lo}-{hi}")
        phi = min(max(phi, lo), hi)
        if n_distance is None:
            span = self.distance[-1] - self.distance[0]
            n_distance = int(np.ceil(4 * span / np.diff(self.distance).min())) + 1 if self.distance.size > 1 else 1
        d = np.linspace(self.distance[0], self.distance[-1], n_distance)
        column = np.array([np.interp(phi, self.solid_fraction, self.rdf[:, k]) for k in range(self.distance.size)])
        return d[0], d[1] - d[0], np.interp(d, self.distance, column)


# A measured solid fraction this far outside a table's solid fractions is looked up at its edge.
# The DEM measures a band's solid fraction to about this: the tiny tube's near-wall band gave 0.5539
# after a resumed (not bit-exact) DEM run, below 0.55 uninterrupted; and the shipped PW factors
# change by 1.4% per 0.01 at their edge (0.51 -> 0.55), a fraction of a percent of the wall heat.
SOLID_FRACTION_MARGIN = 0.01


def covers(solid_fractions, phi: float) -> bool:
    """Whether a table of ``solid_fractions`` (increasing) can be read at ``phi``: within them, or
    at most :data:`SOLID_FRACTION_MARGIN` outside (read at the edge)."""
    return solid_fractions[0] - SOLID_FRACTION_MARGIN <= phi <= solid_fractions[-1] + SOLID_FRACTION_MARGIN


@dataclass(frozen=True)
class RDFTables:
    """Particle-particle and particle-wall RDF tables for one emissivity pair."""

    pp: RDFTable
    pw: RDFTable
    particle_emissivity: float
    wall_emissivity: float
    source: str = ""


def save(path: str | Path, tables: RDFTables) -> None:
    with h5py.File(path, "w") as f:
        f.attrs.update(
            format=FORMAT,
            particle_emissivity=tables.particle_emissivity,
            wall_emissivity=tables.wall_emissivity,
            source=tables.source,
        )
        for kind in ("pp", "pw"):
            table: RDFTable = getattr(tables, kind)
            g = f.create_group(kind)
            region, meaning = SOLID_FRACTION_REGIONS[kind]
            g.attrs.update(
                rays=table.rays,
                solid_fraction_region=region,
                solid_fraction_meaning=meaning,
                stderr_target=table.stderr_target,
                min_samples=table.min_samples,
            )
            for name in _ARRAYS:
                g.create_dataset(name, data=np.asarray(getattr(table, name), dtype=np.float64))
            if table.samples is not None:
                g.create_dataset("samples", data=np.asarray(table.samples, dtype=np.int64))
            if table.binning_error is not None:
                g.create_dataset("binning_error", data=np.asarray(table.binning_error, dtype=np.float64))


def load(path: str | Path) -> RDFTables:
    """Read an RDF table file; a file of another format, or whose groups do not say that they are
    indexed by the solid fraction this format reads them with, raises DPHTError naming it."""
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            old = f.attrs.get("format") == "dpht-rdf-1"
    except OSError:
        old = False  # open_checked names the problem
    if old:
        raise DPHTError(
            f"{path}: an RDF table of the old format dpht-rdf-1, whose particle-wall table is indexed by the "
            f"bulk solid fraction of its slab (the thermal stage reads it at the near-wall one) and has "
            f"interpolated gaps; rebuild it (delete it and rerun the workflow's rdf_table rule)"
        )
    with open_checked(path, FORMAT, "an RDF table") as f:
        kinds = {}
        for kind in ("pp", "pw"):
            if kind not in f:
                raise DPHTError(f"{path}: missing group /{kind}")
            g = f[kind]
            region = g.attrs.get("solid_fraction_region")
            if region != SOLID_FRACTION_REGIONS[kind][0]:
                raise DPHTError(
                    f"{path}: /{kind} attribute solid_fraction_region = {region!r}; expected "
                    f"{SOLID_FRACTION_REGIONS[kind][0]!r} ({SOLID_FRACTION_REGIONS[kind][1]})"
                )
            optional = {name: g[name][...] for name in _OPTIONAL if name in g}
            _check(path, kind, g)
            kinds[kind] = RDFTable(
                *(np.asarray(g[name][...], dtype=np.float64) for name in _ARRAYS),
                rays=int(g.attrs.get("rays", 0)),
                samples=optional.get("samples"),
                binning_error=optional.get("binning_error"),
                stderr_target=float(g.attrs.get("stderr_target", 0.0)),
                min_samples=int(g.attrs.get("min_samples", 0)),
            )
        return RDFTables(
            kinds["pp"],
            kinds["pw"],
            float(f.attrs["particle_emissivity"]),
            float(f.attrs["wall_emissivity"]),
            str(f.attrs.get("source", "")),
        )


def _check(path: Path, kind: str, group) -> None:
    """Every dataset of table ``kind`` in range (an RDF is a fraction of the emitted radiation)."""
    for name in (*_ARRAYS, *_OPTIONAL):
        if name not in group:
            if name in _ARRAYS:
                raise DPHTError(f"{path}: missing dataset /{kind}/{name}")
            continue
        limits = {"distance": dict(low=0.0, increasing=True, what="centre distances in radii"),
                  "solid_fraction": dict(low=0.0, high=1.0, increasing=True, what="solid fractions"),
                  "rdf": dict(low=0.0, high=1.0, what="radiation distribution factors"),
                  "stderr": dict(low=0.0, what="standard errors"), "samples": dict(low=0.0, what="emitter counts"),
                  "binning_error": dict(low=0.0, what="binning errors")}[name]  # fmt: skip
        check_values(path, f"/{kind}/{name}", group[name][...], **limits)


def for_emissivities(tables: list[RDFTables], particle_emissivity: float, wall_emissivity: float) -> RDFTables:
    """RDF tables at the given emissivities, linear between built tables (bilinear on a grid).

    ``tables`` must share their distance and solid-fraction grids and cover the emissivities: a
    grid of particle x wall emissivities (one or more of each). The standard errors combine as for
    a weighted sum of independent estimates.
    """
    if not tables:
        raise DPHTError("no RDF tables given")
    eps_p = sorted({t.particle_emissivity for t in tables})
    eps_w = sorted({t.wall_emissivity for t in tables})
    by_pair = {(t.particle_emissivity, t.wall_emissivity): t for t in tables}
    missing = [(p, w) for p in eps_p for w in eps_w if (p, w) not in by_pair]
    if missing:
        raise DPHTError(f"RDF tables must form a grid of emissivities; missing (particle, wall) = {missing}")
    weights = {}
    for (p, wp), (w, ww) in _product(_bracket(eps_p, particle_emissivity, "particle"), _bracket(eps_w, wall_emissivity, "wall")):
        weights[(p, w)] = weights.get((p, w), 0.0) + wp * ww
    first = tables[0]
    for table in tables[1:]:
        for kind in ("pp", "pw"):
            a, b = getattr(first, kind), getattr(table, kind)
            if not (np.array_equal(a.distance, b.distance) and np.array_equal(a.solid_fraction, b.solid_fraction)):
                raise DPHTError("RDF tables to interpolate must share their distance and solid-fraction grids")

    def mix(kind):
        parts = [(weight, getattr(by_pair[pair], kind)) for pair, weight in weights.items() if weight > 0]
        base = parts[0][1]
        known = all(t.samples is not None and t.binning_error is not None for _, t in parts)
        return RDFTable(
            base.distance,
            base.solid_fraction,
            sum(weight * t.rdf for weight, t in parts),
            np.sqrt(sum((weight * t.stderr) ** 2 for weight, t in parts)),
            rays=min(t.rays for _, t in parts),
            # Binning errors are systematic: they add with the weights.
            samples=np.min([t.samples for _, t in parts], axis=0) if known else None,
            binning_error=sum(weight * t.binning_error for weight, t in parts) if known else None,
            stderr_target=max(t.stderr_target for _, t in parts),
            min_samples=min(t.min_samples for _, t in parts),
        )

    return RDFTables(mix("pp"), mix("pw"), particle_emissivity, wall_emissivity, source=f"interpolated from {sorted(weights)}")


def _bracket(values: list[float], x: float, name: str) -> list[tuple[float, float]]:
    """(value, weight) pairs of linear interpolation at x among sorted ``values``."""
    if not values[0] - 1e-12 <= x <= values[-1] + 1e-12:
        raise DPHTError(f"{name} emissivity {x} is outside the built RDF tables ({values[0]}-{values[-1]})")
    if len(values) == 1:
        return [(values[0], 1.0)]
    k = min(max(int(np.searchsorted(values, x)) - 1, 0), len(values) - 2)
    f = (x - values[k]) / (values[k + 1] - values[k])
    return [(values[k], 1.0 - f), (values[k + 1], f)]


def _product(a, b):
    return [(x, y) for x in a for y in b]
