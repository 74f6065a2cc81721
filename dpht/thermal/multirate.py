"""Multirate explicit integration: each particle sub-steps at its own stable rate (registry name ``multirate``).

Global sub-stepping (:mod:`dpht.thermal.integrate`) makes every particle take the stiffest
particle's step. Here a frame of length dt is split into 2^L micro-steps, and each particle i gets a
power-of-two level, the smallest l_i with ``dt / 2^l_i * g_i <= m c_p,min`` (g_i its sum of
conductances at the frame's start); a pair takes the finer level of its two particles, a wall
contact its particle's. At micro-step k the pairs and contacts whose level's step starts there (level
>= L - trailing_zeros(k); all at k = 0) are *due*: each gets its flux ``F = dt/2^l G (T_j - T_i)``
(J), with G and the temperatures of that moment, added to one particle and removed from the other,
so each pair's heat over the frame is counted once per its own step and energy is conserved
exactly. A stiff particle and its partners are updated every fine micro-step, the rest of the bed
once per frame: the work is sum over pairs of 2^l_e instead of (pairs) x 2^L.

Stability and the maximum principle: within a micro-step particle i receives
``sum_due dt/2^l_e G_e (T_j - T_i)``, and every due pair has ``dt/2^l_e <= dt/2^l_i <= m c_p,min / g_i``,
so the weights sum to at most ``m c_p,min``: each micro-step is a convex combination of
temperatures, as in the explicit scheme. The sum is checked at every micro-step with the
conductances of that moment (they change with temperature); a particle that exceeds it has its
level raised and the frame is redone, so the guarantee does not rest on the frame-start estimate.
The scheme is first order (forward Euler at each pair's level). Its steady states are the
network's only to first order in the step, since pairs of different levels see the temperatures of
different moments of the frame (on the frozen bed of the hard-case suite: 0.8% of the temperature
range at a 1 s step, where some particles sub-step; none at 0.5 s, where all are on level 0); the
explicit and implicit integrators keep them exactly.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from dpht.closures.heat_capacity import temperature_at
from dpht.errors import DPHTError
from dpht.thermal import network
from dpht.thermal.integrate import Frame, Start, StepReport
from dpht.thermal.model import ThermalModel

_MAX_RETRIES = 8  # level raises per frame before giving up (each at least doubles the stiff particles' steps)


def levels_for(g: np.ndarray, capacity: float, dt: float) -> np.ndarray:
    """Smallest level l >= 0 per particle with ``dt / 2^l * g <= capacity``."""
    ratio = dt * g / capacity
    out = np.zeros(g.size, dtype=np.int64)
    stiff = ratio > 1.0
    out[stiff] = np.ceil(np.log2(ratio[stiff] * (1 + 1e-12))).astype(np.int64)
    return out


class Multirate(network.OnNetwork):
    """Power-of-two local sub-stepping over each frame, conservative pair by pair."""

    name = "multirate"

    def __init__(self, model: ThermalModel, options: dict | None = None):
        super().__init__(model)
        self.stats = {"micro_steps": 0, "pair_updates": 0, "retries": 0}

    def prepare(self, net: network.Network) -> None:
        self.q, self.g = np.empty(net.n), np.empty(net.n)

    def advance(self, frame: Frame, h: np.ndarray, dt: float, frame_number: int = 0, start: Start | None = None) -> StepReport:
        model, idx = self.model, frame.particles
        net, T0, heat, clamped = self.begin(frame, h, start)
        if dt == 0.0:
            network.element_heat(model, net, T0, 1.0, heat)
            return StepReport(0, heat, T0, self.name, {"clamped": clamped})
        network.rates(model, net, T0, self.q, self.g)
        capacity = model.mass * model.enthalpy.cp_min
        level = levels_for(self.g, capacity, dt)
        for retry in range(_MAX_RETRIES + 1):
            finest = int(level.max(initial=0))
            if 2**finest > model.max_substeps:
                stiffest = int(np.argmax(level))
                raise DPHTError(
                    f"frame {frame_number}: particle {int(idx[stiffest])} needs 2^{finest} = {2**finest} multirate "
                    f"micro-steps, more than thermal.max_substeps = {model.max_substeps}; raise it or use "
                    f"thermal.integrator: implicit"
                )  # fmt: skip
            h_sorted = h[idx]
            heat[:] = 0.0
            with network.threads_for(net.n):
                bad, updates = self._frame_steps(net, h_sorted, T0, level, dt, capacity, heat)
            if not bad.any():
                break
            self.stats["retries"] += 1
            level[bad] += 1
        else:
            raise DPHTError(f"frame {frame_number}: multirate levels did not settle after {_MAX_RETRIES} raises")
        h[idx] = h_sorted
        self.stats["micro_steps"] += 2**finest
        self.stats["pair_updates"] += updates
        return StepReport(2**finest, heat, T0, self.name,
                          {"finest_level": finest, "pair_updates": updates, "stiff_particles": int(np.count_nonzero(level)),
                           "clamped": clamped})  # fmt: skip

    def _frame_steps(self, net, h, T0, level, dt, capacity, heat):
        """All micro-steps of one frame on ``h`` (J/kg, frame order, in place); returns the
        particles whose convexity bound failed and the count of pair updates."""
        model = self.model
        finest = int(level.max(initial=0))
        pairs, contacts = net.pairs, net.contacts
        pair_level = np.maximum(level[pairs.first], level[pairs.second]) if pairs.first.size else np.zeros(0, np.int64)
        contact_level = level[contacts.particle]
        # Pairs and contacts by level, finest first: the due ones at any micro-step are a prefix.
        pair_order = np.argsort(-pair_level, kind="stable")
        contact_order = np.argsort(-contact_level, kind="stable")
        pairs, contacts = _take(pairs, pair_order), _take(contacts, contact_order)
        levels = Levels(pair_level[pair_order], contact_level[contact_order], dt / 2.0 ** np.arange(finest + 1))
        # Each particle's due entries (pair, sign) and contacts, finest first, as CSR rows.
        incidence = Incidence(*_incidence(net.n, pairs.first, pairs.second, contacts.particle))
        touch = level.copy()  # finest level of anything touching the particle
        if pairs.first.size:
            np.maximum.at(touch, pairs.first, levels.pair)
            np.maximum.at(touch, pairs.second, levels.pair)
        particle_order = np.argsort(-touch, kind="stable")
        pairs_due, contacts_due = _due(levels.pair, finest), _due(levels.contact, finest)
        particles_due = _due(touch[particle_order], finest)
        T = T0.copy()
        bad = np.zeros(net.n, dtype=np.bool_)
        table = model.enthalpy
        updates = 0
        for k in range(2**finest):
            lowest = 0 if k == 0 else finest - ((k & -k).bit_length() - 1)  # coarsest level due at k
            n_pairs, n_contacts, n_particles = pairs_due[lowest], contacts_due[lowest], particles_due[lowest]
            if k > 0:
                _temperatures(h, particle_order[:n_particles], T, *table.arrays)
            due = network.Network(net.n, _take(pairs, slice(n_pairs)), _take(contacts, slice(n_contacts)), net.rows)
            network.conductances(model, due, T)
            _apply(particle_order[:n_particles], lowest, incidence, levels, pairs, contacts, model.element_temperature, T, h,
                   1.0 / model.mass, capacity, bad)  # fmt: skip
            _wall_heat(due.contacts, levels, T, model.element_temperature, 1.0 / dt, heat)
            updates += n_pairs
        return bad, updates

    def cost(self, stiffness) -> float:
        """Rate-evaluation equivalents: listing the pairs (~1.5, not when the frame is reused), then
        each pair once per its own step, at about the cost of an explicit evaluation per pair
        update (the list saves the search; the micro-steps' bookkeeping costs it back). Never below
        explicit's one evaluation, so a frame without stiff particles stays explicit."""
        return (0.0 if stiffness.reused else 1.5) + stiffness.multirate_work


class Levels(NamedTuple):
    """The frame's levels: of its pairs and wall contacts (sorted finest first), and each level's step."""

    pair: np.ndarray  # (E,) int64
    contact: np.ndarray  # (W,) int64
    step: np.ndarray  # (finest + 1,) s, dt / 2^l for level l


class Incidence(NamedTuple):
    """Each particle's pairs and wall contacts as CSR rows, in their (finest first) order."""

    pair_start: np.ndarray  # (n + 1,) int64
    pair: np.ndarray  # int64, the pairs of each row
    contact_start: np.ndarray  # (n + 1,) int64
    contact: np.ndarray  # int64, the contacts of each row


def _take(record, rows):
    """A :class:`dpht.thermal.network.Pairs` or ``Contacts`` at ``rows`` (an index array: copies; a slice: views)."""
    return type(record)(*(a[rows] for a in record))


def _due(levels: np.ndarray, finest: int) -> np.ndarray:
    """For each level l = 0..finest, how many of ``levels`` (sorted finest first) are >= l."""
    return np.searchsorted(-levels, -np.arange(finest + 1), side="right")


@nb.njit(cache=True)
def _incidence(n, first, second, contact_i):
    """Each particle's pairs and contacts as CSR rows, in their (finest first) order."""
    row_start, cursor = network.row_offsets(n, first, second, False)
    row_pair = np.empty(row_start[n], dtype=np.int64)
    for e in range(first.size):  # pairs are finest first, so each row is too
        row_pair[cursor[first[e]]] = e
        cursor[first[e]] += 1
        row_pair[cursor[second[e]]] = e
        cursor[second[e]] += 1
    contact_start = np.zeros(n + 1, dtype=np.int64)
    for w in range(contact_i.size):
        contact_start[contact_i[w] + 1] += 1
    for i in range(n):
        contact_start[i + 1] += contact_start[i]
    row_contact = np.empty(contact_i.size, dtype=np.int64)
    cursor = contact_start[:-1].copy()
    for w in range(contact_i.size):
        row_contact[cursor[contact_i[w]]] = w
        cursor[contact_i[w]] += 1
    return row_start, row_pair, contact_start, row_contact


@nb.njit(cache=True, parallel=True)
def _temperatures(h, rows, T, T0, dT, table_h, guide, guide_step):
    for t in nb.prange(rows.size):
        i = rows[t]
        T[i] = temperature_at(h[i], T0, dT, table_h, guide, guide_step)


@nb.njit(cache=True, parallel=True)
def _apply(particles, lowest, incidence, levels, pairs, contacts, element_T, T, h, inv_mass, capacity, bad):
    """One micro-step: every touched particle sums the heat of its due pairs and contacts (fixed
    order, finest first) and checks that their weights sum to at most its capacity. The records'
    arrays are taken out before the loop (see :mod:`dpht.thermal.kernels` on records in parallel loops)."""
    row_start, row_pair, contact_start, row_contact = incidence.pair_start, incidence.pair, incidence.contact_start, incidence.contact
    pair_level, contact_level, step_of = levels.pair, levels.contact, levels.step
    first, second, G, contact_e, Gw = pairs.first, pairs.second, pairs.G, contacts.element, contacts.G
    for t in nb.prange(particles.size):
        i = particles[t]
        Ti = T[i]
        heat = 0.0
        weight = 0.0
        for k in range(row_start[i], row_start[i + 1]):
            e = row_pair[k]
            if pair_level[e] < lowest:
                break
            j = second[e] if first[e] == i else first[e]
            w = step_of[pair_level[e]] * G[e]
            heat += w * (T[j] - Ti)
            weight += w
        for k in range(contact_start[i], contact_start[i + 1]):
            c = row_contact[k]
            if contact_level[c] < lowest:
                break
            w = step_of[contact_level[c]] * network.contact_sum(Gw, c)
            heat += w * (element_T[contact_e[c]] - Ti)
            weight += w
        h[i] += heat * inv_mass
        if weight > capacity * (1.0 + 1e-12):
            bad[i] = True


@nb.njit(cache=True)
def _wall_heat(due, levels, T, element_T, inv_dt, heat):
    """Mean heat (W) per element and PW mode over the frame of the ``due`` contacts, in order (serial)."""
    contact_i, contact_e, Gw, contact_level, step_of = due.particle, due.element, due.G, levels.contact, levels.step
    for c in range(contact_i.size):
        e = contact_e[c]
        f = step_of[contact_level[c]] * inv_dt * (element_T[e] - T[contact_i[c]])
        for m in range(Gw.shape[1]):
            heat[e, m] += f * Gw[c, m]
