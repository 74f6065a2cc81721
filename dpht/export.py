"""A thermal run as a folder ParaView opens on its own (``python -m dpht export``).

The thermal stage's ``thermal.xdmf`` shows the temperatures only and reads the positions from the DEM
run's folder (``../../dem/<key>/positions.h5``), so it breaks when copied. :func:`export` writes
everything into one folder, with file names relative to it (copy or move the folder as a whole)::

    particles.pvd            time series of the particles (open this in ParaView)
    walls.pvd                time series of the wall mesh
    frames/particles_<k>.vtp  one VTK XML PolyData file per thermal frame k (vertices)
    frames/walls_<k>.vtp      one per thermal frame (triangles; the same mesh in every frame)
    README.md                what the arrays are, their units, and what the thermal file does not hold

The arrays, with their units, are :data:`PARTICLE_ARRAYS` and :data:`WALL_ARRAYS`; the README lists
them. Heat rates are W into the particles (negative: the wall cools them), the mean over the interval
from the frame to the next (the last frame's: instantaneous), as in the thermal file
(:mod:`dpht.thermal.output`). The thermal file holds no heat rate per particle (only the wall
elements' per particle-wall mode and their sums), so none is exported.

Sources: a design variant's results folder (``results/<run>/<variant>``: its ``summary.json`` names the
stage runs) or a thermal run folder (``results/thermal/<key>``: the variant naming it in
``results/*/*/summary.json`` gives its DEM and geometry runs), or any files given explicitly.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpht.errors import DPHTError
from dpht.figures.scene import _check_aligned, _open, _wall_modes
from dpht.thermal.model import wall_temperatures
from dpht.geometry.walls import Walls, load_walls

FORMAT = "dpht-paraview-1"  # in README.md's first line: what may be replaced by a new export
PARTICLES, WALLS, FRAMES = "particles.pvd", "walls.pvd", "frames"

# name -> (unit, meaning); "{mode}" stands for one array per particle-wall mode (attr wall_modes).
PARTICLE_ARRAYS = {
    "id": ("", "DEM particle id"),
    "radius": ("m", "particle radius (ParaView: a Glyph filter, sphere, scale array radius, scale factor 2)"),
    "temperature": ("K", "particle temperature at the frame"),
}
WALL_ARRAYS = {
    "zone": ("", "wall zone, index into the field data zone_names (thermal.walls sets each zone's condition)"),
    "surface": ("", "wall surface a particle touches as one wall, index into the field data surface_names"),
    "area": ("m^2", "element area"),
    "normal": ("", "unit normal, pointing into the particle region"),
    "wall_temperature": ("K", "the element's temperature from its zone's condition (thermal.walls; NaN: adiabatic); "
                              "absent for a travelling slice, whose walls change with its height, and when "
                              "thermal.h5 records no config"),
    "heat_flux": ("W/m^2", "heat flux into the particles, all particle-wall modes (> 0: the wall heats them)"),
    "heat_flux_{mode}": ("W/m^2", "heat flux into the particles by one particle-wall mode"),
}
WALL_FIELDS = {  # per wall file, field data
    "wall_heat_{mode}": ("W", "heat rate into the particles by one particle-wall mode, all elements (/wall_heat)"),
    "zone_names": ("", "names of the zones"),
    "surface_names": ("", "names of the surfaces"),
}


@dataclass(frozen=True)
class Sources:
    """The three files an export reads."""

    thermal: Path  # thermal.h5 of the thermal stage
    positions: Path  # positions.h5 of the DEM stage
    walls: Path  # walls.h5 of the geometry stage


def find_sources(folder, *, positions=None, walls=None) -> Sources:
    """The files of a variant's results folder or of a thermal run folder (module docstring);
    ``positions`` and ``walls`` given explicitly take precedence."""
    folder = Path(folder)
    if (folder / "thermal.h5").is_file():
        keys = _variant_keys(folder.parent.parent, folder.name) if positions is None or walls is None else {}
        results, thermal = folder.parent.parent, folder / "thermal.h5"
    elif (folder / "summary.json").is_file():
        keys = _stage_keys(folder / "summary.json")
        results = folder.parent.parent  # results/<run>/<variant>/ (dpht.paths)
        thermal = results / "thermal" / keys["thermal"] / "thermal.h5"
    else:
        raise DPHTError(f"{folder}: neither a thermal run folder (with thermal.h5) nor a variant's results folder "
                        "(with summary.json), e.g. results/thermal/<key> or results/<run>/<variant>")  # fmt: skip
    sources = Sources(
        thermal,
        Path(positions) if positions is not None else results / "dem" / keys["dem"] / "positions.h5",
        Path(walls) if walls is not None else results / "geometry" / keys["geometry"] / "walls.h5",
    )
    for name, path in vars(sources).items():
        if not path.is_file():
            raise DPHTError(f"{folder}: its {name} file {path} does not exist")
    return sources


def _stage_keys(summary: Path) -> dict:
    try:
        keys = json.loads(summary.read_text())["stage_keys"]
        missing = [stage for stage in ("geometry", "dem", "thermal") if not keys.get(stage)]
    except (ValueError, KeyError, TypeError, AttributeError):
        raise DPHTError(f"{summary}: not a variant summary (a JSON object with stage_keys)") from None
    if missing:
        raise DPHTError(f"{summary}: stage_keys names no {', '.join(missing)} run")
    return keys


def _variant_keys(results: Path, thermal_key: str) -> dict:
    """The stage keys of the first variant (by name) whose summary names thermal run ``thermal_key``."""
    for summary in sorted(results.glob("*/*/summary.json")):  # results/<run>/<variant>/ (dpht.paths)
        try:
            keys = _stage_keys(summary)
        except DPHTError:
            continue  # another summary, e.g. a stage's or a study's
        if keys["thermal"] == thermal_key:
            return keys
    raise DPHTError(f"no results/<run>/<variant>/summary.json under {results} names thermal run {thermal_key}: give the "
                    "DEM run's positions file and the geometry run's wall table (--positions, --walls)")  # fmt: skip


def export(sources: Sources, out) -> Path:
    """Write the folder ``out`` (module docstring) from ``sources``; an earlier export there is
    replaced, any other non-empty folder refused. Returns ``out``."""
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not _is_export(out):
        raise DPHTError(f"{out}: a non-empty folder that is no ParaView export ({out / 'README.md'} does not start "
                        f"with {FORMAT}); choose another --out")  # fmt: skip
    walls = load_walls(sources.walls)
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        _write(sources, walls, work)
        if out.exists():
            shutil.rmtree(out)
        os.replace(work, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


def _is_export(folder: Path) -> bool:
    readme = folder / "README.md"
    return readme.is_file() and readme.read_text().startswith(f"# {FORMAT}")


def _write(sources: Sources, walls: Walls, folder: Path) -> None:
    # Off-screen VTK without an X server (pyvista imports VTK's rendering), as dpht.figures.scene.
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    (folder / FRAMES).mkdir()
    with _open(sources.positions, "positions") as fp, _open(sources.thermal, "thermal") as ft:
        dem_frames = _check_aligned(sources.positions, fp, sources.thermal, ft)
        n_elements = ft["element_heat"].shape[1]
        if n_elements != len(walls):
            raise DPHTError(f"{sources.thermal}: element_heat has {n_elements} wall elements, "
                            f"the wall table {sources.walls} {len(walls)}")  # fmt: skip
        modes, times, wall_heat = _wall_modes(ft), ft["time"][...], ft["wall_heat"][...]
        radius, ids = float(fp.attrs["radius"]), fp["ids"][...]
        mesh = wall_mesh(pv, walls)
        thermal = json.loads(ft.attrs.get("spec", "{}")).get("thermal", {})  # the run's config
        if "walls" in thermal and "slice" not in thermal:
            mesh.cell_data["wall_temperature"] = wall_temperatures(walls, thermal["walls"])
        entries = {PARTICLES: [], WALLS: []}
        for k, dem_frame in enumerate(dem_frames):
            x = fp["positions"][dem_frame]
            temperature = ft["temperature"][k]
            present = np.all(np.isfinite(x), axis=1) & np.isfinite(temperature)  # lost particles are left out
            particles = pv.PolyData(np.ascontiguousarray(x[present]))
            particles.point_data["id"] = ids[present]
            particles.point_data["radius"] = np.full(int(present.sum()), radius)
            particles.point_data["temperature"] = temperature[present]
            heat = ft["element_heat"][k].astype(np.float64)  # (M, modes) W
            frame = mesh.copy(deep=False)
            frame.cell_data["heat_flux"] = heat.sum(axis=1) / walls.area
            for j, mode in enumerate(modes):
                frame.cell_data[f"heat_flux_{mode}"] = heat[:, j] / walls.area
                frame.field_data[f"wall_heat_{mode}"] = [float(wall_heat[k, j])]
            for kind, data in ((PARTICLES, particles), (WALLS, frame)):
                name = f"{FRAMES}/{Path(kind).stem}_{k:06d}.vtp"
                data.field_data["TimeValue"] = [float(times[k])]  # ParaView's name for a dataset's time
                data.save(folder / name, binary=True)
                entries[kind].append((float(times[k]), name))
    for kind, files in entries.items():
        _write_pvd(folder / kind, files)
    (folder / "README.md").write_text(readme(sources, modes, len(times), len(ids), len(walls)))


def wall_mesh(pv, walls: Walls):
    """The wall triangles as one PolyData, corners shared where they coincide exactly, with the
    static cell arrays (zone, surface, area, normal) and the zone and surface names."""
    corners, index = np.unique(walls.vertices.reshape(-1, 3), axis=0, return_inverse=True)
    m = len(walls)
    faces = np.column_stack([np.full(m, 3), index.reshape(m, 3)]).ravel()
    mesh = pv.PolyData(corners, faces)
    mesh.cell_data["zone"] = walls.zone
    mesh.cell_data["surface"] = walls.surface
    mesh.cell_data["area"] = walls.area
    mesh.cell_data["normal"] = walls.normal
    mesh.field_data["zone_names"] = list(walls.zone_names)
    mesh.field_data["surface_names"] = list(walls.surface_names)
    return mesh


def _write_pvd(path: Path, files: list[tuple[float, str]]) -> None:
    """A ParaView collection file: one dataset per time, by a path relative to the file's folder."""
    rows = "\n".join(f'    <DataSet timestep="{t!r}" part="0" file="{name}"/>' for t, name in files)
    path.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                    f"{rows}\n  </Collection>\n</VTKFile>\n")  # fmt: skip


