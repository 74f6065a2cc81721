"""What leaves a tube through its outlet: the temperatures of the particles crossing the periodic
boundary downwards, where the thermal stage resets them to the inlet temperature, taken at the start
of the interval in which they cross (thermal.h5 does not store the state at the crossing itself:
this misses the last interval's heating, 0.0005 K of the default tube's 3.44 K outlet rise at its
0.01 s step); and their mixing-cup temperature, the temperature of their mean specific enthalpy
(every particle carries the same mass, so this is the flow-weighted outlet temperature an exit
thermocouple in a mixing cup would read).
"""

from __future__ import annotations

import h5py
import numpy as np

from dpht.closures import heat_capacity
from dpht.dem.dumps import PositionsFile
from dpht.thermal import integrate


def leaving_temperatures(thermal_h5, positions_h5, frames) -> np.ndarray:
    """Temperatures (K) of the particles that left through the outlet between consecutive thermal
    frames of ``frames`` (increasing indices into thermal.h5, e.g. a window's), each once per passage:
    a particle crossing between frames k-1 and k is taken from row k-1 (row k holds the state at the
    start of its own frame, after the resets of the particles that re-entered there). Empty for a DEM run without a periodic z axis; lost particles (NaN)
    are left out."""
    frames = np.asarray(frames, dtype=int)
    leaving = []
    with h5py.File(thermal_h5, "r") as f, PositionsFile(positions_h5) as dem:
        dem_frames, temperature = f["dem_frame"][...], f["temperature"]
        lo, hi = np.asarray(dem.attrs["box_lo"]), np.asarray(dem.attrs["box_hi"])
        if not np.asarray(dem.attrs["periodic"], dtype=bool)[2] or frames.size < 2:
            return np.empty(0)
        previous = dem.frame(int(dem_frames[frames[0]]))
        for k in frames[1:]:
            current = dem.frame(int(dem_frames[k]))
            crossed = integrate.wrapped(previous.image, current.image, previous.positions, current.positions, lo, hi, 2)
            leaving.append(temperature[k - 1][crossed])
            previous = current
    leaving = np.concatenate(leaving).astype(np.float64)
    return leaving[np.isfinite(leaving)]


def mixing_cup(temperatures: np.ndarray, specific_heat) -> float:
    """Temperature (K) of the mean specific enthalpy of equal-mass particles at ``temperatures`` (K),
    with ``specific_heat`` the config's (a number or an expression of T or T_C)."""
    table = heat_capacity.build(heat_capacity.specific_heat(specific_heat), float(temperatures.min()),
                                float(temperatures.max()))  # fmt: skip
    return float(table.temperature(np.mean(table.enthalpy(temperatures))))


def enthalpy_difference(high: float, low: float, specific_heat) -> float:
    """h(high) - h(low) (J/kg) between two temperatures (K) for the config's ``specific_heat``."""
    table = heat_capacity.build(heat_capacity.specific_heat(specific_heat), min(low, high), max(low, high))
    return float(table.enthalpy(np.array([high]))[0] - table.enthalpy(np.array([low]))[0])
