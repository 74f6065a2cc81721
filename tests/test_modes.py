"""The registry of heat-transfer modes against everything that lists modes: the config schema and
default config, the modes' laws, the model's cutoffs, the output's wall columns; and a mode added
through the registry alone, seen by the explicit kernel and the integrators' network."""

import math
from pathlib import Path

import numba as nb
import numpy as np
import pytest
import yaml

from dpht import config
from dpht.errors import ConfigError
from dpht.closures import htc, rdf
from dpht.closures.conductance import MEAN, PIECE, RADIATIVE, Law
from dpht.thermal import implicit, integrate, model as thermal_model, modes, network, neighbors
from dpht.util.interp import Table1D, Table2D
from dpht.verification import scenes

ROOT = Path(__file__).resolve().parent.parent
R = scenes.RADIUS


def test_config_schema_switches_are_the_registry():
    thermal = config.schema()["properties"]["thermal"]["properties"]
    switches = thermal["modes"]
    assert switches["additionalProperties"] is False
    assert list(switches["properties"]) == list(modes.NAMES)
    switch = config.schema()["$defs"]["switch"]
    assert switch == {"enum": [True, False, "auto"], "default": "auto"}  # decided by thermal.effects
    for mode in modes.MODES:
        assert switches["properties"][mode.name] == {"$ref": "#/$defs/switch"}, mode.name
        if mode.cutoff_key is not None:  # the key giving the cutoff exists, in radii
            assert "radii" in thermal[mode.cutoff_key]["description"], mode.cutoff_key


def test_default_config_lists_every_mode():
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    assert list(cfg["thermal"]["modes"]) == list(modes.NAMES)
    # A switch left out is auto, as in the default config; only a true one is on before the effects are decided.
    filled = config.load(ROOT / "config" / "config.yaml")
    assert filled["thermal"]["modes"] == dict.fromkeys(modes.NAMES, "auto") == cfg["thermal"]["modes"]
    assert modes.enabled(filled["thermal"]["modes"]) == frozenset()
    assert modes.enabled({"pfp": True, "pfw": "auto", "pp_contact": False}) == {"pfp"}


def test_registry_entries_are_consistent():
    assert len(set(modes.NAMES)) == len(modes.MODES) and len(set(modes.LABELS.values())) == len(modes.MODES)
    assert set(modes.PP_MODES) | set(modes.PW_MODES) == set(modes.NAMES)
    for mode in modes.MODES:  # every style's law resolves, of a known temperature dependence and table type
        assert mode.styles and len({style.name for style in mode.styles}) == len(mode.styles), mode.name
        for style in mode.styles:
            law = style.resolve()
            assert isinstance(law, Law) and law.temperature in (MEAN, RADIATIVE) and law.table in (Table1D, Table2D), style
        assert (mode.style().resolve().temperature == RADIATIVE) == (mode.table is not None and mode.table[0] == "rdf")
    for mode in modes.MODES:
        if mode.table is not None:
            kind, part = mode.table
            assert part in (htc.KINDS if kind == "htc" else rdf.RDFTables.__dataclass_fields__), mode.name
            assert modes.reader(kind, part) is mode
    assert modes.needing("rdf") == config.RADIATION_MODES == ("pp_radiation", "pw_radiation")
    assert [modes.wall_column(m) for m in modes.PW_MODES] == list(range(len(modes.PW_MODES)))


@pytest.mark.parametrize(
    "enabled, pair, wall",
    [
        (["pp_contact"], 2.0, 0.0),
        (["pw_contact"], 0.0, 1.0),
        (["pp_contact", "pfp"], 3.0, 0.0),
        (["pw_contact", "pfw"], 0.0, 1.5),
        (["pp_contact", "pw_radiation"], 2.0, 7.0),
        (list(modes.NAMES), 7.0, 7.0),
    ],
)
def test_model_cutoffs_follow_each_modes_rule(enabled, pair, wall):
    """Contact: touching (2 R centre-centre, R centre-wall); the others: their thermal.* key in radii
    (scenes.BASE_SPEC: pfp 3, pfw 1.5, radiation 7)."""
    model = scenes.build_model(scenes.spec(enabled), scenes.plane_walls(), scenes.synthetic_rdf())
    assert model.pair_cutoff == pair * R and model.wall_cutoff == wall * R
    assert bool(model.surfaces) == (wall > 0)
    assert model.n_elements == len(scenes.plane_walls().area)


def test_a_table_needed_but_missing_is_refused():
    with pytest.raises(ConfigError, match="thermal.rdf_table: needed for \\['pp_radiation'\\]"):
        scenes.build_model(scenes.spec(["pp_radiation"]))


G_TOY = 3e-3  # W/K


