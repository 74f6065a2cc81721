"""Figures from synthetic stage outputs: the images are drawn, and the numbers written beside them
(binned heat flux, temperature profiles, energy balance, HTC curves) match fields with known values."""

import csv
import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from matplotlib.image import imread

from dpht import config, stages
from dpht.closures import htc
from dpht.dem import dumps
from dpht.figures import scene as figures
from dpht.thermal import output as thermal_io, stage as thermal_stage
from dpht.verification import scenes
from dpht.errors import DPHTError
from dpht.plan import FIGURES
from dpht.thermal.modes import NAMES, PW_MODES, needing
from figure_files import check_figure
from dpht.geometry.errors import GeometryError
from dpht.geometry.walls import Walls, save_walls

TUBE_RADIUS = 4.5e-3  # m
LENGTH = 0.05  # m, the periodic domain, inlet at the top
HEATED = (0.004, 0.040)  # m
PARTICLE_RADIUS = 5e-4  # m
MODES = list(PW_MODES)
ENABLED = [m for m in NAMES if m not in needing("rdf")]  # radiation off: its heat stays zero
TIME = np.linspace(0.0, 1.0, 11)  # s; window (0.5, 1) = intervals 5..9
IN_WINDOW = TIME >= 0.5 - 1e-12
FLUX_A = np.array([-2.0e3, -3.0e4, 0.0])  # W/m^2, q''_m(z) = A_m + B_m z on the heated wall
FLUX_B = np.array([1.0e4, 2.0e5, 0.0])  # W/m^3


# ------------------------------------------------------------------------ synthetic files


def tube_walls(n_theta=24, n_z=50, hole=3e-3):
    """Faceted tube (zones by height) with an annular orifice plate at the bottom of the heated range."""
    theta = np.linspace(0, 2 * np.pi, n_theta + 1)
    ring = np.column_stack([np.cos(theta), np.sin(theta)])
    z = np.linspace(0.0, LENGTH, n_z + 1)
    tris = []
    for z0, z1 in zip(z[:-1], z[1:]):
        for (c0, s0), (c1, s1) in zip(ring[:-1], ring[1:]):
            p = [np.array([TUBE_RADIUS * c, TUBE_RADIUS * s, h]) for c, s, h in
                 ((c0, s0, z0), (c1, s1, z0), (c1, s1, z1), (c0, s0, z1))]
            tris += [(p[0], p[1], p[2]), (p[0], p[2], p[3])]
    tube = np.array(tris)
    zc = tube[:, :, 2].mean(axis=1)
    zone = np.where((zc > HEATED[0]) & (zc < HEATED[1]), 0, 1)
    plate = []
    for (c0, s0), (c1, s1) in zip(ring[:-1], ring[1:]):
        p = [np.array([r * c, r * s, HEATED[0]]) for r, c, s in
             ((hole, c0, s0), (TUBE_RADIUS, c0, s0), (TUBE_RADIUS, c1, s1), (hole, c1, s1))]
        plate += [(p[0], p[1], p[2]), (p[0], p[2], p[3])]
    vertices = np.concatenate([tube, np.array(plate)])
    zone = np.concatenate([zone, np.full(len(plate), 2)])
    return Walls.from_vertices(vertices, zone, ("heated_wall", "adiabatic_wall", "orifice"))


def write_walls(path, walls):
    save_walls(path, walls, json.dumps({"synthetic": True}), 2 * PARTICLE_RADIUS)
    return path


def write_thermal(path, *, ids, temperature, element_heat, particles=None, recycled=None, fmt=thermal_io.FORMAT,
                  complete=True):
    """A thermal output as the lead specified it; /wall_heat is the element sum; the energy group
    is consistent with it unless ``particles``/``recycled`` are given."""
    n_frames = len(TIME)
    wall_heat = element_heat.astype(np.float64).sum(axis=1)
    dt = np.diff(TIME)
    wall = np.concatenate([[0.0], np.cumsum(wall_heat[:-1].sum(axis=1) * dt)])
    recycled = np.zeros(n_frames) if recycled is None else recycled
    particles = 5.0 + wall + recycled if particles is None else particles
    with h5py.File(path, "w") as f:
        f.attrs.update(format=fmt, modes=json.dumps(ENABLED), inlet_temperature=303.15, wall_modes=MODES,
                       complete=complete)
        f["ids"] = ids
        f["time"] = TIME
        f["temperature"] = temperature.astype(np.float32)
        f["wall_heat"] = wall_heat
        f["element_heat"] = element_heat.astype(np.float32)
        f["substeps"] = np.ones(n_frames, np.int32)
        f["energy/particles"] = particles
        f["energy/wall"] = wall
        f["energy/recycled"] = recycled
    return path


