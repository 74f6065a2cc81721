"""The hand-over field: the temperature of the particles leaving one segment of a chain, mapped on
the tube's cross-section, and given to the particles of the next (docs/theory/chain.md).

The map is built from a :class:`Stream`, the record of the particles that crossed a segment's
outlet (their positions in the cross-section, temperatures, radii, and optionally the
temperatures of their shells), on a :class:`CrossSection` grid of ``rings`` equal-area rings and
``sectors`` equal sectors (1: axisymmetric). Each cell holds the *mixing-cup* temperature of what
crossed it: the temperature of the mean specific enthalpy of its samples weighted by the mass
they carry through the outlet (DPHT paper, Section 6: the outlet temperature a cup catching the
flow would read), ``w_i = r_i^3 f_i`` with ``f_i`` the sample's flux factor (1 for a particle
counted once per crossing; its axial velocity for the particles of a band taken at one time).
Enthalpies come from the receiving scene's enthalpy table (:mod:`dpht.closures.heat_capacity`), so
c_p(T) is mixed as energy, not as temperature.

Sampling is piecewise constant: a particle takes its cell's temperature (a cell without samples
takes the nearest cell's with samples, by the distance between cell centres). :func:`assign`
then corrects every particle's enthalpy by one shift ``delta`` (J/kg) so that the mass-weighted
mean enthalpy of the receiving particles equals the stream's mixing-cup enthalpy: energy is
conserved across the hand-over to round-off, and ``delta`` (with its size in kelvin) is reported.
It measures how differently the two sets of particles fill the cells (their packing, radii and
the grid's resolution), and is zero for a uniform field.

Means are taken as deviations from a reference enthalpy of the same set (the first sample's), so
a uniform field gives back its temperature exactly, bit for bit: a run handed a uniform field is
the run started at that temperature. Every kernel is sequential over particles in their given
order: the same inputs give the same field whatever the thread count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from dpht.closures.heat_capacity import EnthalpyTable, specific_heat_at
from dpht.errors import DPHTError


@dataclass(frozen=True)
class CrossSection:
    """The grid of the map: ``rings`` rings of equal area (thinner towards the wall, where the
    thermal boundary layer is) times ``sectors`` equal sectors from the +x axis, counter-clockwise,
    on a tube of ``radius`` (m) about the z axis (x = y = 0, as the geometry stage builds it)."""

    rings: int
    sectors: int
    radius: float  # m

    def __post_init__(self):
        if not (isinstance(self.rings, int) and self.rings >= 1 and isinstance(self.sectors, int) and self.sectors >= 1):
            raise DPHTError(f"cross-section grid: rings and sectors must be integers >= 1, got {self.rings}, {self.sectors}")
        if not self.radius > 0:
            raise DPHTError(f"cross-section grid: the tube radius must be > 0 m, got {self.radius!r}")

    @property
    def cells(self) -> int:
        return self.rings * self.sectors

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """Cell index (ring * sectors + sector) of every point (M, 2) m; -1 where not finite.
        Points beyond the radius fall in the outer ring."""
        xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
        return _cells(xy[:, 0].copy(), xy[:, 1].copy(), self.radius, self.rings, self.sectors)

    def centres(self) -> np.ndarray:
        """(cells, 2) m: each cell's centre (mid-area radius, mid angle) in x, y."""
        ring, sector = np.divmod(np.arange(self.cells), self.sectors)
        r = self.radius * np.sqrt((ring + 0.5) / self.rings)
        theta = 2 * np.pi * (sector + 0.5) / self.sectors
        return np.column_stack([r * np.cos(theta), r * np.sin(theta)])

    def ring_edges(self) -> np.ndarray:
        """(rings + 1,) m: the rings' radii, from the axis to the wall."""
        return self.radius * np.sqrt(np.arange(self.rings + 1) / self.rings)


