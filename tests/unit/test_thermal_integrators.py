"""The time integrators (dpht.thermal.integrators): the registry against the schema, explicit kept
bit-identical, auto's choice, TR-BDF2's maximum principle, thread-count determinism, multirate's
local work, the frozen bed through the stage, clamped look-ups, resume from a checkpoint. The
measured orders and the hard cases are verification cases (dpht/verification/cases/stability.py),
run by tests/unit/test_verification.py."""

import dataclasses
import json
import logging
import math

import h5py
import numba as nb
import numpy as np
import pytest
import scipy.sparse as sparse
import yaml

from dpht import config
from dpht.closures import conductance, contact, htc
from dpht.dem.dumps import DumpFrame, write_positions
from dpht.errors import ConfigError
from dpht.thermal import implicit, integrate, integrators, intraparticle, model as thermal_model, neighbors, network, stage
from dpht.thermal.modes import NAMES
from dpht.verification import reference, scenes
from dpht.verification.cases import stability
from dpht.geometry.walls import save_walls

R = scenes.RADIUS
CONDUCTION = stability.CONDUCTION


def test_schema_and_config_list_the_registry():
    thermal = config.schema()["properties"]["thermal"]["properties"]
    assert thermal["integrator"]["enum"] == list(integrators.CHOICES) and thermal["integrator"]["default"] == "auto"
    options = thermal["implicit"]["properties"]
    assert options["scheme"]["enum"] == list(implicit.SCHEMES)
    assert options["preconditioner"]["enum"] == list(implicit.PRECONDITIONERS)
    assert {k: options[k]["default"] for k in implicit.DEFAULTS} == implicit.DEFAULTS
    text = (config.SCHEMA_PATH.parent.parent.parent / "config" / "config.yaml").read_text()
    cfg = yaml.safe_load(text)
    assert cfg["thermal"]["integrator"] == "auto" and all(name in text for name in integrators.CHOICES)
    with pytest.raises(Exception, match="integrator"):
        integrators.create("implicitt", None)


def cluster_model(modes=CONDUCTION, n=300, seed=4, wall=600.0, **particles):
    s = scenes.spec(modes, walls={"hot": {"temperature": wall}})
    s["particles"].update(particles)
    model = scenes.build_model(s, scenes.plane_walls())
    positions = scenes.random_cluster(n=n, seed=seed)
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    h0 = model.enthalpy.enthalpy(np.random.default_rng(seed).uniform(300, 500, n))
    return model, frame, h0


def test_explicit_and_auto_on_a_mild_frame_are_bit_identical_to_the_explicit_function():
    model, frame, h0 = cluster_model()
    direct, registered, auto = h0.copy(), h0.copy(), h0.copy()
    rates = integrate.Rates.for_frame(model, frame)
    chosen = integrators.create("auto", model)
    for _ in range(3):
        integrate.advance(model, frame, direct, 0.05, rates)
        integrators.create("explicit", model).advance(frame, registered, 0.05)
        report = chosen.advance(frame, auto, 0.05)
        assert report.integrator == "explicit"
    assert np.array_equal(direct, registered) and np.array_equal(direct, auto)


def test_auto_picks_implicit_for_a_stiff_frame_and_says_why(caplog):
    model, frame, h0 = cluster_model()
    chosen = integrators.create("auto", model)
    with caplog.at_level(logging.INFO, logger="dpht"):
        report = chosen.advance(frame, h0.copy(), 500.0, frame_number=3)
    assert report.integrator == "implicit"
    decision = chosen.decisions[0]
    assert decision["frame"] == 3 and decision["largest_ratio"] > 100 and decision["integrator"] == "implicit"
    assert min(decision["estimated_cost"], key=decision["estimated_cost"].get) == "implicit"
    assert "auto: implicit from frame 3" in caplog.text and "largest" in caplog.text


def one_particle_at_a_wall(z):
    """A particle at 300 K touching a 600 K wall with dt G / (m c_p) = z: its temperature after one step."""
    s = scenes.spec(["pw_contact"], walls={"hot": {"temperature": 600.0}})
    model = scenes.build_model(s, scenes.plane_walls())
    p, w = s["particles"], s["wall"]
    d = 0.99 * R
    softening = contact.c_pw(p["poisson_ratio"], p["youngs_modulus_real"], p["youngs_modulus_dem"],
                             w["poisson_ratio"], w["youngs_modulus_real"], w["youngs_modulus_dem"])  # fmt: skip
    G = contact.pw_conductivity(p["conductivity"], w["conductivity"]) * softening * math.sqrt(R**2 - d**2)
    dt = z * model.mass * p["specific_heat"] / G
    frame = integrate.prepare_frame(model, np.array([[0.001, 0.0013, d]]), None, None, (False,) * 3)
    out = {}
    for scheme in implicit.SCHEMES:
        h = model.enthalpy.enthalpy(np.array([300.0]))
        implicit.Implicit(model, {"scheme": scheme}).advance(frame, h, dt)
        out[scheme] = float(model.enthalpy.temperature(h)[0])
    return out