def tube_positions(n=3000, seed=1):
    """(F, N, 3) particle centres uniform in the tube (a new draw per frame)."""
    rng = np.random.default_rng(seed)
    r = (TUBE_RADIUS - PARTICLE_RADIUS) * np.sqrt(rng.random((len(TIME), n)))
    phi = 2 * np.pi * rng.random((len(TIME), n))
    z = LENGTH * rng.random((len(TIME), n))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def write_positions(path, x, fmt=dumps.FORMAT):
    with h5py.File(path, "w") as f:
        f.attrs["format"] = fmt
        f["positions"] = x
        f["ids"] = np.arange(1, x.shape[1] + 1, dtype=np.int64)
        f["time"] = TIME
        f["image"] = np.zeros(x.shape, np.int32)
        f.attrs.update(radius=PARTICLE_RADIUS, box_lo=[-TUBE_RADIUS, -TUBE_RADIUS, 0.0],
                       box_hi=[TUBE_RADIUS, TUBE_RADIUS, LENGTH], periodic=[False, False, True])
    return path


def known_element_heat(walls, outside_factor=3.0):
    """Element heat q''_m(z_centroid) x area on the heated wall, zero elsewhere; frames before the
    window carry ``outside_factor`` times as much, and the last frame (no interval) NaN."""
    z = walls.centroid[:, 2]
    heated = walls.zone_mask("heated_wall")
    q = np.where(heated[:, None], FLUX_A + FLUX_B * z[:, None], 0.0) * walls.area[:, None]
    factor = np.where(IN_WINDOW, 1.0, outside_factor)
    heat = factor[:, None, None] * q[None]
    heat[-1] = np.nan
    return heat, q


def field(x, kind):
    """Known temperature fields [K]: linear in z, or linear in r (plus 500 K before the window)."""
    value = 400.0 + 2.0e4 * x[..., 2] if kind == "axial" else 900.0 - 5.0e4 * np.hypot(x[..., 0], x[..., 1])
    value = value + np.where(IN_WINDOW, 0.0, 500.0)[:, None]
    value[:, ::97] = np.nan  # lost particles
    return value


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("figures")
    walls = tube_walls()
    x = tube_positions()
    ids = np.arange(1, x.shape[1] + 1, dtype=np.int64)
    heat, q = known_element_heat(walls)
    files = {
        "walls": write_walls(root / "walls.h5", walls),
        "positions": write_positions(root / "positions.h5", x),
        "thermal": write_thermal(root / "thermal.h5", ids=ids, temperature=field(x, "axial"), element_heat=heat),
        "thermal_radial": write_thermal(root / "thermal_r.h5", ids=ids, temperature=field(x, "radial"),
                                        element_heat=heat),
        "thermal_double": write_thermal(root / "thermal_2.h5", ids=ids, temperature=field(x, "axial"),
                                        element_heat=2.0 * heat),
    }
    return {"root": root, "table": walls, "x": x, "q": q, **files}


def read_csv(path):
    with open(path) as stream:
        rows = list(csv.DictReader(stream))
    return {key: np.array([float(r[key]) if key not in ("kind", "variant") else r[key] for r in rows])
            for key in rows[0]}


def assert_picture(png):
    """A real picture: a non-trivial PNG whose pixels vary."""
    image = imread(png)[..., :3]
    assert png.stat().st_size > 5000
    assert image.std() > 0.05


# (height, width) in pixels of each figure of the figures stage
FIGURE_PIXELS = {"cross_section": (1200, 800), "wall_heat_flux": (660, 960), "wall_heat_history": (720, 960),
                 "temperature_profiles": (600, 1440), "htc_curves": (600, 1440), "engineering": (660, 1920)}


# ----------------------------------------------------------------------------------- tests


