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

ROOT = Path(__file__).resolve().parents[2]
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
    (c_PP = 1), bit for bit; an unknown style in a spec is refused, naming the key and the styles."""
    s = scenes.spec(["pp_contact"])
    dem = thermal_model.build({**s, "thermal": {**s["thermal"], "styles": {"pp_contact": "dem"}}}, None, {})
    assert dem.styles["pp_contact"].name == "dem" and dem.styles["pw_contact"].name == "corrected"
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
    for styles, message in (({"pp_contact": "area"}, r"thermal.styles.pp_contact: 'area' is not a style of pp_contact; "
                                                     r"expected one of \['corrected', 'dem'\]"),
                            ({"pp_contct": "dem"}, r"thermal.styles.pp_contct: not a heat-transfer mode")):  # fmt: skip
        with pytest.raises(ConfigError, match=message):
            thermal_model.build({**s, "thermal": {**s["thermal"], "styles": styles}}, None, {})


def test_config_schema_styles_are_the_registry():
    """thermal.styles lists every mode with alternatives, its styles' names as the enum, the
    registry's first (the DPHT paper's) the default."""
    styles = config.schema()["properties"]["thermal"]["properties"]["styles"]
    assert styles["additionalProperties"] is False and styles["default"] == {}
    with_alternatives = [m for m in modes.MODES if len(m.styles) > 1]
    assert list(styles["properties"]) == [m.name for m in with_alternatives] == ["pp_contact", "pw_contact"]
    for mode in with_alternatives:
        entry = styles["properties"][mode.name]
        assert entry["enum"] == [s.name for s in mode.styles] and entry["default"] == mode.styles[0].name, mode.name


def _styled(tmp_path, styles: dict):
    """The tiny scene's config with ``thermal.styles``, loaded as the workflow does; its plan."""
    override = tmp_path / "styles.yaml"
    override.write_text(yaml.safe_dump({"thermal": {"styles": styles}}))
    from dpht.plan import Plan

    cfg = config.load(ROOT / ".test" / "config" / "config.yaml", override)
    return cfg, Plan(cfg).keys["base"]


def test_styles_reach_the_stage_keys_only_off_their_defaults(tmp_path):
    """The default styles, named or not, leave every key as it was (the cache of earlier runs
    stays valid); a non-default style is in the thermal stage's spec and changes the thermal and
    screening keys, and nothing upstream (geometry, DEM, tables)."""
    _, plain = _styled(tmp_path, {})
    cfg, named = _styled(tmp_path, {"pp_contact": "corrected", "pw_contact": "corrected"})
    assert named == plain and "styles" not in config.thermal_spec(cfg)["thermal"]
    cfg, dem = _styled(tmp_path, {"pw_contact": "dem"})
    assert config.thermal_spec(cfg)["thermal"]["styles"] == {"pw_contact": "dem"}
    assert dem["thermal"] != plain["thermal"] and dem["screening"] != plain["screening"]
    assert all(dem[stage] == plain[stage] for stage in ("geometry", "dem", "pfp", "pfw", "rdf"))


def test_an_unknown_style_in_a_config_is_refused_with_its_file_line_and_the_styles(tmp_path):
    override = tmp_path / "styles.yaml"
    override.write_text("thermal:\n  styles:\n    pp_contact: radius\n")
    with pytest.raises(ConfigError, match=r"styles.yaml:3: thermal.styles.pp_contact: 'radius' is not allowed; "
                                          r'expected one of "corrected", "dem"'):  # fmt: skip
        config.load(ROOT / ".test" / "config" / "config.yaml", override)


def test_the_dem_contact_styles_carry_more_heat_and_conserve_energy():
    """thermal.styles {pp_contact: dem, pw_contact: dem} (as the stage spec holds them) drop the
    softening corrections c_PP, c_PW < 1 of Eqs. 3 and 7: every contact conductance is 1/c larger
    (at the same temperatures the pair rates and the wall heat scale by exactly 1/c), so a bed on a
    hot plane gains more heat in the same time and its temperatures even out faster; in both styles
    the heat the bed gains is the heat the wall gave (first law, to round-off)."""
    s = scenes.spec(["pp_contact", "pw_contact"], walls={"hot": {"temperature": 800.0}})
    walls = scenes.plane_walls(half=0.05)
    positions = scenes.random_cluster(n=300, seed=11)
    T0 = np.random.default_rng(12).uniform(300.0, 500.0, len(positions))
    column = modes.wall_column("pw_contact")
    runs = {}
    for name, styles in (("corrected", {}), ("dem", {"pp_contact": "dem", "pw_contact": "dem"})):
        styled = {**s, "thermal": {**s["thermal"], "styles": styles}}
        pairs_only = thermal_model.build({**styled, "thermal": {**styled["thermal"], "modes": {"pp_contact": True}}}, None, {})
        frame = integrate.prepare_frame(pairs_only, positions, None, None, (False,) * 3)
        rates = integrate.Rates.for_frame(pairs_only, frame)
        integrate.evaluate(pairs_only, frame, T0[frame.particles], rates)
        q_pairs = rates.q.copy()
        model = thermal_model.build(styled, walls, {})
        h = model.enthalpy.enthalpy(T0)
        e0 = math.fsum(h * model.mass)
        frame, _, reports = scenes.advance(model, positions, h, 0.02, 5)
        wall_heat = math.fsum(r.element_heat.sum() * 0.02 for r in reports)
        gained = math.fsum(h * model.mass) - e0
        assert gained > 0 and abs(gained - wall_heat) <= 1e-9 * wall_heat, name
        assert reports[0].substeps == 1  # so its wall heat is at the starting temperatures
        spread = np.std(model.enthalpy.temperature(h)[frame.particles])
        runs[name] = (model, q_pairs, reports[0].element_heat.sum(axis=0)[column], gained, spread)
    (corrected, q_c, wall_c, gained_c, spread_c), (dem, q_d, wall_d, gained_d, spread_d) = runs["corrected"], runs["dem"]
    c_pp, c_pw = corrected.pair.softening, corrected.wall.softening
    assert 0 < c_pp < 1 and 0 < c_pw < 1 and np.count_nonzero(q_c) > 100
    np.testing.assert_allclose(q_d, q_c / c_pp, rtol=1e-12, atol=1e-12 * np.abs(q_d).max())
    np.testing.assert_allclose(wall_d, wall_c / c_pw, rtol=1e-12)
    assert gained_d > gained_c and spread_d < spread_c