@dataclass(frozen=True)
class Stream:
    """What crossed a segment's outlet: one sample per crossing particle (SI units).

    ``xy`` (N, 2) m in the cross-section, ``temperature`` (N,) K (float64: the run's enthalpies
    converted, not thermal.h5's float32 rows, or the energy is handed over to 1e-7 only), ``radius``
    (N,) m, ``flux`` (N,) the flux factor of each sample (None: 1, each counted once),
    ``shells`` (N, K) K the temperatures of resolved particles' nodes with ``shell_weight`` (K,)
    each node's share of a particle's mass (:class:`dpht.thermal.intraparticle.ShellGrid` ``weight``)."""

    xy: np.ndarray
    temperature: np.ndarray
    radius: np.ndarray
    flux: np.ndarray | None = None
    shells: np.ndarray | None = None
    shell_weight: np.ndarray | None = None

    def __post_init__(self):
        n = np.shape(self.temperature)[0] if np.ndim(self.temperature) == 1 else -1
        shapes = [np.shape(self.xy) == (n, 2), np.shape(self.radius) == (n,),
                  self.flux is None or np.shape(self.flux) == (n,)]  # fmt: skip
        if self.shells is not None:
            shapes += [self.shell_weight is not None and np.ndim(self.shells) == 2 and np.shape(self.shells)[0] == n
                       and np.shape(self.shell_weight) == (np.shape(self.shells)[1],)]  # fmt: skip
        if n < 1 or not all(shapes):
            raise DPHTError("hand-over stream: expected xy (N, 2), temperature (N,), radius (N,), flux (N,) or None, "
                            "shells (N, K) with shell_weight (K,) or None, N >= 1")  # fmt: skip
        for name in ("temperature", "radius"):
            values = np.asarray(getattr(self, name))
            if not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise DPHTError(f"hand-over stream: every {name} must be finite and > 0")
        if self.flux is not None and (not np.all(np.isfinite(self.flux)) or np.any(np.asarray(self.flux) < 0)):
            raise DPHTError("hand-over stream: every flux factor must be finite and >= 0")

    def weights(self) -> np.ndarray:
        """Each sample's share of the mass carried through the outlet, up to one factor: r^3 f."""
        r = np.asarray(self.radius, dtype=np.float64)
        w = r * r * r
        return w if self.flux is None else w * np.asarray(self.flux, dtype=np.float64)

    def channels(self) -> np.ndarray:
        """(N, 1 + K) K: the particle's mean temperature, then its nodes'."""
        T = np.asarray(self.temperature, dtype=np.float64)[:, None]
        return np.ascontiguousarray(T if self.shells is None else np.hstack([T, np.asarray(self.shells, dtype=np.float64)]))


@dataclass(frozen=True)
class Field:
    """The map (module docstring). ``temperature`` (cells, 1 + K) K: each cell's mixing-cup
    temperature of the particles' mean, then of each node (with ``shell_weight``, empty without
    shells); ``weight`` (cells,) the cell's share of the stream's mass flow (0: no sample, its
    temperatures those of the nearest cell with samples); ``count`` (cells,) samples;
    ``cup_temperature`` K the whole stream's mixing-cup temperature."""

    grid: CrossSection
    temperature: np.ndarray
    weight: np.ndarray
    count: np.ndarray
    cup_temperature: float
    shell_weight: np.ndarray

    @property
    def shells(self) -> int:
        """Nodes per particle in the map (0: uniform particles)."""
        return self.temperature.shape[1] - 1

    @property
    def filled(self) -> int:
        """Cells without a sample (their temperature taken from the nearest cell with samples)."""
        return int(np.count_nonzero(self.count == 0))

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """(M, 1 + K) K: the map's temperatures at points ``xy`` (M, 2) m (NaN where not finite)."""
        cells = self.grid.cell_of(xy)
        out = np.full((cells.size, self.temperature.shape[1]), np.nan)
        inside = cells >= 0
        out[inside] = self.temperature[cells[inside]]
        return out

    def cup_enthalpy(self, table: EnthalpyTable) -> float:
        """The stream's mixing-cup specific enthalpy (J/kg) in ``table``, from the cells."""
        h = table.enthalpy(self.temperature[:, 0])
        return _weighted_mean(h, self.weight, h[int(np.argmax(self.count > 0))])


def build(stream: Stream, grid: CrossSection, table: EnthalpyTable) -> Field:
    """The map of ``stream`` on ``grid``, mixing enthalpies of ``table`` (module docstring)."""
    T = stream.channels()
    h = table.enthalpy(T)
    w = stream.weights()
    cells = grid.cell_of(stream.xy)
    if np.any(cells < 0):
        raise DPHTError("hand-over stream: every sample needs a finite position in the cross-section")
    if not w.sum() > 0:
        raise DPHTError("hand-over stream: its samples carry no mass (every flux factor is 0)")
    total, deviation, first, uniform, count = _accumulate(cells, w, h, T, grid.cells)
    cell_h = first[0] + deviation / np.where(total > 0, total, 1.0)[:, None]
    cell_T = np.where(uniform, first[1], table.temperature(cell_h))
    cell_T = cell_T[_nearest_filled(grid.centres(), count)]
    cup_h = _weighted_mean(h[:, 0], w, h[0, 0])
    cup_T = float(T[0, 0]) if np.all(T[:, 0] == T[0, 0]) else float(table.temperature(cup_h))
    shell_weight = np.zeros(0) if stream.shells is None else np.asarray(stream.shell_weight, dtype=np.float64)
    return Field(grid, cell_T, total / total.sum(), count, cup_T, shell_weight)