def test_flux_bins_reproduce_known_flux(case, tmp_path):
    png = figures.wall_heat_flux(case["thermal"], case["walls"], tmp_path / "flux.png")
    assert_picture(png)
    table = read_csv(png.with_suffix(".csv"))
    z_top = LENGTH
    # Bins cover the heated wall only (adiabatic tube and plate carry no heat).
    assert table["distance_lo_m"][0] == pytest.approx(z_top - HEATED[1], abs=1e-15)
    assert table["distance_hi_m"][-1] == pytest.approx(z_top - HEATED[0], abs=1e-15)
    # q'' is linear in z: the area-weighted bin mean equals q'' at the area-weighted mean height.
    z_mean = z_top - table["distance_mean_m"]
    for j, mode in enumerate(MODES):
        expected = FLUX_A[j] + FLUX_B[j] * z_mean
        np.testing.assert_allclose(table[f"flux_{mode}_W_m2"], expected, rtol=1e-6, atol=1e-9)
    # Flux x area over the bins is the total heat of the window, not of the 3x larger early frames.
    total_q = case["q"].sum()
    assert np.sum(table["flux_total_W_m2"] * table["area_m2"]) == pytest.approx(total_q, rel=1e-6)
    heated_area = case["table"].area[case["table"].zone_mask("heated_wall")].sum()
    assert table["area_m2"].sum() == pytest.approx(heated_area, rel=1e-12)


def test_flux_explicit_bins_and_zones(case, tmp_path):
    edges = LENGTH - np.array([0.046, 0.030, 0.010])  # decreasing z: increasing distance
    edges = np.sort(edges)
    png = figures.wall_heat_flux(case["thermal"], case["walls"], tmp_path / "f.png", bins=edges,
                                 zones=["heated_wall", "adiabatic_wall"])
    table = read_csv(png.with_suffix(".csv"))
    walls = case["table"]
    tube = walls.zone_mask("heated_wall") | walls.zone_mask("adiabatic_wall")
    d = LENGTH - walls.centroid[:, 2]
    for lo, hi, area, heat in zip(edges[:-1], edges[1:], table["area_m2"], table["heat_total_W"]):
        inside = tube & (d >= lo) & ((d < hi) | (hi == edges[-1]) & (d <= hi))
        assert area == pytest.approx(walls.area[inside].sum(), rel=1e-12)
        assert heat == pytest.approx(case["q"][inside].sum(), rel=1e-6)
    with pytest.raises(DPHTError, match="no_such_zone"):
        figures.wall_heat_flux(case["thermal"], case["walls"], tmp_path / "g.png", zones=["no_such_zone"])


def test_temperature_profiles_match_known_fields(case, tmp_path):
    frames = figures.window_frames(TIME, (0.5, 1.0))
    png = figures.temperature_profiles(case["positions"], case["thermal"], tmp_path / "axial.png")
    assert_picture(png)
    axial = read_csv(png.with_suffix(".axial.csv"))
    np.testing.assert_allclose(axial["temperature_K"], 400.0 + 2.0e4 * axial["z_mean_m"], rtol=0, atol=1e-3)
    alive = np.isfinite(field(case["x"], "axial")[frames])
    assert axial["samples"].sum() == alive.sum()
    assert axial["z_hi_m"][1] - axial["z_lo_m"][1] == pytest.approx(2 * PARTICLE_RADIUS)

    band = (0.0, 0.01)
    png = figures.temperature_profiles(case["positions"], case["thermal_radial"], tmp_path / "radial.png",
                                       radial_band=band)
    radial = read_csv(png.with_suffix(".radial.csv"))
    filled = radial["samples"] > 0
    np.testing.assert_allclose(radial["temperature_K"][filled], 900.0 - 5.0e4 * radial["r_mean_m"][filled],
                               rtol=0, atol=1e-3)
    x = case["x"][frames]
    in_band = (x[..., 2] >= band[0]) & (x[..., 2] <= band[1]) & alive
    assert radial["samples"].sum() == in_band.sum()
    assert not filled[-1]  # no centre within one radius of the wall