def readme(sources: Sources, modes, n_frames: int, n_particles: int, n_elements: int) -> str:
    """README.md of an export: the sources, the arrays with their units, and what is not there."""

    def table(arrays: dict) -> list[str]:
        rows = ["| array | unit | meaning |", "|---|---|---|"]
        for name, (unit, meaning) in arrays.items():
            names = [name.format(mode=m) for m in modes] if "{mode}" in name else [name]
            rows += [f"| {n} | {unit} | {meaning} |" for n in names]
        return rows

    lines = [
        f"# {FORMAT}: a thermal run for ParaView",
        "",
        f"Open `{PARTICLES}` and `{WALLS}` in ParaView (File > Open); {n_frames} frames, {n_particles} particles, "
        f"{n_elements} wall elements. Every path is relative to this folder: copy or move it as a whole.",
        "",
        "Written by `python -m dpht export` from:",
        "",
        *(f"- {name}: `{path.resolve()}`" for name, path in vars(sources).items()),
        "",
        "Heat rates and fluxes are into the particles (negative: the wall cools them), the mean over the interval "
        "from the frame to the next (the last frame's: instantaneous). Lengths in m, temperatures in K.",
        "",
        "## particles (point data; lost particles are left out of a frame)",
        "",
        *table(PARTICLE_ARRAYS),
        "",
        "## walls (cell data)",
        "",
        *table(WALL_ARRAYS),
        "",
        "Field data of every walls file:",
        "",
        *table(WALL_FIELDS),
        "",
        "## not in the thermal file, so not here",
        "",
        "- heat rates per particle (by mode or in total): the thermal stage stores the particles' temperatures and "
        "the wall elements' heat per particle-wall mode only;",
        "- the particle-particle heat rates.",
        "",
    ]
    return "\n".join(lines)
