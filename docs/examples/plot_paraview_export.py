"""
The ParaView export, read with pyvista
======================================

``dpht export`` (:mod:`dpht.export`) writes a thermal run as a folder ParaView opens on its own:
``particles.pvd`` and ``walls.pvd``, time series of VTK files with the particles' radius and
temperature and the wall elements' heat flux per mode. Any VTK reader reads it; here pyvista
reads the last frame of both and draws them off screen.
"""

import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from dpht.export import Sources, export

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # off screen, no X server
import pyvista as pv  # noqa: E402

work = tempfile.TemporaryDirectory()  # removed when the script ends
folder = export(Sources(Path("data/thermal.h5"), Path("data/positions.h5"), Path("data/walls.h5")),
                Path(work.name) / "paraview")
print(sorted(p.name for p in folder.iterdir()))

particles_reader, walls_reader = pv.get_reader(folder / "particles.pvd"), pv.get_reader(folder / "walls.pvd")
times = particles_reader.time_values
print(f"{len(times)} frames, {times[0]:.2f}-{times[-1]:.2f} s")
for reader in (particles_reader, walls_reader):
    reader.set_active_time_value(reader.time_values[-1])
particles, walls = particles_reader.read()[0], walls_reader.read()[0]
print("particle arrays:", particles.point_data.keys())
print("wall arrays:", walls.cell_data.keys())

# %%
# Left, the particles as spheres of their radius coloured by temperature; right, the back half of
# the wall coloured by the heat flux it gives them (mean over the interval from the frame to the next).

plotter = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(900, 700), border=False)
spheres = particles.glyph(geom=pv.Sphere(theta_resolution=12, phi_resolution=12), scale="radius", factor=2.0,
                          orient=False)
bar = {"vertical": True, "position_x": 0.8, "position_y": 0.1, "height": 0.8, "fmt": "%.0f"}
plotter.add_mesh(spheres, scalars="temperature", cmap="inferno", scalar_bar_args={"title": "T (K)", **bar})
plotter.view_xz()
plotter.subplot(0, 1)
back = walls.clip(normal="-y", origin=(0, 0, 0))
plotter.add_mesh(back, scalars="heat_flux", cmap="Blues", scalar_bar_args={"title": "q (W/m^2)", **bar, "fmt": "%.1e"})
plotter.view_xz()
image = plotter.screenshot(return_img=True)
plotter.close()

fig = plt.figure(figsize=(9, 7))
fig.figimage(image)
plt.show()
