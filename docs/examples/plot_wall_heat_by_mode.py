"""
Wall heat by mode
=================

The thermal stage writes the heat the walls give the particles into ``thermal.h5``
(:mod:`dpht.thermal.output`): per frame and particle-wall mode, summed over the wall
(``/wall_heat``) and per wall element (``/element_heat``). Here: the wall's heat rate by mode over
the run, and the energy it adds up to, against the stage's own energy account.
"""

import h5py
import matplotlib.pyplot as plt
import numpy as np

from dpht.thermal.modes import LABELS

with h5py.File("data/thermal.h5", "r") as f:
    time = f["time"][...]  # s
    wall_heat = f["wall_heat"][...]  # W into the particles, one column per mode of attrs wall_modes
    modes = [str(m) for m in f.attrs["wall_modes"]]
    wall_energy = f["energy/wall"][...]  # J received from the wall since the first frame

# %%
# A frame's heat rate is the mean over the interval from that frame to the next, so it is drawn
# as a step over that interval (the last frame's, instantaneous, has no interval).

fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
for column, mode in enumerate(modes):
    ax.stairs(wall_heat[:-1, column], time, label=LABELS[mode])
ax.stairs(wall_heat[:-1].sum(axis=1), time, color="k", label="all modes")
ax.set_xlabel("time (s)")
ax.set_ylabel("heat rate into the particles (W)")
ax.legend()
plt.show()

# %%
# The rates integrated over the run equal the wall energy the stage recorded.

integrated = float(np.sum(wall_heat[:-1].sum(axis=1) * np.diff(time)))
print(f"wall heat over {time[-1]:.2f} s: {integrated:.4f} J from the rates, {wall_energy[-1]:.4f} J recorded")
for column, mode in enumerate(modes):
    share = np.sum(wall_heat[:-1, column] * np.diff(time)) / integrated
    print(f"  {LABELS[mode]}: {100 * share:.1f}%")
