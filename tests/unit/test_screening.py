"""Screening (issue 14): the effects a scene calls for, decided from its config and its settled bed,
each decision logged with its reason; on a synthetic bed of the thermal stage's tests."""

import copy
import json
import logging
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from dpht import config, stages
from dpht.plan import Plan, path
from dpht.closures import htc
from dpht.errors import ConfigError
from dpht.thermal import effects, integrate, modes, network, screening, stage
from dpht.thermal.effects import Decision
from test_solid_fraction import dem_summary
from test_thermal_stage import make_scene, run_stage

ROOT = Path(__file__).resolve().parents[2]
SHIPPED_RDF = next((ROOT / "tables" / "rdf" / "shipped").glob("*.h5"))  # emissivities 0.65 / 0.6, as the scene's


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return make_scene(tmp_path_factory.mktemp("screening"), n_frames=3)


def auto_spec(scene, particles=None, **thermal):
    """The scene's spec with every mode left at auto and ``particles`` and ``thermal`` keys overridden."""
    spec = copy.deepcopy(scene[1])
    spec["thermal"]["modes"] = dict.fromkeys(modes.NAMES, effects.AUTO)
    spec["particles"].update(particles or {})
    spec["thermal"].update(thermal)
    return spec


def tables_of(spec):
    return {kind: htc.table_from_spec(config.htc_spec(spec, kind)) for kind in htc.KINDS}


def screen(scene, particles=None, dem_summary=None, rdf_grids=None, **thermal):
    """The screening of the scene, its HTC tables at the solid fractions of ``thermal`` (0.6 where measured)."""
    folder = scene[0]
    spec = auto_spec(scene, particles, **thermal)
    phi = spec["thermal"]["solid_fraction"]
    numbers = {r: 0.6 if v == "measured" else v for r, v in phi.items()} if isinstance(phi, dict) else phi
    tables = tables_of({**spec, "thermal": {**spec["thermal"], "solid_fraction": numbers}})
    return screening.screen(spec, folder / "positions.h5", folder / "walls.h5", dem_summary, tables, SHIPPED_RDF, rdf_grids)


def decision(result, name) -> Decision:
    return Decision(**result["decisions"][name])


# --- decided by the config alone -----------------------------------------------------------------


def test_switches_set_in_the_config_and_effects_all():
    thermal = {"modes": {"pfp": True, "pfw": False, "pp_radiation": "auto"}, "walls": {"hot": {"temperature": 900.0}}}
    decided = effects.from_config(thermal)
    assert decided["pfp"] == Decision("pfp", True, "set in the config", True)
    assert decided["pfw"] == Decision("pfw", False, "set in the config", False)
    assert effects.pending(decided) == ("pp_contact", "pw_contact", "pp_radiation", "pw_radiation")
    assert effects.possible_modes(decided) == set(modes.NAMES) - {"pfw"}
    everything = effects.from_config({**thermal, "effects": "all", "intraparticle": "auto"})
    assert effects.pending(everything) == () and effects.possible_modes(everything) == set(modes.NAMES) - {"pfw"}
    assert everything["pp_radiation"].reason == "thermal.effects: all" and everything["intraparticle"].on
    resolved = effects.resolve(thermal, everything)
    assert resolved["modes"] == {**dict.fromkeys(modes.NAMES, True), "pfw": False}
    with pytest.raises(ValueError, match="not decided"):
        effects.resolve(thermal, decided)


def test_particle_wall_modes_are_off_without_a_wall_with_a_temperature():
    adiabatic = {"walls": {"tube": "adiabatic", "plate": "adiabatic"}, "modes": {"pw_contact": True}}
    decided = effects.from_config(adiabatic)
    assert [decided[m].on for m in ("pfw", "pw_radiation")] == [False, False]
    assert "no wall zone has a temperature" in decided["pfw"].reason
    assert decided["pw_contact"].on  # set in the config: as set
    # A zone with a temperature that the geometry does not have does not count either.
    heated_elsewhere = {"walls": {"mixer": {"temperature": 900.0}, "tube": "adiabatic"}}
    assert not effects.from_config(heated_elsewhere, zones=("tube",))["pfw"].on
    assert effects.from_config(heated_elsewhere)["pfw"] is None


def test_gas_gap_modes_are_off_in_a_vacuum():
    decided = effects.from_config({"walls": {"hot": {"temperature": 900.0}}, "gas_pressure": 0.0})
    assert not decided["pfp"].on and not decided["pfw"].on and "gas_pressure = 0" in decided["pfp"].reason
    assert decided["pp_contact"] is None and decided["pp_radiation"] is None  # the bed decides those