def tr_bdf2_amplification(z):
    g = implicit.GAMMA
    stage = (1 - g * z / 2) / (1 + g * z / 2)
    return (stage / (g * (2 - g)) - (1 - g) ** 2 / (g * (2 - g))) / (1 + (1 - g) / (2 - g) * z)


@pytest.mark.parametrize("z", [0.5, 2.0, 1 + math.sqrt(2) - 1e-3, 4.0, 10.0])  # beyond ~20 the stage leaves the enthalpy table
def test_backward_euler_keeps_the_maximum_principle_and_tr_bdf2_only_up_to_one_plus_sqrt2(z):
    T = one_particle_at_a_wall(z)
    assert 300.0 <= T["backward_euler"] <= 600.0
    assert T["backward_euler"] == pytest.approx(600.0 - 300.0 / (1 + z), rel=1e-9)
    excess = 300.0 * tr_bdf2_amplification(z)  # 600 - T: negative means beyond the wall temperature
    assert 600.0 - T["tr_bdf2"] == pytest.approx(excess, rel=1e-6, abs=1e-6)
    if z <= 1 + math.sqrt(2):
        assert T["tr_bdf2"] <= 600.0 + 1e-9
    else:
        assert T["tr_bdf2"] > 600.0 + 1e-3  # overshoots the wall: not a maximum principle scheme
    assert tr_bdf2_amplification(10.0) == pytest.approx(-0.20, abs=0.01)


