"""
Two variants compared
=====================

With several variants the workflow compares them in ``results/<run>/comparison/``:
``variants.csv`` holds each variant's wall heat flux along the tube, ``variants.totals.csv`` its
total wall heat rate relative to the first variant. Here the tiny scene in air and in a vacuum,
where the particles exchange heat with the wall only where they touch it and by radiation.
"""

import csv

import matplotlib.pyplot as plt
import numpy as np

with open("data/variants.csv", newline="") as f:
    rows = list(csv.DictReader(f))
variants = list(dict.fromkeys(row["variant"] for row in rows))

fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
for variant in variants:
    mine = [row for row in rows if row["variant"] == variant]
    edges = np.array([float(mine[0]["distance_lo_m"])] + [float(row["distance_hi_m"]) for row in mine])
    ax.stairs([float(row["flux_total_W_m2"]) / 1e3 for row in mine], 1e3 * edges, label=variant)
ax.set_xlabel("distance from the inlet (mm)")
ax.set_ylabel("wall heat flux into the particles (kW/m$^2$)")
ax.legend()
plt.show()

# %%
# The totals, over the steady window:

with open("data/variants.totals.csv", newline="") as f:
    for row in csv.DictReader(f):
        print(f"{row['variant']:>8}: {float(row['heat_total_W']):6.2f} W ({100 * float(row['relative_to_first']):+.0f}%)")