def test_wall_heat_history_energy_residual(case, tmp_path):
    heat, _ = known_element_heat(case["table"])
    x = case["x"]
    ids = np.arange(1, x.shape[1] + 1)
    recycled = -0.3 * TIME  # J, recycling removes 0.3 W
    leak = 0.7  # W gained by the particles from nowhere
    total = heat[:-1].sum(axis=(1, 2))
    particles = 5.0 + np.concatenate([[0.0], np.cumsum(total * np.diff(TIME))]) + recycled + leak * TIME
    path = write_thermal(tmp_path / "t.h5", ids=ids, temperature=field(x, "axial"), element_heat=heat,
                         particles=particles, recycled=recycled)
    png = figures.wall_heat_history(path, tmp_path / "history.png")
    assert_picture(png)
    table = read_csv(png.with_suffix(".csv"))
    np.testing.assert_allclose(table["residual_W"], leak, rtol=0, atol=1e-9 * np.abs(total).max())
    np.testing.assert_allclose(table["heat_total_W"], total, rtol=1e-12)
    assert len(table["time_start_s"]) == len(TIME) - 1


def test_htc_curves_show_published_tail(tmp_path):
    # The paper's continuum model (the gas pressure's temperature jump is tested in tests/unit/test_htc.py).
    png = figures.htc_curves(tmp_path / "htc.png", radius=5e-4, k_solid=2.0, solid_fraction=0.60, pressure="continuum")
    assert_picture(png)
    table = read_csv(png.with_suffix(".csv"))

    def tail(kind, temperature, at):
        rows = (table["kind"] == kind) & (table["temperature_K"] == temperature)
        d, h = table["distance_over_R"][rows], table["htc_W_K"][rows]
        return h[np.argmin(np.abs(d - at))] / h.max()

    # DPHT paper, Section 3.4: at 1273 K the PFP HTC at 3R is still about 7% of its peak; lower at
    # low temperature.
    assert tail("pfp", 1273.0, 3.0) == pytest.approx(0.07, abs=0.01)
    assert tail("pfp", 300.0, 3.0) < tail("pfp", 1273.0, 3.0)
    # The PFW curves span the same gaps: at d_iw = 1.5R the same fraction as PFP at 3R.
    assert tail("pfw", 1273.0, 1.5) == pytest.approx(tail("pfp", 1273.0, 3.0), rel=1e-9)


def test_compare_variants_totals_and_profiles(case, tmp_path):
    png = figures.compare_variants(
        [("base", case["thermal"], case["walls"]), ("double", case["thermal_double"], case["walls"])],
        tmp_path / "compare.png")
    assert_picture(png)
    totals = read_csv(png.with_suffix(".totals.csv"))
    assert totals["heat_total_W"][0] == pytest.approx(case["q"].sum(), rel=1e-6)
    assert totals["relative_to_first"][1] == pytest.approx(1.0, rel=1e-6)
    table = read_csv(png.with_suffix(".csv"))
    base, double = (table["flux_total_W_m2"][table["variant"] == v] for v in ("base", "double"))
    np.testing.assert_allclose(double, 2.0 * base, rtol=1e-6)
    with pytest.raises(DPHTError, match="distinct"):
        figures.compare_variants([("a", case["thermal"], case["walls"])] * 2, tmp_path / "x.png")


def test_cross_section_renders_particles(case, tmp_path):
    png = figures.cross_section(case["positions"], case["thermal"], case["walls"], tmp_path / "cs.png",
                                z_scale=0.5, window_size=(400, 600))
    assert_picture(png)
    image = imread(png)[..., :3]
    assert image.shape[:2] == (600, 400)
    saturation = image.max(axis=-1) - image.min(axis=-1)
    assert np.mean(saturation > 0.3) > 0.01  # coloured spheres, not just grey walls and text
    with pytest.raises(DPHTError, match="no particle"):
        figures.cross_section(case["positions"], case["thermal"], case["walls"], tmp_path / "e.png",
                              slab=1e-9)


def test_output_is_deterministic(case, tmp_path):
    a = figures.wall_heat_flux(case["thermal"], case["walls"], tmp_path / "a.png")
    b = figures.wall_heat_flux(case["thermal"], case["walls"], tmp_path / "b.png")
    assert a.read_bytes() == b.read_bytes()
    assert a.with_suffix(".csv").read_bytes() == b.with_suffix(".csv").read_bytes()