def radiating_bed(shape=(6, 6, 4), periodic=False):
    """A jittered lattice with all six modes between a 1,000 K and a 300 K wall (periodic across x
    and y when asked, the box the lattice's period)."""
    positions, height = scenes.lattice_bed(shape, seed=3)
    s = scenes.spec(list(NAMES), walls={"hot": {"temperature": 1000.0}, "cold": {"temperature": 300.0}},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    model = scenes.build_model(s, scenes.slab_walls(height, half=0.01), scenes.synthetic_rdf())
    lo, hi = np.zeros(3), np.array([shape[0] * 1.98 * R, shape[1] * 1.98 * R, height])
    frame = integrate.prepare_frame(model, positions, lo, hi, (periodic, periodic, False))
    return model, frame


def test_the_network_holds_each_pair_once_in_the_order_of_the_upper_triangle():
    """Through periodic boundaries the traversal lists pairs with first > second; the network
    renumbers them row by row of the matrix's upper triangle, and its CSR matrix is the graph
    Laplacian of the traversal's pairs (built independently by scipy)."""
    model, frame = radiating_bed((9, 9, 3), periodic=True)
    first, second, r2 = neighbors.pair_list(frame.cells, model.pair_cutoff)
    assert np.any(first > second)
    net = network.assemble(model, frame)
    pairs = net.pairs
    assert np.all(pairs.first < pairs.second) and np.all(np.diff(pairs.first * net.n + pairs.second) >= 0)

    def conductance(a, b, r2):  # distinct per pair
        return 1.0 + np.minimum(a, b) + 1e-4 * np.maximum(a, b) + r2 / R**2

    pairs.G[:], net.contacts.G[:] = conductance(pairs.first, pairs.second, pairs.r2), 0.0
    matrix, q = network.Matrix(net), np.empty(net.n)
    matrix.fill(model, np.zeros(net.n), np.zeros(net.n), 1.0, q)
    G = conductance(first, second, r2)
    off = sparse.coo_matrix((np.concatenate([G, G]), (np.concatenate([first, second]), np.concatenate([second, first]))),
                            shape=(net.n, net.n)).toarray()  # fmt: skip
    assert np.allclose(matrix.csr.toarray(), np.diag(off.sum(axis=1)) - off, rtol=1e-14, atol=0.0)


def against_reference(model, frame, positions, walls, T):
    """Largest deviation of the explicit kernel's and of the network's heat rates (W) from the
    brute-force reference's (:mod:`dpht.verification.reference`: its own physics, in numpy),
    relative to the largest reference rate; and the largest difference between the two."""
    Tf = T[frame.particles]
    rates = integrate.Rates.for_frame(model, frame)
    integrate.evaluate(model, frame, Tf, rates)
    net = network.assemble(model, frame)
    network.conductances(model, net, Tf)
    q_net = np.empty(net.n)
    network.rates(model, net, Tf, q_net, np.empty(net.n))
    q_ref = reference.heat_rates(model, positions, T, walls)[0][frame.particles]
    scale = np.abs(q_ref).max()
    return np.abs(rates.q - q_ref).max() / scale, np.abs(q_net - q_ref).max() / scale, np.abs(rates.q - q_net).max() / scale


def test_the_explicit_kernel_and_the_network_match_the_brute_force_reference():
    """All six modes: both integrator paths, the explicit kernel and the implicit and multirate
    integrators' network, against the reference."""
    model, frame = radiating_bed()
    positions, height = scenes.lattice_bed((6, 6, 4), seed=3)
    T = np.random.default_rng(4).uniform(300.0, 1000.0, len(positions))
    explicit, net, between = against_reference(model, frame, positions, scenes.slab_walls(height, half=0.01), T)
    assert explicit <= 1e-10 and net <= 1e-10 and between <= 1e-12


@nb.njit(**conductance.PIECE)
def contact_two_percent_high(r2, T_mean, side, own, k_solid):
    G, clamped = conductance.pp_contact_corrected(r2, T_mean, side, own, k_solid)
    return 1.02 * G, clamped


def test_a_two_percent_error_in_the_shared_pair_conductance_is_caught_by_the_reference(monkeypatch):
    """pp_contact's closure 2% high: the explicit kernel and the network still agree (they share the
    one pair conductance, so comparing them cannot see it), and the reference of the test above
    catches it in both, far beyond its tolerance."""
    wrong = conductance.PP_CONTACT._replace(conductance=contact_two_percent_high)
    monkeypatch.setattr(conductance, "PP_CONTACT", wrong)
    model, frame = radiating_bed()
    assert model.laws["pp_contact"] is wrong
    positions, height = scenes.lattice_bed((6, 6, 4), seed=3)
    T = np.random.default_rng(4).uniform(300.0, 1000.0, len(positions))
    explicit, net, between = against_reference(model, frame, positions, scenes.slab_walls(height, half=0.01), T)
    assert between <= 1e-12
    assert explicit > 1e-3 and net > 1e-3


def test_newton_matrix_is_the_jacobian_of_the_step_residual():
    """With the conductances' slopes, the iteration matrix is the Jacobian of the backward Euler
    residual m h(T) - c dt q(T) (radiation, k(T), the gas gap's temperature dependence, c_p(T), pairs
    and wall contacts), column by column against central differences."""
    model, frame = radiating_bed((4, 4, 3))
    integrator = implicit.Implicit(model)
    integrator.network(frame)
    T = np.random.default_rng(1).uniform(400.0, 900.0, frame.particles.size)
    c_dt = 20.0

    def residual(T):
        integrator._matrix_at(T, c_dt)
        return model.mass * integrator.h_T - c_dt * integrator.q

    integrator._matrix_at(T, c_dt, newton=True)
    jacobian = integrator.matrix.csr.toarray()
    differences = np.empty_like(jacobian)
    for k in range(T.size):
        up, down = T.copy(), T.copy()
        up[k] += 1e-3
        down[k] -= 1e-3
        differences[:, k] = (residual(up) - residual(down)) / 2e-3
    assert np.allclose(jacobian, differences, rtol=1e-6, atol=1e-9 * np.abs(jacobian).max())
    assert not np.allclose(jacobian, jacobian.T, rtol=1e-3)  # radiation: not symmetric
    integrator._matrix_at(T, c_dt)
    picard = integrator.matrix.csr.toarray()
    assert np.array_equal(picard, picard.T)


def test_newton_takes_half_the_iterations_of_picard_to_the_same_answer(monkeypatch):
    """A radiating bed heated from cold in two steps of 500 s to 1e-8 K: Newton (Picard first, then
    Newton while the corrections shrink) ends where Picard alone (the slopes never used) does, in
    at most half its iterations."""
    model, frame = radiating_bed()

    def run():
        h = model.enthalpy.enthalpy(np.full(frame.particles.size, 300.0))
        integrator = implicit.Implicit(model, {"tolerance": 1e-8})
        for _ in range(2):
            integrator.advance(frame, h, 500.0)
        return model.enthalpy.temperature(h), integrator.stats

    T_newton, newton = run()
    matrix_at = implicit.Implicit._matrix_at
    monkeypatch.setattr(implicit.Implicit, "_matrix_at", lambda self, T, c_dt, newton=False: matrix_at(self, T, c_dt))
    T_picard, picard = run()
    assert newton["newton_iterations"] > 0 and newton["unconverged"] == picard["unconverged"] == 0
    assert newton["iterations"] <= picard["iterations"] / 2
    assert np.max(np.abs(T_newton - T_picard)) < 1e-6


@pytest.mark.parametrize("name", integrators.NAMES + ("tr_bdf2",))
def test_one_and_two_threads_give_identical_bits(name, monkeypatch):
    monkeypatch.setattr(network, "SMALL", 0)  # run the network kernels on every thread even for this small bed
    model, frame, h0 = cluster_model(n=1200, seed=7)
    thermal = {"integrator": "implicit", "implicit": {"scheme": "tr_bdf2"}} if name == "tr_bdf2" else {"integrator": name}

    def once():
        h = h0.copy()
        integrator = integrators.create(thermal["integrator"], model, thermal)
        for _ in range(2):
            integrator.advance(frame, h, 5.0)
        return h

    results = scenes.on_threads(once)
    assert np.array_equal(results[0], results[1])


def test_multirate_sub_steps_only_the_stiff_particles():
    """A lattice with gas gaps and a chain of deeply overlapping metal particles (no softening):
    multirate does a small fraction of global sub-stepping's pair updates, and agrees with it."""
    model, positions, h0 = stability.stiff_chain()
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    h_multi, h_explicit = h0.copy(), h0.copy()
    multi = integrators.create("multirate", model)
    report = multi.advance(frame, h_multi, 0.2)
    explicit = integrators.create("explicit", model).advance(frame, h_explicit, 0.2)
    assert report.stats["finest_level"] >= 3 and report.stats["stiff_particles"] < 30
    assert report.stats["pair_updates"] < 0.2 * multi.net.pairs.first.size * report.substeps
    assert explicit.substeps >= 8
    T_m, T_e = model.enthalpy.temperature(h_multi), model.enthalpy.temperature(h_explicit)
    assert np.max(np.abs(T_m - T_e)) < 0.05 * (T_e.max() - T_e.min())


def write_tables(folder, s) -> dict:
    """The scene's HTC tables as files, as the workflow's table stages write them."""
    tables = {kind: folder / f"{kind}.h5" for kind in ("pfp", "pfw")}
    for kind, table in scenes.htc_tables(s).items():
        htc.save_table(tables[kind], table)
    return tables


def test_frozen_bed_through_the_stage(tmp_path):
    """One frame of a lattice bed held for 20 s in 2 s steps between a hot and a cold wall."""
    positions, height = scenes.lattice_bed((5, 5, 3))
    lo, hi = positions.min(axis=0) - R, positions.max(axis=0) + R
    ids = np.arange(1, len(positions) + 1)
    image = np.zeros(positions.shape, dtype=np.int32)
    frames = [DumpFrame(k, lo, hi, (False, False, False), ids, positions, image) for k in (0, 1000)]
    write_positions(tmp_path / "positions.h5", frames, radius=R, density=3560.0, timestep=1e-5, dump_interval=1000)
    save_walls(tmp_path / "walls.h5", scenes.slab_walls(height, half=0.01), "{}", 2 * R)
    s = scenes.spec(CONDUCTION, walls={"hot": {"temperature": 800.0}, "cold": {"temperature": 300.0}},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    s["thermal"].update(integrator="implicit", frozen_bed={"frame": -1, "duration": 20.0, "step": 2.0})
    tables = write_tables(tmp_path, s)
    summary = stage.run(s, tmp_path / "positions.h5", tmp_path / "walls.h5", tables, tmp_path / "thermal.h5")
    with h5py.File(tmp_path / "thermal.h5") as f:
        time, T = f["time"][...], f["temperature"][...]
        E, W = f["energy/particles"][...], f["energy/wall"][...]
        assert json.loads(f.attrs["summary"])["frozen_bed"] is True
    assert np.allclose(time, np.arange(11) * 2.0) and T.shape == (11, len(positions))
    assert np.max(np.abs(np.diff(E) - np.diff(W))) <= 1e-12 * np.max(np.abs(np.diff(W)))
    assert T[-1].mean() > T[1].mean() > 300.0 and T.max() <= 800.0 + 1e-3
    assert summary["integrator"]["requested"] == "implicit" and summary["integrator"]["frames"]["implicit"] == 10


def test_frozen_bed_from_a_packing_without_dem(tmp_path):
    """A hard-wall packing from the packing generator, written as a one-frame positions file,
    heated from its lower wall by the stage under auto."""
    from dpht.radiation.packing import pack, write_packed_bed

    packing = pack(300, 0.55, radius=R, wall_axis=2, bulk_margin=2.0, rate=0.05)
    write_packed_bed(tmp_path / "positions.h5", packing, density=3560.0)
    height = packing.box[1][2]
    walls = scenes.slab_walls(height, half=2 * height)
    save_walls(tmp_path / "walls.h5", walls, "{}", 2 * R)
    s = scenes.spec(CONDUCTION, walls={"hot": {"temperature": 500.0}, "cold": "adiabatic"},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    s["thermal"]["frozen_bed"] = {"frame": 0, "duration": 60.0, "step": 5.0}
    tables = write_tables(tmp_path, s)
    summary = stage.run(s, tmp_path / "positions.h5", tmp_path / "walls.h5", tables, tmp_path / "thermal.h5")
    with h5py.File(tmp_path / "thermal.h5") as f:
        T = f["temperature"][...]
        E, W = f["energy/particles"][...], f["energy/wall"][...]
    assert T.shape == (13, 300) and 300.0 < T[-1].mean() < 500.0 and T.max() <= 500.0 + 1e-3
    assert np.max(np.abs(np.diff(E) - np.diff(W))) <= 1e-12 * np.max(np.abs(np.diff(W)))
    assert sum(summary["integrator"]["frames"].values()) == 12


def test_lookups_below_the_htc_tables_are_clamped_counted_and_logged(tmp_path, caplog):
    """Without DEM softening (c_PP = 1) deep overlaps put the real distance below the PFP table's
    first node: each integrator counts exactly the pairs a brute-force search finds there, their
    conductance is the table's edge value (finite), and the stage logs and sums them."""
    s = scenes.spec(CONDUCTION, walls={"hot": {"temperature": 500.0}, "cold": {"temperature": 300.0}},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    s["particles"]["youngs_modulus_dem"] = s["particles"]["youngs_modulus_real"]
    positions, height = scenes.lattice_bed((4, 4, 3), spacing=1.7)
    walls = scenes.slab_walls(height, half=0.01)
    model = scenes.build_model(s, walls)
    i, j, d = reference.all_pairs(model, positions)
    expected = int(np.count_nonzero(d < model.tables["pfp"].x0))
    assert expected > 10
    frame = integrate.prepare_frame(model, positions, None, None, (False,) * 3)
    for name in integrators.NAMES:
        h = model.enthalpy.enthalpy(np.full(len(positions), 300.0))
        report = integrators.create(name, model).advance(frame, h, 1.0)
        assert report.stats["clamped"]["pfp_distance"] == expected, name
        assert np.all(np.isfinite(h))
    lo, hi = positions.min(axis=0) - R, positions.max(axis=0) + R
    image = np.zeros(positions.shape, dtype=np.int32)
    write_positions(tmp_path / "positions.h5", [DumpFrame(0, lo, hi, (False,) * 3, np.arange(1, len(positions) + 1), positions, image)],
                    radius=R, density=3560.0, timestep=1e-5, dump_interval=1000)  # fmt: skip
    save_walls(tmp_path / "walls.h5", walls, "{}", 2 * R)
    s["thermal"]["frozen_bed"] = {"frame": 0, "duration": 3.0, "step": 1.0}
    tables = write_tables(tmp_path, s)
    with caplog.at_level(logging.WARNING, logger="dpht"):
        summary = stage.run(s, tmp_path / "positions.h5", tmp_path / "walls.h5", tables, tmp_path / "thermal.h5")
    assert summary["clamped_lookups"]["pfp_distance"] == 4 * expected  # every frame, the last one too
    assert summary["clamped_lookups"]["temperature"] == 0
    assert "outside their range" in caplog.text


def stored(saved: dict) -> dict:
    """An integrator checkpoint as a file holds it: arrays copied, everything else through JSON."""
    arrays = {k: np.array(v) for k, v in saved.items() if isinstance(v, np.ndarray)}
    return {**json.loads(json.dumps({k: v for k, v in saved.items() if k not in arrays})), **arrays}


def frozen_run(thermal, schedule, positions, height, resume_at=None, restore=True):
    """A frozen bed's frames through the stage's step; with ``resume_at``, everything rebuilt from
    the State and the integrator's checkpoint after that many frames, as a resumed run is."""
    s = scenes.spec(list(NAMES), walls={"hot": {"temperature": 1000.0}, "cold": {"temperature": 300.0}},
                    initial_temperature=300.0, inlet_temperature=300.0, **thermal)  # fmt: skip
    walls = scenes.slab_walls(height, half=0.01)

    def fresh():
        model = scenes.build_model(s, walls, scenes.synthetic_rdf())
        frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic, key=0)
        return model, frame, integrators.create(thermal["integrator"], model, thermal)  # the frame as the stage keys it

    model, frame, integrator = fresh()
    state = stage.State.initial(model, len(positions))
    for count in range(len(schedule.frames)):
        if count == resume_at:
            saved = stored(integrator.checkpoint())
            state = stage.State(state.count, state.h.copy(), state.wall_energy, state.recycled_energy, None,
                                dict(state.frames_by), dict(state.clamped),
                                shells=None if state.shells is None else state.shells.copy())  # fmt: skip
            model, frame, integrator = fresh()
            if restore:
                integrator.restore(saved)
        stage.step(model, schedule, state, positions, integrator, frame)
    return state, integrators.summary(integrator, state.frames_by)


@pytest.mark.parametrize("name", ["auto", "implicit", "tr_bdf2", "multirate", "resolved"])
def test_a_resumed_frozen_bed_equals_the_uninterrupted_one_bitwise(name):
    """A radiating frozen bed heated for 6 frames of 200 s (auto runs implicit on it, whose AMG
    hierarchy, built at the first frame, serves the whole run; also with resolved particles, whose
    hierarchy holds their Schur complements): resumed after frame 3 from the State and the
    integrator's checkpoint it gives the same bits, decisions and counts; without the checkpoint
    (a hierarchy built at frame 3's temperatures) it does not."""
    thermal = {"integrator": name}
    if name == "tr_bdf2":
        thermal = {"integrator": "implicit", "implicit": {"scheme": "tr_bdf2"}}
    elif name == "resolved":
        thermal = {"integrator": "implicit", "intraparticle": True, "shells": 5}
    positions, height = scenes.lattice_bed((6, 6, 4), seed=3)
    lo, hi = positions.min(axis=0) - R, positions.max(axis=0) + R
    times = np.arange(7) * 200.0
    schedule = stage.Schedule([0] * len(times), times, lo, hi, np.zeros(3, bool), None, frozen=True)
    whole, summary = frozen_run(thermal, schedule, positions, height)
    resumed, summary_resumed = frozen_run(thermal, schedule, positions, height, resume_at=3)
    assert np.array_equal(whole.h, resumed.h) and summary == summary_resumed
    assert (whole.shells is None) == (name != "resolved") and np.array_equal(whole.shells, resumed.shells)
    assert (whole.wall_energy, whole.frames_by, whole.clamped) == (resumed.wall_energy, resumed.frames_by, resumed.clamped)
    if name != "multirate":
        assert summary["frames"]["implicit"] == 6
        forgotten, _ = frozen_run(thermal, schedule, positions, height, resume_at=3, restore=False)
        assert not np.array_equal(whole.h, forgotten.h)


def test_a_dem_frame_met_again_after_a_resume_gets_a_hierarchy_of_its_own():
    """A travelling slice plays its DEM record back and forth, so a DEM frame comes back later as a
    new geometry (mirror: frames 3, 4, 3). Auto runs implicit on the long first and third intervals
    and explicit on the short second; resumed after the second, the third builds its AMG hierarchy
    at its own temperatures as the uninterrupted run does (the checkpoint's hierarchy serves only
    the geometry it was built on, a frozen bed's), so the bits are the same."""
    s = scenes.spec(list(NAMES), walls={"hot": {"temperature": 1000.0}, "cold": {"temperature": 300.0}},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    positions, height = scenes.lattice_bed((6, 6, 4), seed=3)
    at = {3: positions, 4: scenes.lattice_bed((6, 6, 4), seed=4)[0]}  # the DEM frames' positions
    lo, hi = positions.min(axis=0) - 2 * R, positions.max(axis=0) + 2 * R
    schedule = stage.Schedule([3, 4, 3, 4], np.array([0.0, 200.0, 200.001, 400.001]), lo, hi, np.zeros(3, bool), None)
    walls = scenes.slab_walls(height, half=0.01)

    def run(resume_at=None):
        model = scenes.build_model(s, walls, scenes.synthetic_rdf())
        integrator, state = integrators.create("auto", model), stage.State.initial(model, len(positions))
        for count, dem_frame in enumerate(schedule.frames):
            if count == resume_at:
                saved = stored(integrator.checkpoint())
                model = scenes.build_model(s, walls, scenes.synthetic_rdf())
                integrator = integrators.create("auto", model)
                integrator.restore(saved)
                state = stage.State(state.count, state.h.copy(), state.wall_energy, state.recycled_energy, None,
                                    dict(state.frames_by), dict(state.clamped))  # fmt: skip
            stage.step(model, schedule, state, at[dem_frame], integrator)
        return state, integrators.summary(integrator, state.frames_by)

    whole, summary = run()
    assert summary["frames"] == {"explicit": 1, "multirate": 0, "implicit": 2}
    resumed, summary_resumed = run(resume_at=2)
    assert np.array_equal(whole.h, resumed.h) and summary == summary_resumed


def test_a_frozen_bed_stopped_and_resumed_through_the_stage_equals_the_uninterrupted_run(tmp_path, monkeypatch):
    """The stage's checkpoints carry the integrator: a radiating frozen bed under auto (implicit,
    one AMG hierarchy for the run) stopped after its second checkpoint and run again gives the
    uninterrupted file's rows and summary, bit for bit."""
    from dpht.closures import rdf

    positions, height = scenes.lattice_bed((6, 6, 4), seed=3)
    lo, hi = positions.min(axis=0) - R, positions.max(axis=0) + R
    frame = DumpFrame(0, lo, hi, (False,) * 3, np.arange(1, len(positions) + 1), positions, np.zeros(positions.shape, np.int32))
    write_positions(tmp_path / "positions.h5", [frame], radius=R, density=3560.0, timestep=1e-5, dump_interval=1000)
    save_walls(tmp_path / "walls.h5", scenes.slab_walls(height, half=0.01), "{}", 2 * R)
    s = scenes.spec(list(NAMES), walls={"hot": {"temperature": 1000.0}, "cold": {"temperature": 300.0}},
                    initial_temperature=300.0, inlet_temperature=300.0)  # fmt: skip
    s["thermal"]["frozen_bed"] = {"frame": 0, "duration": 1400.0, "step": 200.0}
    tables = write_tables(tmp_path, s)
    rdf.save(tmp_path / "rdf.h5", scenes.synthetic_rdf())

    def run(name):
        return stage.run(s, tmp_path / "positions.h5", tmp_path / "walls.h5", tables, tmp_path / f"{name}.h5",
                         rdf_table=tmp_path / "rdf.h5", checkpoints=stage.Checkpoints(frames=2))  # fmt: skip

    whole = run("whole")
    step = stage.step

    def stopping(model, schedule, state, *args):
        if state.count == 5:
            raise KeyboardInterrupt
        return step(model, schedule, state, *args)

    monkeypatch.setattr(stage, "step", stopping)
    with pytest.raises(KeyboardInterrupt):
        run("resumed")
    with h5py.File(tmp_path / "resumed.work" / "checkpoint.h5") as f:
        assert f.attrs["count"] == 4 and "implicit/amg_T" in f["integrator"]
    monkeypatch.setattr(stage, "step", step)
    resumed = run("resumed")
    with h5py.File(tmp_path / "whole.h5") as a, h5py.File(tmp_path / "resumed.h5") as b:
        for name in ("temperature", "wall_heat", "energy/particles", "energy/wall"):
            assert np.array_equal(a[name][...], b[name][...], equal_nan=True), name
    assert whole["integrator"]["frames"]["implicit"] == 7
    assert stage.reproducible(whole) == stage.reproducible(resumed)


DURATION = 20.0  # s of the resolved cluster's runs


def resolved_run(model, frame, h0, name, dt, steps, thermal=None):
    """``steps`` steps of ``dt`` with integrator ``name`` from uniform particles at ``h0``: the
    particles' enthalpies, node enthalpies, wall and gas heat (J) and the last report."""
    integrator = integrators.create(name, model, {"integrator": name, **(thermal or {})})
    h, shells = h0.copy(), np.repeat(h0[:, None], model.shells.n, axis=1)
    wall = gas = 0.0
    for _ in range(steps):
        report = integrator.advance(frame, h, dt, shells=shells)
        wall += dt * math.fsum(report.element_heat.ravel())
        gas += report.convected
    return h, shells, wall, gas, report


def resolved_cluster(conductivity=0.3, shells=8, **kwargs):
    model, frame, h0 = cluster_model(n=150, conductivity=conductivity, **kwargs)
    return thermal_model.resolved(dataclasses.replace(model, shell_count=shells)), frame, h0


@pytest.mark.parametrize("gas", [None, (300.0, 700.0)])
def test_implicit_advances_resolved_particles_far_beyond_the_explicit_limit(gas):
    """Poorly conducting particles at a wall (and in a hot gas): one implicit step of 20 s, where
    explicit needs hundreds of sub-steps (the surface node's capacity bounds them), stays inside the
    wall's and the gas's temperatures, conserves energy to 1e-12 node by node, and converges (at
    first order or faster) to explicit's answer at its stable sub-step."""
    model, frame, h0 = resolved_cluster()
    if gas:
        model = dataclasses.replace(model, convection=intraparticle.Surface(*gas))
    m = model.mass
    reference = resolved_run(model, frame, h0, "explicit", DURATION, 1)
    assert reference[4].substeps > 100
    errors = []
    for steps in (1, 4, 16):
        h, shells, wall, heat_gas, report = resolved_run(model, frame, h0, "implicit", DURATION / steps, steps)
        assert report.integrator == "implicit" and report.stats["unconverged"] == 0
        gained = m * (math.fsum(h) - math.fsum(h0))
        assert abs(gained - wall - heat_gas) <= 1e-12 * (abs(wall) + abs(heat_gas))
        nodes = m * math.fsum(intraparticle.mean_enthalpy(shells, model.shells.weight)) - m * math.fsum(h0)
        assert abs(nodes - gained) <= 1e-12 * abs(gained)
        T = model.enthalpy.temperature(shells)
        assert T.min() >= 300.0 - 1e-6 and T.max() <= max(600.0, gas[1] if gas else 0.0) + 1e-6
        errors.append(abs(wall + heat_gas - reference[2] - reference[3]) / abs(reference[2] + reference[3]))
    assert errors[2] < 0.01 and errors[0] / errors[1] > 2.5 and errors[1] / errors[2] > 2.5


def test_a_resolved_frozen_bed_reaches_the_lumped_steady_state():
    """A hot wall below, a cold gas around: at steady state no heat crosses a particle's interior
    (it all enters and leaves through the surface node), so resolved particles are uniform at the
    temperatures of uniform ones. Both by implicit steps of 10^4 s."""
    model, frame, h0 = resolved_cluster(conductivity=0.5)
    gas = intraparticle.Surface(50.0, 300.0)
    resolved = dataclasses.replace(model, convection=gas)
    lumped = dataclasses.replace(model, shells=None, convection=gas)
    h, shells, *_ = resolved_run(resolved, frame, h0, "implicit", 1e4, 3)
    h_lumped = h0.copy()
    implicit_lumped = integrators.create("implicit", lumped)
    for _ in range(3):
        implicit_lumped.advance(frame, h_lumped, 1e4)
    T_lumped, T_nodes = lumped.enthalpy.temperature(h_lumped), resolved.enthalpy.temperature(shells)
    assert T_lumped.max() - T_lumped.min() > 50.0  # a real profile through the cluster
    assert np.max(np.abs(T_nodes - T_lumped[:, None])) < 1e-6
    assert np.max(np.abs(resolved.enthalpy.temperature(h) - T_lumped)) < 1e-6


def test_auto_chooses_between_explicit_and_implicit_for_resolved_particles(caplog):
    """A resolved model under auto: a mild frame runs explicit (bit-identical to it), a stiff one
    implicit, with multirate never a candidate; the same for uniform particles with convection."""
    model, frame, h0 = resolved_cluster()
    caplog.set_level(logging.INFO, logger="dpht")
    auto = integrators.create("auto", model)
    assert set(auto.candidates) == set(integrators.SHELLS) == {"explicit", "implicit"}
    _, shells_auto, *_, report = resolved_run(model, frame, h0, "auto", 1e-4, 2)
    assert report.integrator == "explicit"
    _, shells_explicit, *_ = resolved_run(model, frame, h0, "explicit", 1e-4, 2)
    assert np.array_equal(shells_auto, shells_explicit)
    *_, report = resolved_run(model, frame, h0, "auto", 20.0, 1)  # dt g/(m c_p) up to 110: implicit repays its setup
    assert report.integrator == "implicit" and "auto: implicit from frame 0" in caplog.text
    blown = dataclasses.replace(model, shells=None, convection=intraparticle.Surface(100.0, 300.0))
    assert set(integrators.create("auto", blown).candidates) == {"explicit", "implicit"}
    h = h0.copy()
    assert integrators.create("auto", blown).advance(frame, h, 500.0).integrator == "implicit"


def test_resolved_implicit_is_identical_for_one_and_two_threads(monkeypatch):
    monkeypatch.setattr(network, "SMALL", 0)
    model, frame, h0 = resolved_cluster()
    model = dataclasses.replace(model, convection=intraparticle.Surface(80.0, 450.0))
    results = scenes.on_threads(lambda: resolved_run(model, frame, h0, "implicit", 0.5, 2)[:4])
    for a, b in zip(*results):
        assert np.array_equal(a, b)


def test_uniform_particles_with_convection_conserve_energy_under_both_implicit_schemes():
    model, frame, h0 = cluster_model(n=150)
    model = dataclasses.replace(model, convection=intraparticle.Surface(200.0, 700.0))
    for scheme in implicit.SCHEMES:
        integrator = integrators.create("implicit", model, {"implicit": {"scheme": scheme}})
        h = h0.copy()
        report = integrator.advance(frame, h, 2.0)
        wall = 2.0 * math.fsum(report.element_heat.ravel())
        gained = model.mass * (math.fsum(h) - math.fsum(h0))
        assert report.convected > 0 and abs(gained - wall - report.convected) <= 1e-12 * abs(gained)


def test_multirate_and_tr_bdf2_refuse_resolved_particles():
    model, _, _ = resolved_cluster()
    blown = dataclasses.replace(model, shells=None, convection=intraparticle.Surface(100.0, 300.0))
    for m in (model, blown):
        with pytest.raises(ConfigError, match="thermal.integrator: 'multirate' cannot advance resolved particles"):
            integrators.create("multirate", m)
    for name in ("implicit", "auto"):
        with pytest.raises(ConfigError, match="'tr_bdf2' cannot advance resolved particles"):
            integrators.create(name, model, {"implicit": {"scheme": "tr_bdf2"}})
    integrators.create("implicit", blown, {"implicit": {"scheme": "tr_bdf2"}})  # uniform particles with a gas: fine


@pytest.mark.parametrize("thermal", [{"intraparticle": True}, {"intraparticle": "auto"},
                                     {"convection": {"coefficient": 10.0, "gas_temperature": 300.0}}])  # fmt: skip
def test_intraparticle_or_convection_with_multirate_is_a_config_error(thermal):
    with pytest.raises(ConfigError, match="thermal.integrator: 'multirate' cannot advance"):
        integrators.check_intraparticle({**thermal, "integrator": "multirate"})
    for name in ("auto", "explicit", "implicit"):
        integrators.check_intraparticle({**thermal, "integrator": name})
    if "intraparticle" in thermal:
        with pytest.raises(ConfigError, match="thermal.implicit.scheme: 'tr_bdf2'"):
            integrators.check_intraparticle({**thermal, "integrator": "auto", "implicit": {"scheme": "tr_bdf2"}})
    integrators.check_intraparticle({"intraparticle": False, "integrator": "multirate"})