@nb.njit(**PIECE)
def constant(r2, T_mean, side, own, table):
    """A toy mode: a constant conductance (its coefficient) between particles within its cutoff."""
    return own.coefficient, 0


TOY = modes.Mode("pp_toy", "pp", "none", "toy", "a constant conductance within 2.5 radii", 2.5, None,
                 (modes.Style("constant", Law(MEAN, constant, lambda mode, setting: (G_TOY, Table1D(0.0, 1.0, np.zeros(2))), Table1D),
                              "none", "G_TOY"),))  # fmt: skip


def test_a_mode_added_through_the_registry_alone_reaches_the_kernels_and_the_network():
    """A constant-conductance pair mode, registered here only (no kernel, model or network edit):
    next to contact conduction, the explicit kernel's heat rates are the contact's plus G (T_j -
    T_i) for every pair within its cutoff (brute force), the network holds the same conductances,
    energy is conserved to round-off, and the implicit integrator takes it too."""
    registry = modes.REGISTRY.with_mode(TOY)
    s = scenes.spec(["pp_contact"])
    s["thermal"]["modes"]["pp_toy"] = True
    model = thermal_model.build(s, None, {}, modes_registry=registry)
    plain = thermal_model.build(s, None, {})
    assert model.modes == {"pp_contact", "pp_toy"} and model.pair_cutoff == 2.5 * R
    positions = scenes.random_cluster(n=300, seed=4)
    T = np.random.default_rng(5).uniform(300.0, 700.0, len(positions))

    def explicit(m):
        frame = integrate.prepare_frame(m, positions, None, None, (False,) * 3)
        rates = integrate.Rates.for_frame(m, frame)
        integrate.evaluate(m, frame, T[frame.particles], rates)
        q = np.zeros(len(positions))
        q[frame.particles] = rates.q
        return q, frame

    q, frame = explicit(model)
    q_contact = explicit(plain)[0]
    i, j = neighbors.brute_force_pairs(positions, 2.5 * R)
    q_toy = np.zeros(len(positions))
    np.add.at(q_toy, i, G_TOY * (T[j] - T[i]))
    np.add.at(q_toy, j, G_TOY * (T[i] - T[j]))
    assert i.size > 500 and np.count_nonzero(q_contact) > 100
    np.testing.assert_allclose(q, q_contact + q_toy, rtol=0, atol=1e-12 * np.abs(q).max())
    assert abs(math.fsum(q)) <= 1e-12 * math.fsum(np.abs(q))

    net = network.assemble(model, frame)
    network.conductances(model, net, T[frame.particles])
    touching = net.pairs.r2 < 4 * R**2
    assert net.pairs.first.size == i.size and np.all(net.pairs.G[~touching] == G_TOY) and np.all(net.pairs.G[touching] > G_TOY)
    q_net, g_net = np.empty(net.n), np.empty(net.n)
    network.rates(model, net, T[frame.particles], q_net, g_net)
    np.testing.assert_allclose(q_net, q[frame.particles], rtol=0, atol=1e-12 * np.abs(q).max())

    h = model.enthalpy.enthalpy(T)
    energy = math.fsum(h * model.mass)
    report = implicit.Implicit(model).advance(frame, h, 5.0)
    assert report.integrator == "implicit" and np.ptp(model.enthalpy.temperature(h)) < np.ptp(T)
    assert abs(math.fsum(h * model.mass) - energy) <= 1e-12 * energy


def test_a_style_is_chosen_per_mode():
    """pp_contact's "dem" style (the DEM's own contact radius) equals the default with no softening
    (c_PP = 1), bit for bit; an unknown style is refused."""
    s = scenes.spec(["pp_contact"])
    dem = thermal_model.build(s, None, {}, styles={"pp_contact": "dem"})
    s_hard = scenes.spec(["pp_contact"])
    s_hard["particles"]["youngs_modulus_dem"] = s_hard["particles"]["youngs_modulus_real"]
    hard = thermal_model.build(s_hard, None, {})
    positions = scenes.random_cluster(n=200, seed=6)
    T = np.random.default_rng(7).uniform(300.0, 700.0, len(positions))
    q = []
    for m in (dem, hard, thermal_model.build(s, None, {})):
        frame = integrate.prepare_frame(m, positions, None, None, (False,) * 3)
        rates = integrate.Rates.for_frame(m, frame)
        integrate.evaluate(m, frame, T[frame.particles], rates)
        q.append(rates.q)
    assert np.array_equal(q[0], q[1]) and not np.allclose(q[0], q[2])
    with pytest.raises(KeyError, match="pp_contact.*no style 'area'"):
        thermal_model.build(s, None, {}, styles={"pp_contact": "area"})