def test_bad_inputs_name_the_file(case, tmp_path):
    missing = tmp_path / "missing.h5"
    with pytest.raises(DPHTError, match="missing.h5"):
        figures.wall_heat_history(missing, tmp_path / "x.png")
    wrong = tmp_path / "wrong_tag.h5"
    heat, _ = known_element_heat(case["table"])
    x = case["x"]
    write_thermal(wrong, ids=np.arange(1, x.shape[1] + 1), temperature=field(x, "axial"), element_heat=heat,
                  fmt="something-else")
    with pytest.raises(DPHTError, match="wrong_tag.h5.*format"):
        figures.wall_heat_flux(wrong, case["walls"], tmp_path / "x.png")
    with pytest.raises(GeometryError, match="nowalls.h5"):
        figures.wall_heat_flux(case["thermal"], tmp_path / "nowalls.h5", tmp_path / "x.png")
    incomplete = tmp_path / "interrupted.h5"
    write_thermal(incomplete, ids=np.arange(1, x.shape[1] + 1), temperature=field(x, "axial"), element_heat=heat,
                  complete=False)
    with pytest.raises(DPHTError, match="interrupted.h5.*incomplete"):
        figures.wall_heat_history(incomplete, tmp_path / "x.png")
    with pytest.raises(DPHTError, match="old_positions.h5.*format"):
        figures.temperature_profiles(write_positions(tmp_path / "old_positions.h5", x, fmt="x"), case["thermal"],
                                     tmp_path / "x.png")
    broken = tmp_path / "broken_positions.h5"
    with h5py.File(broken, "w") as f:
        f.attrs["format"] = dumps.FORMAT
        f["positions"] = x
    with pytest.raises(DPHTError, match="broken_positions.h5.*ids"):
        figures.temperature_profiles(broken, case["thermal"], tmp_path / "x.png")
    not_hdf5 = tmp_path / "text.h5"
    not_hdf5.write_text("not hdf5")
    with pytest.raises(DPHTError, match="text.h5"):
        figures.wall_heat_history(not_hdf5, tmp_path / "x.png")
    coarse = write_walls(tmp_path / "coarse_walls.h5", tube_walls(n_theta=12))
    with pytest.raises(DPHTError, match="coarse_walls.h5"):
        figures.wall_heat_flux(case["thermal"], coarse, tmp_path / "x.png")
    with pytest.raises(DPHTError, match="window"):
        figures.wall_heat_flux(case["thermal"], case["walls"], tmp_path / "x.png", window=(0.8, 0.2))


def test_misaligned_files_are_refused(case, tmp_path):
    x = case["x"][:, :-1]
    other = write_positions(tmp_path / "fewer.h5", x)
    with pytest.raises(DPHTError, match="fewer.h5"):
        figures.temperature_profiles(other, case["thermal"], tmp_path / "x.png")


def test_compare_cross_sections_share_one_colour_scale(case, tmp_path):
    ids = np.arange(1, case["x"].shape[1] + 1, dtype=np.int64)
    heat, _ = known_element_heat(case["table"])
    hotter = write_thermal(tmp_path / "hot.h5", ids=ids, temperature=field(case["x"], "axial") + 300.0, element_heat=heat)
    png = figures.compare_cross_sections(
        [("cool", case["positions"], case["thermal"], case["walls"]), ("hot", case["positions"], hotter, case["walls"])],
        tmp_path / "cmp.png", window_size=(300, 500),
    )  # fmt: skip
    assert_picture(png)

    def warmth(single):
        image = imread(single)[..., :3]
        coloured = (image.max(axis=-1) - image.min(axis=-1)) > 0.3
        return np.mean(image[coloured, 0] - image[coloured, 2])  # red minus blue of the particles

    # Same particles, same relative field: only a shared scale makes the hotter run look hotter.
    assert warmth(tmp_path / "cmp.hot.png") > warmth(tmp_path / "cmp.cool.png") + 0.2
    with pytest.raises(DPHTError, match="variants"):
        figures.compare_cross_sections([], tmp_path / "e.png")


