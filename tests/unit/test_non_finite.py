"""A non-finite temperature anywhere in a step stops the run with a message naming the frame and
the particle (before: a NaN enthalpy became a clamped, finite-looking temperature, and a NaN heat
rate a bare ``ValueError`` from ``math.ceil``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dpht.errors import DPHTError
from dpht.thermal import integrate
from dpht.thermal.state import State
from dpht.util.interp import Table2D
from dpht.verification import scenes
from test_thermal_stage import run_stage, scene  # noqa: F401  (the stage's synthetic scene fixture)

R = scenes.RADIUS


def frame_and_model(modes=("pp_contact", "pfp", "pw_contact", "pfw")):
    s = scenes.spec(modes, walls={"hot": {"temperature": 600.0}})
    model = scenes.build_model(s, scenes.plane_walls())
    positions = scenes.random_cluster(n=200, seed=1)
    frame = integrate.prepare_frame(model, positions, None, None, (False, False, False))
    h = model.enthalpy.enthalpy(np.full(len(positions), 400.0))
    return model, frame, h


def test_a_nan_enthalpy_names_the_frame_and_particle():
    model, frame, h = frame_and_model()
    h[37] = np.nan
    with pytest.raises(DPHTError, match=r"frame 12, sub-step 0: particle 37 .* enthalpy nan") as error:
        integrate.advance(model, frame, h, 0.01, integrate.Rates.for_frame(model, frame), frame_number=12)
    assert isinstance(error.value, integrate.NonFiniteTemperature) and error.value.particle == 37


def test_a_nan_conductance_names_the_particle_it_reaches():
    """A NaN entry of the PFW table: the first particle whose heat rate it spoils is named."""
    model, frame, h = frame_and_model()
    pfw = model.tables["pfw"]
    values = pfw.values.copy()
    values[:, :] = np.nan  # every gas-gap look-up
    broken = dataclasses.replace(model, tables={**model.tables, "pfw": Table2D(pfw.x0, pfw.dx, pfw.y0, pfw.dy, values)})
    rates = integrate.Rates.for_frame(broken, frame)
    with pytest.raises(DPHTError, match=r"frame 3, sub-step 0: particle \d+ .* heat rate nan W") as error:
        integrate.advance(broken, frame, h, 0.01, rates, frame_number=3)
    near_wall = frame.particles[np.flatnonzero(np.isnan(rates.q))]
    assert isinstance(error.value, integrate.NonFiniteTemperature) and error.value.particle == near_wall[0]


def test_the_stage_names_the_frame_and_the_dem_id(scene, monkeypatch):  # noqa: F811
    initial = State.initial

    def poisoned(model, n):
        state = initial(model, n)
        state.h[10] = np.inf
        return state

    monkeypatch.setattr(State, "initial", staticmethod(poisoned))
    with pytest.raises(DPHTError, match=r"frame 0, sub-step 0: particle 10 .* enthalpy inf J/kg.*Its DEM id is 11\."):
        run_stage(scene, "poisoned")