def test_the_thermal_stage_refuses_modes_left_at_auto(scene, tmp_path):
    folder, _, tables = scene
    with pytest.raises(ConfigError, match=r"thermal.modes: \['pp_radiation'\] are not decided"):
        stage.run({**scene[1], "thermal": {**scene[1]["thermal"], "modes": {**scene[1]["thermal"]["modes"],
                                                                               "pp_radiation": "auto"}}},
                  folder / "positions.h5", folder / "walls.h5", tables, tmp_path / "t.h5")  # fmt: skip
    assert not (tmp_path / "t.h5").exists()


# --- decided on the settled bed -------------------------------------------------------------------


def test_conductance_sums_equal_those_of_the_rate_kernels(scene):
    """Each mode's sum over the network (pairs once, wall contacts) equals the rate kernels' summed
    conductances of that mode alone (every pair twice, once per particle), a different code path."""
    folder, spec, _ = scene
    spec = {**spec, "thermal": {**spec["thermal"], "solid_fraction": {"bulk": 0.6, "near_wall": 0.5}}}  # within the table
    model = stage.thermal_model.build(spec, stage.load_walls(folder / "walls.h5"), tables_of(spec),
                                      stage._rdf_tables(SHIPPED_RDF, spec))  # fmt: skip
    with stage.PositionsFile(folder / "positions.h5") as dem:
        schedule = stage.Schedule.of(dem, 1)
        positions = np.asarray(dem.frame(0).positions, dtype=np.float64)
    frame = integrate.prepare_frame(model, positions, schedule.box_lo, schedule.box_hi, schedule.periodic)
    T = 700.0
    sums = screening.conductance_sums(model, network.assemble(model, frame), T, weighted=False)
    element_T = np.where(np.isfinite(model.element_temperature), T, np.nan)
    for name in modes.NAMES:
        alone = replace(model, modes=frozenset({name}), element_temperature=element_T)
        rates = integrate.Rates.for_frame(alone, frame)
        integrate.evaluate(alone, frame, np.full(frame.particles.size, T), rates)
        twice = 2.0 if modes.BY_NAME[name].side == "pp" else 1.0
        assert sums[name] > 0 and np.sum(rates.g) == pytest.approx(twice * sums[name], rel=1e-12), name
    shares = screening.shares(sums)
    for side in ("pp", "pw"):
        assert sum(v for m, v in shares.items() if modes.BY_NAME[m].side == side) == pytest.approx(1.0, rel=1e-14)


def test_radiation_is_screened_by_temperature_and_emissivity(scene, caplog):
    with caplog.at_level(logging.INFO, logger="dpht"):
        hot = screen(scene, walls={"hot": {"temperature": 1300.0}})
    cold = screen(scene, walls={"hot": {"temperature": 310.0}}, initial_temperature=300.0, inlet_temperature=300.0)
    dark = screen(scene, {"emissivity": 0.05}, walls={"hot": {"temperature": 310.0}}, initial_temperature=300.0,
                  inlet_temperature=300.0)  # fmt: skip
    for name in effects.RADIATION:
        share = {r: decision(result, name).estimate for r, result in (("hot", hot), ("cold", cold), ("dark", dark))}
        assert share["hot"] > 0.3 and 0.02 < share["cold"] < 0.15, share  # sigma T^3: 80 times from 310 to 1300 K
        assert share["dark"] < 0.01 and share["dark"] == pytest.approx(share["cold"] * 0.05 / 0.65, rel=0.2), share
        assert decision(hot, name).on and decision(cold, name).on and not decision(dark, name).on
    line = decision(hot, "pp_radiation").line()
    assert line.startswith("pp_radiation: on - ") and "% of the pairs' conductivity (sum of G r^2) at T = 1300 K" in line
    assert "screening: pp_radiation: on - " in caplog.text  # logged
    assert "at T = 310 K" in decision(dark, "pp_radiation").reason and "below 1%" in decision(dark, "pp_radiation").reason


