"""Radiation distribution factor (RDF) tables: the file format, loading and interpolation grids.

An RDF table gives, for a particle inside a bed of solid fraction ``phi``, the fraction of the rays
it emits that are absorbed by another particle at centre distance ``d`` (particle-particle, "pp") or
by the wall at centre-to-wall distance ``d`` (particle-wall, "pw"), after any number of diffuse
reflections (DPHT paper, Sections 3.6-3.7, Eqs. 25-26). Distances are stored in particle radii.

File format (HDF5), one file per particle emissivity and wall emissivity::

    /            attrs: format = "dpht-rdf-1", particle_emissivity, wall_emissivity, source
    /pp/distance         (n_d,)        centre-centre distance / R, strictly increasing
    /pp/solid_fraction   (n_phi,)      strictly increasing
    /pp/rdf              (n_phi, n_d)  RDF, dimensionless
    /pp/stderr           (n_phi, n_d)  one standard error of each entry (0 where exact)
    /pp                  attrs: rays (rays emitted per particle and solid fraction)
    /pw/...              the same with centre-to-wall distance / R
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.errors import DPHTError
from dpht.util.h5 import open_checked

FORMAT = "dpht-rdf-1"


@dataclass(frozen=True)
class RDFTable:
    """RDF versus distance (in radii) and solid fraction, for one kind ("pp" or "pw")."""

    distance: np.ndarray
    solid_fraction: np.ndarray
    rdf: np.ndarray
    stderr: np.ndarray
    rays: int = 0

    def __post_init__(self):
        d, phi, v = self.distance, self.solid_fraction, self.rdf
        if d.ndim != 1 or phi.ndim != 1 or v.shape != (phi.size, d.size):
            raise DPHTError(
                f"RDF table shapes disagree: distance {d.shape}, solid_fraction {phi.shape}, "
                f"rdf {v.shape} (expected (n_phi, n_d))"
            )
        if np.any(np.diff(d) <= 0) or np.any(np.diff(phi) <= 0):
            raise DPHTError("RDF table: distance and solid_fraction must be strictly increasing")
        if self.stderr.shape != v.shape:
            raise DPHTError(f"RDF table: stderr shape {self.stderr.shape} != rdf shape {v.shape}")

    def at_solid_fraction(self, phi: float, n_distance: int = 256):
        """RDF versus distance at solid fraction ``phi`` on a uniform grid: ``(d0, dd, values)``.

        Linear in ``phi`` between the tabulated solid fractions; ``phi`` outside them is an error.
        """
        lo, hi = self.solid_fraction[0], self.solid_fraction[-1]
        if not lo <= phi <= hi:
            raise DPHTError(f"solid fraction {phi} is outside the RDF table's range {lo}-{hi}")
        d = np.linspace(self.distance[0], self.distance[-1], n_distance)
        column = np.array([np.interp(phi, self.solid_fraction, self.rdf[:, k]) for k in range(self.distance.size)])
        return d[0], d[1] - d[0], np.interp(d, self.distance, column)


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
            g.attrs["rays"] = table.rays
            for name in ("distance", "solid_fraction", "rdf", "stderr"):
                g.create_dataset(name, data=np.asarray(getattr(table, name), dtype=np.float64))


def load(path: str | Path) -> RDFTables:
    path = Path(path)
    with open_checked(path, FORMAT, "an RDF table") as f:
        kinds = {}
        for kind in ("pp", "pw"):
            if kind not in f:
                raise DPHTError(f"{path}: missing group /{kind}")
            g = f[kind]
            kinds[kind] = RDFTable(
                *(np.asarray(g[name][...], dtype=np.float64) for name in ("distance", "solid_fraction", "rdf", "stderr")),
                rays=int(g.attrs.get("rays", 0)),
            )
        return RDFTables(
            kinds["pp"],
            kinds["pw"],
            float(f.attrs["particle_emissivity"]),
            float(f.attrs["wall_emissivity"]),
            str(f.attrs.get("source", "")),
        )


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
        return RDFTable(
            base.distance,
            base.solid_fraction,
            sum(weight * t.rdf for weight, t in parts),
            np.sqrt(sum((weight * t.stderr) ** 2 for weight, t in parts)),
            rays=min(t.rays for _, t in parts),
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