@dataclass(frozen=True)
class Handed:
    """The field given to a set of particles (:func:`assign`): ``enthalpy`` (M, 1 + K) J/kg in the
    receiving table and ``temperature`` (M, 1 + K) K, the particle's mean then its nodes' (K = 0
    without shells), and the hand-over's books: the shift ``correction`` (J/kg) applied to every
    enthalpy, its size in kelvin at the stream's mixing-cup temperature, the ``residual`` (J/kg)
    left after it (round-off) and that relative to the map's enthalpy spread."""

    enthalpy: np.ndarray
    temperature: np.ndarray
    correction: float  # J/kg
    correction_K: float  # K
    residual: float  # J/kg
    relative_residual: float
    filled_cells: int

    def summary(self) -> dict:
        """The books as plain numbers (the thermal stage's summary)."""
        return {"correction_J_kg": self.correction, "correction_K": self.correction_K, "residual_J_kg": self.residual,
                "relative_residual": self.relative_residual, "filled_cells": self.filled_cells}  # fmt: skip


def assign(field: Field, xy: np.ndarray, radius, table: EnthalpyTable) -> Handed:
    """The field at the particles at ``xy`` (M, 2) m of ``radius`` (m, one or (M,)), their
    enthalpies shifted by one ``delta`` so that their mass-weighted mean enthalpy in ``table`` is
    the stream's mixing-cup enthalpy (module docstring). Every position must be finite."""
    sampled = field.sample(xy)
    if not np.all(np.isfinite(sampled)):
        raise DPHTError("hand-over: every receiving particle needs a finite position in the cross-section")
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (sampled.shape[0],))
    w = r * r * r
    target = field.cup_enthalpy(table)
    h = table.enthalpy(sampled)
    delta = target - _weighted_mean(h[:, 0], w, target)
    if delta != 0.0:  # else the temperatures stay exactly the field's
        h += delta
        sampled = table.temperature(h)
    residual = _weighted_mean(h[:, 0], w, target) - target
    spread = float(np.ptp(table.enthalpy(field.temperature[:, 0])))
    cp = specific_heat_at(field.cup_temperature, table.T0, table.dT, table.h)
    return Handed(h, sampled, float(delta), float(delta / cp), float(residual),
                  float(abs(residual) / spread) if spread > 0 else 0.0, field.filled)  # fmt: skip


def _weighted_mean(values: np.ndarray, weights: np.ndarray, reference: float) -> float:
    """sum(w v) / sum(w), as ``reference`` plus the weighted mean deviation from it (exactly
    ``reference`` when every value is): compensated sums, so the order of the values does not matter."""
    return float(reference + math.fsum(weights * (values - reference)) / math.fsum(weights))


def _nearest_filled(centres: np.ndarray, count: np.ndarray) -> np.ndarray:
    """For every cell, itself if it has samples, else the cell with samples nearest to its centre
    (the first of equals)."""
    filled = np.flatnonzero(count > 0)
    d2 = ((centres[:, None, :] - centres[None, filled, :]) ** 2).sum(axis=2)
    return np.where(count > 0, np.arange(count.size), filled[np.argmin(d2, axis=1)])


@nb.njit(cache=True)
def _cells(x, y, radius, rings, sectors):
    out = np.empty(x.size, dtype=np.int64)
    for i in range(x.size):
        if not (np.isfinite(x[i]) and np.isfinite(y[i])):
            out[i] = -1
            continue
        rho2 = (x[i] * x[i] + y[i] * y[i]) / (radius * radius)
        ring = min(int(rho2 * rings), rings - 1)  # equal area: ring k holds rho^2 in [k, k+1) / rings
        sector = 0
        if sectors > 1:
            theta = math.atan2(y[i], x[i])
            if theta < 0.0:
                theta += 2.0 * math.pi
            sector = min(int(theta / (2.0 * math.pi) * sectors), sectors - 1)
        out[i] = ring * sectors + sector
    return out


@nb.njit(cache=True)
def _accumulate(cells, w, h, T, n_cells):
    """Per cell and channel: the weight, the weighted sum of deviations from the cell's first
    sample's enthalpy, (the first sample's enthalpy, its temperature), whether every sample has
    that temperature, and the sample count. Sequential, in the samples' order."""
    n_channels = h.shape[1]
    total = np.zeros(n_cells)
    deviation = np.zeros((n_cells, n_channels))
    first = np.zeros((2, n_cells, n_channels))
    uniform = np.ones((n_cells, n_channels), dtype=np.bool_)
    count = np.zeros(n_cells, dtype=np.int64)
    for i in range(cells.size):
        c = cells[i]
        if count[c] == 0:
            for k in range(n_channels):
                first[0, c, k] = h[i, k]
                first[1, c, k] = T[i, k]
        count[c] += 1
        total[c] += w[i]
        for k in range(n_channels):
            deviation[c, k] += w[i] * (h[i, k] - first[0, c, k])
            if T[i, k] != first[1, c, k]:
                uniform[c, k] = False
    return total, deviation, first, uniform, count