def test_a_measured_solid_fraction_beyond_the_thermal_stages_rdf_table_stops_the_screening(scene, tmp_path):
    """The DEM run measured a near-wall solid fraction (0.58) beyond the PW table the thermal stage
    will read (0.2-0.55): once the screening decides pw_radiation on, it refuses, naming the value,
    the summary, the table's range and what to do, before the thermal stage is planned; with the
    mode decided off the table is not read, and the screening decides as before."""
    summary = dem_summary(tmp_path / "summary.json", bulk=0.6, near_wall=0.58)
    grids = {"pp": np.array([0.25, 0.64]), "pw": np.array([0.2, 0.55])}
    measured = {"bulk": 0.6, "near_wall": "measured"}
    with pytest.raises(ConfigError, match=r"thermal.solid_fraction.near_wall = measured: the DEM run measured 0.5800 "
                                          r"\(.*summary.json\), outside the PW RDF table's solid fractions 0.2-0.55 "
                                          r"\(by more than 0.01; pw_radiation\); give thermal.solid_fraction.near_wall as a number within "
                                          r"0.2-0.55, or use an RDF table that covers 0.5800"):
        screen(scene, dem_summary=summary, rdf_grids=grids, solid_fraction=measured, walls={"hot": {"temperature": 1300.0}})
    dark = screen(scene, {"emissivity": 0.05}, dem_summary=summary, rdf_grids=grids, solid_fraction=measured,
                  walls={"hot": {"temperature": 310.0}}, initial_temperature=300.0, inlet_temperature=300.0)
    assert not decision(dark, "pw_radiation").on and dark["solid_fraction"]["near_wall"]["value"] == 0.58


def test_the_threshold_divides_exactly_at_the_share(scene):
    first = screen(scene)
    share = decision(first, "pp_contact").estimate
    assert decision(screen(scene, screening_threshold=share * (1 - 1e-9)), "pp_contact").on
    assert not decision(screen(scene, screening_threshold=share * (1 + 1e-9)), "pp_contact").on


def test_the_contact_styles_reach_the_screening(scene):
    """thermal.styles {pp_contact: dem} (the DEM's own contact radius, c_PP = 1 in Eq. 3) makes the
    screening's particle-particle contact conductance 1/c_PP times the corrected one, and nothing else."""
    plain, dem = screen(scene), screen(scene, styles={"pp_contact": "dem"})
    spec = auto_spec(scene)
    c_pp = (spec["particles"]["youngs_modulus_dem"] / spec["particles"]["youngs_modulus_real"]) ** 0.2  # Eq. 3
    for T, sums in plain["conductance_W_K"].items():
        assert dem["conductance_W_K"][T]["pp_contact"] == pytest.approx(sums["pp_contact"] / c_pp, rel=1e-12)
        assert {m: g for m, g in dem["conductance_W_K"][T].items() if m != "pp_contact"} == \
               {m: g for m, g in sums.items() if m != "pp_contact"}  # fmt: skip
    assert decision(dem, "pp_contact").estimate > decision(plain, "pp_contact").estimate


def test_gas_gap_against_contact(scene):
    """Air at 0.1 Pa (a technical vacuum: a mean free path of centimetres, the gap's conductance
    a thousandth of its value at 1 atm) leaves the contacts to carry the heat: the gas-gap modes are
    screened out and contact conduction stays; at 1 atm the gas gap carries most of it."""
    air = screen(scene)
    poor = screen(scene, gas_pressure=0.1)
    assert decision(air, "pfp").on and decision(air, "pfp").estimate > 0.5
    assert not decision(poor, "pfp").on and not decision(poor, "pfw").on
    assert decision(poor, "pp_contact").on and decision(poor, "pw_contact").on
    assert decision(poor, "pp_contact").estimate > decision(air, "pp_contact").estimate


def test_resolved_particles_by_the_biot_number(scene):
    insulating = screen(scene, {"conductivity": 0.05}, intraparticle="auto")
    metallic = screen(scene, {"conductivity": 200.0}, intraparticle="auto")
    assert decision(insulating, "intraparticle").on and decision(insulating, "intraparticle").estimate > 0.1
    assert not decision(metallic, "intraparticle").on and decision(metallic, "intraparticle").estimate < 0.1
    assert "Bi up to" in decision(metallic, "intraparticle").reason


def test_recycling_follows_the_dem_run():
    assert effects.recycling([False, False, True], 12).on
    assert not effects.recycling([False, False, True], 0).on
    assert "slice" in effects.recycling([False, False, True], 12, travelling_slice=True).reason
    assert not effects.recycling([False, False, True], 12, travelling_slice=True).on