def test_figures_of_a_strided_thermal_run(tmp_path):
    """thermal.frame_stride 2: the thermal stage records the positions frames it used and the figures
    stage reads the positions at those frames (issue 11, item 1: figures failed on 151 vs 76 frames).
    Every figure of the stage is drawn at its size, with finite numbers in the columns its CSV
    promises, and the engineering figure's energy balance closes (issue 16)."""
    # A lattice of particles (no contacts) moving down by a different step each frame, so that
    # every positions frame differs; 11 frames, a frame every 1000 steps of 1e-5 s.
    spacing = 2.2 * PARTICLE_RADIUS
    grid = np.arange(-TUBE_RADIUS + 1.5 * PARTICLE_RADIUS, TUBE_RADIUS - 1.5 * PARTICLE_RADIUS, spacing)
    x, y, z = np.meshgrid(grid, grid, np.arange(0.5 * spacing, LENGTH, spacing), indexing="ij")
    inside = np.hypot(x, y) < TUBE_RADIUS - 1.5 * PARTICLE_RADIUS
    start = np.column_stack([x[inside], y[inside], z[inside]])
    ids = np.arange(1, len(start) + 1)
    box_lo, box_hi = np.array([-TUBE_RADIUS, -TUBE_RADIUS, 0.0]), np.array([TUBE_RADIUS, TUBE_RADIUS, LENGTH])
    frames, centres = [], []
    for k in range(11):
        unwrapped = start - [0.0, 0.0, 1e-4 * k * k]
        image = np.zeros((len(start), 3), dtype=np.int32)
        image[:, 2] = np.floor(unwrapped[:, 2] / LENGTH).astype(np.int32)
        wrapped = unwrapped - image * [0.0, 0.0, LENGTH]
        centres.append(wrapped)
        frames.append(dumps.DumpFrame(1000 * k, box_lo, box_hi, (False, False, True), ids, wrapped, image))
    positions = tmp_path / "positions.h5"
    dumps.write_positions(positions, frames, radius=PARTICLE_RADIUS, density=3560.0, timestep=1e-5, dump_interval=1000,
                          summary={"mass_flow_second_half_kg_s": 0.01}, attrs={"recycled": [False, False, True]})
    walls = write_walls(tmp_path / "walls.h5", tube_walls())
    spec = scenes.spec(("pp_contact", "pw_contact", "pfp", "pfw"), frame_stride=2, walls={
        "heated_wall": {"temperature": 900.0}, "adiabatic_wall": "adiabatic", "orifice": "adiabatic"})
    tables = {}
    for kind in ("pfp", "pfw"):
        tables[kind] = tmp_path / f"{kind}.h5"
        htc.save_table(tables[kind], htc.table_from_spec(config.htc_spec(spec, kind)))
    thermal = tmp_path / "thermal.h5"
    thermal_stage.run(spec, positions, walls, tables, thermal, xdmf=tmp_path / "thermal.xdmf")
    with h5py.File(thermal) as f:
        np.testing.assert_array_equal(f["dem_frame"][...], [0, 2, 4, 6, 8, 10])

    outputs = {name: str(tmp_path / f"{name}.png") for name in FIGURES}
    figures_spec = {"window": [0.5, 1.0], "heated_zones": ["heated_wall"], "radial_band": [0.004, 0.006],
                    "htc": {"radius": PARTICLE_RADIUS, "k_solid": 2.0, "gas": "air"}}  # solid fractions: the thermal run's
    stages.figures(figures_spec, {"positions": positions, "walls": walls, "thermal": thermal}, outputs, 1)
    for name, png in outputs.items():
        assert_picture(Path(png))
        assert imread(png).shape[:2] == FIGURE_PIXELS[name]
        check_figure(Path(png))  # its CSVs' columns, finite where they promise numbers
    balance = json.loads(Path(outputs["engineering"]).with_suffix(".json").read_text())
    assert balance["outlet_particles"] > 0
    assert abs(balance["residual_window_relative"]) < 1e-9  # the stage conserves energy
    # The profiles count the particles of positions frames 6, 8 and 10 (thermal times 0.06-0.1 s).
    axial = read_csv(Path(outputs["temperature_profiles"]).with_suffix(".axial.csv"))
    used = np.concatenate([centres[k][:, 2] for k in (6, 8, 10)])
    expected, _ = np.histogram(used, bins=np.append(axial["z_lo_m"], axial["z_hi_m"][-1]))
    np.testing.assert_array_equal(axial["samples"], expected)


def test_wall_heat_history_legend_covers_no_curve(case, tmp_path, monkeypatch):
    """The legend sat inside the axes, over the residual line (issue 11): it goes below them."""
    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda fig, png: (drawn.append(fig), save(fig, png))[1])
    figures.wall_heat_history(case["thermal"], tmp_path / "history.png")
    (fig,) = drawn
    fig.draw_without_rendering()  # the layout as saved
    (legend,) = fig.legends
    box = legend.get_window_extent()
    assert len(legend.get_texts()) == 4  # the two enabled wall modes, the total and the residual
    for ax in fig.axes:
        assert not box.overlaps(ax.get_window_extent())


