"""
Cross-section and wall heat flux
================================

The figure functions of :mod:`dpht.figures.scene` draw from the three stage outputs, the DEM
positions, the wall table and the thermal output, and each writes a PNG (and the numbers it plots
in a CSV beside it). Here the cross-section at the last frame, particles coloured by temperature
with the heated wall in red and a scale bar, and the heat flux along the tube by mode.
"""

import csv
import tempfile
from pathlib import Path

import matplotlib.image
import matplotlib.pyplot as plt

from dpht.figures import scene

positions, walls, thermal = "data/positions.h5", "data/walls.h5", "data/thermal.h5"
work = tempfile.TemporaryDirectory()  # removed when the script ends
out = Path(work.name)
section = scene.cross_section(positions, thermal, walls, out / "cross_section.png", window_size=(600, 900))
flux = scene.wall_heat_flux(thermal, walls, out / "wall_heat_flux.png")


def show(png):
    """A PNG the figure functions wrote, on a figure of its own."""
    image = matplotlib.image.imread(png)
    fig = plt.figure(figsize=(image.shape[1] / 100, image.shape[0] / 100))
    fig.figimage(image)
    plt.show()


show(section)

# %%
# The flux is averaged over the figures' steady window (the second half of the run), in bins
# along the tube; its CSV holds the numbers.

show(flux)
with open(flux.with_suffix(".csv"), newline="") as f:
    for row in csv.DictReader(f):
        print(f"{1e3 * float(row['distance_lo_m']):4.1f}-{1e3 * float(row['distance_hi_m']):4.1f} mm: "
              f"{float(row['flux_total_W_m2']) / 1e3:6.1f} kW/m^2, of which gas gap {float(row['flux_pfw_W_m2']) / 1e3:6.1f}")