def test_the_stage_uses_the_screening_decisions_and_records_them(scene, tmp_path):
    """stages.thermal with a screening file: the screened modes decide the run (pp_radiation off
    here), every decision goes to the summary, recycling from the DEM run."""
    folder, spec, tables = scene
    screened = {name: Decision(name, name != "pp_radiation", "test", effects.AUTO, "screening").record()
                for name in effects.SCREENED}  # fmt: skip
    (tmp_path / "screening.json").write_text(json.dumps({"decisions": screened}))
    inputs = {"positions": str(folder / "positions.h5"), "walls": str(folder / "walls.h5"),
              "screening": str(tmp_path / "screening.json"), **{k: str(v) for k, v in tables.items()},
              "rdf": str(folder / "rdf.h5")}  # fmt: skip
    outputs = {"thermal": str(tmp_path / "thermal.h5"), "xdmf": str(tmp_path / "thermal.xdmf"),
               "summary": str(tmp_path / "summary.json")}  # fmt: skip
    stages.thermal(auto_spec(scene, intraparticle="auto"), inputs, outputs, 1)
    summary = json.loads((tmp_path / "summary.json").read_text())
    by_effect = {d["effect"]: d for d in summary["effects"]}
    assert set(by_effect) == set(effects.SCREENED) | {"recycling"}
    assert not by_effect["pp_radiation"]["on"] and by_effect["pw_radiation"]["on"]
    assert by_effect["recycling"]["on"] and by_effect["recycling"]["by"] == "dem"
    with h5py.File(tmp_path / "thermal.h5") as f:
        assert json.loads(f.attrs["modes"]) == sorted(set(modes.NAMES) - {"pp_radiation"})
    # The same run with pp_radiation switched off in the config gives the same bits.
    explicit, _ = run_stage(scene, "explicit_off", modes={**dict.fromkeys(modes.NAMES, True), "pp_radiation": False},
                            intraparticle=True)  # fmt: skip
    with h5py.File(tmp_path / "thermal.h5") as screened_run, h5py.File(explicit) as explicit_run:
        np.testing.assert_array_equal(screened_run["temperature"][...], explicit_run["temperature"][...])


def test_the_check_scenes_share_what_they_do_not_change_and_are_checked_before_they_run():
    cfg = config.load(ROOT / "config" / "config.yaml")
    plan = Plan(cfg)
    check = plan.study("screening_check")
    names = [scene["name"] for scene in json.loads(check.spec_json())["scenes"]]
    inputs = check.inputs
    assert names[0] == "default" and names[1:] == list(cfg["screening_check"]["scenes"]) and list(check.scenes) == names
    key = {f: (lambda name, f=f: inputs[name].split("/")[2]) for f in ("thermal", "positions")}
    # its scene (config/tube.yaml) is the default design's base scene as the check was measured: the same runs
    assert inputs["0_auto_thermal"] == path("thermal", plan.keys["base"]["thermal"], "thermal.h5")
    for i, name in enumerate(names):
        auto, on = plan.runs[key["thermal"](f"{i}_auto_thermal")], plan.runs[key["thermal"](f"{i}_all_thermal")]
        assert {s: auto.upstream[s] == on.upstream[s] for s in ("geometry", "dem")} == {"geometry": True, "dem": True}, name
        assert auto.key != on.key and on.upstream["screening"] is None, name  # every auto switched on: nothing to screen
        assert (auto.upstream["dem"] == plan.keys["base"]["dem"]) == (name != "large"), name  # only the large particles need a DEM run
    assert len(inputs) == 3 * 2 * len(names)
    # A scene the pre-flight check refuses stops the check when it is asked for, and only then.
    cfg["screening_check"]["scenes"]["helium_hot"] = {"thermal": {"gas": "helium", "walls": {"heated_wall": {"temperature": "1300"}}}}
    bad = Plan(config.validate(cfg))
    assert bad.targets() == plan.targets()
    with pytest.raises(ConfigError, match=r"screening_check \(helium_hot\): thermal.gas: .*helium"):
        bad.study("screening_check")


def test_switching_an_effect_on_later_reuses_every_stage_it_does_not_change():
    cfg = config.load(ROOT / "config" / "config.yaml")
    cfg["variants"] = {"base": {}, "radiating": {"thermal": {"modes": {"pp_radiation": True}}},
                       "everything": {"thermal": {"effects": "all"}}}  # fmt: skip
    keys = Plan(config.validate(cfg)).keys
    for name in ("radiating", "everything"):
        same = {s: keys[name][s] == keys["base"][s] for s in keys["base"]}
        # the screening runs again (seconds: its spec has the switch) and so does the thermal stage
        assert same == {"geometry": True, "dem": True, "pfp": True, "pfw": True, "rdf": True, "screening": False,
                        "thermal": False}, name  # fmt: skip
    assert keys["everything"]["screening"] is None  # the config decides every effect: nothing to screen