def test_cross_section_marks_the_heated_wall_and_has_a_true_scale_bar(case, tmp_path):
    """The heated zone's outline is red, over the heated height only; the scale bar's 2 mm are 2/9 of
    the tube's 9 mm width as drawn; the run's thermal.walls marks the same zones by default."""
    def render(name, thermal=case["thermal"], **kwargs):
        png = figures.cross_section(case["positions"], thermal, case["walls"], tmp_path / name, window_size=(400, 600),
                                    **kwargs)  # fmt: skip
        return imread(png)[..., :3]

    image = render("heated.png", heated_zones=["heated_wall"])
    pure_red = (image[..., 0] > 0.9) & (image[..., 1] < 0.15) & (image[..., 2] < 0.15)
    rows, columns = np.nonzero(pure_red[100:])  # under the notes at the top left
    middle = 0.5 * (columns.min() + columns.max())
    left, right = np.median(columns[columns < middle]), np.median(columns[columns > middle])
    tube_px = right - left  # between the walls' centre lines
    band = slice(int(right) - 3, int(right) + 4)  # the right wall, clear of the notes
    dimgrey = (np.abs(image[..., 0] - image[..., 2]) < 0.02) & (image[..., 0] > 0.3) & (image[..., 0] < 0.5)
    red_rows = np.nonzero(pure_red[:, band].any(axis=1))[0]
    wall_rows = np.nonzero((pure_red | dimgrey)[:, band].any(axis=1))[0]
    assert np.ptp(red_rows) / np.ptp(wall_rows) == pytest.approx((HEATED[1] - HEATED[0]) / LENGTH, abs=0.02)
    dark = np.all(image < 0.1, axis=-1)
    dark[: int(0.9 * image.shape[0])] = False  # under the colour bar: the bar and its label
    dark[:, : int(figures._COLOUR_BAR_X * image.shape[1]) - 2] = False
    bar = np.nonzero(dark[np.argmax(dark.sum(axis=1))])[0]  # the row of the most dark pixels crosses the bar
    assert np.ptp(bar) + 1 == pytest.approx(tube_px * 2e-3 / (2 * TUBE_RADIUS), abs=3)  # 2 mm of the 9 mm tube
    plain = render("plain.png")  # a thermal file without the run's config: nothing marked
    assert not np.any((plain[..., 0] > 0.9) & (plain[..., 1] < 0.15) & (plain[..., 2] < 0.15))
    configured = tmp_path / "configured.h5"
    shutil.copy(case["thermal"], configured)
    with h5py.File(configured, "r+") as f:
        f.attrs["spec"] = json.dumps({"thermal": {"walls": {"heated_wall": {"temperature": 900.0},
                                                            "adiabatic_wall": "adiabatic", "orifice": "adiabatic"}}})
    np.testing.assert_array_equal(render("default.png", thermal=configured), image)


def test_axis_units_and_the_mixer_bands_in_the_legend(case, tmp_path, monkeypatch):
    """A conductance is labelled W/K, a coefficient W/(m^2 K), a flux W/m^2; a variant's mixer bands
    have their legend entry (one per variant, however many mixers)."""
    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda fig, png: (drawn.append(fig), save(fig, png))[1])
    figures.htc_curves(tmp_path / "htc.png", radius=5e-4, k_solid=2.0, solid_fraction=0.6, pressure="continuum")
    figures.compare_variants([("base", case["thermal"], case["walls"]), ("double", case["thermal_double"], case["walls"])],
                             tmp_path / "cmp.png", spans={"double": [(0.01, 0.015), (0.02, 0.03)]})  # fmt: skip
    htc_fig, compare_fig = drawn
    assert [ax.get_ylabel() for ax in htc_fig.axes] == ["conductance $H_{ij}$ (W/K)", "conductance $H_{iw}$ (W/K)"]
    flux_ax = compare_fig.axes[0]
    assert "(W/m$^2$)" in flux_ax.get_ylabel()
    assert [t.get_text() for t in flux_ax.get_legend().get_texts()] == ["base", "double", "double: mixers"]
