"""Text dump reader and positions HDF5 file: round trips on synthetic LIGGGHTS dumps."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from dpht.dem.dumps import (
    Box, PositionsFile, content_digest, dump_files, read_dump, read_dumps, set_summary, unwrapped, write_positions,
)
from dpht.errors import DPHTError

BOX_LO, BOX_HI = np.array([-0.0055, -0.0055, 0.0]), np.array([0.0055, 0.0055, 0.05])
DT, EVERY, STEP0 = 1.0e-5, 1000, 37000


def write_dump(path, step, ids, positions, image):
    """A dump file as LIGGGHTS writes it with 'dump_modify sort id format ...'."""
    lines = [
        "ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", str(len(ids)), "ITEM: BOX BOUNDS ff ff pp",
        *(f"{lo:.17g} {hi:.17g}" for lo, hi in zip(BOX_LO, BOX_HI)), "ITEM: ATOMS id x y z ix iy iz ",
    ]
    lines += [
        f"{i} {x:.10g} {y:.10g} {z:.10g} {a} {b} {c} " for i, (x, y, z), (a, b, c) in zip(ids, positions, image)
    ]
    path.write_text("\n".join(lines) + "\n")


def synthetic_run(folder, n=50, frames=6, lose=None, seed=0):
    """Particles falling through the periodic box; ``lose`` = (id, from_frame) drops one particle."""
    rng = np.random.default_rng(seed)
    ids = np.arange(1, n + 1)
    start = rng.uniform(BOX_LO + 1e-3, BOX_HI - 1e-3, size=(n, 3))
    speed = rng.uniform(0.0, 2.0, size=n)  # m/s downwards
    truth = []
    for k in range(frames):
        t = k * EVERY * DT
        z_unwrapped = start[:, 2] - speed * t
        image = np.zeros((n, 3), dtype=np.int32)
        image[:, 2] = np.floor(z_unwrapped / BOX_HI[2]).astype(np.int32)
        pos = start.copy()
        pos[:, 2] = z_unwrapped - image[:, 2] * BOX_HI[2]
        keep = np.ones(n, dtype=bool)
        if lose and k >= lose[1]:
            keep[ids == lose[0]] = False
        write_dump(folder / f"dump.{STEP0 + k * EVERY}.txt", STEP0 + k * EVERY, ids[keep], pos[keep], image[keep])
        truth.append((pos, image, keep))
    return ids, truth


def gather(folder, out, precision="float64", **kw):
    files = dump_files(folder)
    return write_positions(
        out, read_dumps(files.values()), radius=5e-4, density=3560.0, timestep=DT, dump_interval=EVERY,
        precision=precision, **kw,
    )


def test_read_dump_parses_header_and_columns(tmp_path):
    ids, truth = synthetic_run(tmp_path, frames=1)
    frame = read_dump(tmp_path / f"dump.{STEP0}.txt")
    assert frame.step == STEP0
    assert frame.periodic == (False, False, True)
    np.testing.assert_array_equal(frame.box_lo, BOX_LO)
    np.testing.assert_array_equal(frame.box_hi, BOX_HI)
    np.testing.assert_array_equal(frame.ids, ids)
    np.testing.assert_allclose(frame.positions, truth[0][0], rtol=0, atol=1e-11)  # 10 significant digits
    np.testing.assert_array_equal(frame.image, truth[0][1])


def test_truncated_and_foreign_dumps_are_rejected(tmp_path):
    synthetic_run(tmp_path, frames=1)
    path = tmp_path / f"dump.{STEP0}.txt"
    text = path.read_text()
    path.write_text(text[: len(text) - 40])  # cut inside the last lines, as a kill would
    with pytest.raises(DPHTError, match="truncated"):
        read_dump(path)
    path.write_text(text.replace("ix iy iz", "vx vy vz"))
    with pytest.raises(DPHTError, match="columns"):
        read_dump(path)


def test_round_trip_streams_frames_and_counts_crossings(tmp_path):
    ids, truth = synthetic_run(tmp_path, frames=6)
    out = tmp_path / "positions.h5"
    stats = gather(tmp_path, out, summary={"particles": len(ids)})
    assert stats.n_frames == 6 and stats.lost_first_step == {}
    # Independent count: how many times each particle wrapped downwards since the first frame.
    wraps = [int(np.sum(truth[0][1][:, 2] - image[:, 2])) for _, image, _ in truth]
    np.testing.assert_array_equal(stats.crossings, wraps)
    assert wraps[-1] > 0
    with PositionsFile(out) as f:
        assert f.n_frames == 6 and f.n_particles == len(ids)
        np.testing.assert_array_equal(f.ids, ids)
        np.testing.assert_array_equal(f.steps, STEP0 + EVERY * np.arange(6))
        np.testing.assert_allclose(f.times, EVERY * DT * np.arange(6))
        assert f.summary == {"particles": len(ids)}
        assert f.attrs["format"] == "dpht-positions-1" and f.radius == 5e-4 and f.timestep == DT
        assert list(f.attrs["periodic"]) == [False, False, True]
        got = list(f.frames(2, 5))
        assert [g.index for g in got] == [2, 3, 4]
        for g in got:
            np.testing.assert_allclose(g.positions, truth[g.index][0], rtol=0, atol=1e-11)
            np.testing.assert_array_equal(g.image, truth[g.index][1])
            assert not g.lost.any()
    with h5py.File(out) as h5:
        for name in ("positions", "image"):
            assert h5[name].chunks == (1, len(ids), 3)
            assert h5[name].compression == "gzip" and h5[name].shuffle


def test_float32_positions_are_good_to_1e7_m(tmp_path):
    ids, truth = synthetic_run(tmp_path, frames=3)
    out = tmp_path / "positions.h5"
    gather(tmp_path, out, precision="float32")
    with PositionsFile(out) as f:
        for frame in f.frames():
            assert frame.positions.dtype == np.float32
            assert np.max(np.abs(frame.positions - truth[frame.index][0])) < 1e-7


def test_lost_particle_is_nan_and_flagged(tmp_path):
    ids, truth = synthetic_run(tmp_path, frames=5, lose=(7, 3))
    out = tmp_path / "positions.h5"
    stats = gather(tmp_path, out)
    assert stats.lost_first_step == {7: STEP0 + 3 * EVERY}
    with PositionsFile(out) as f:
        for frame in f.frames():
            missing = frame.index >= 3
            assert frame.lost[6] == missing and frame.lost.sum() == missing
            assert np.isnan(frame.positions[6]).all() == missing
            assert not np.isnan(np.delete(frame.positions, 6, axis=0)).any()


def test_gap_duplicate_and_unknown_ids_are_errors(tmp_path):
    synthetic_run(tmp_path, frames=4)
    frames = list(read_dumps(dump_files(tmp_path).values()))
    common = dict(radius=5e-4, density=3560.0, timestep=DT, dump_interval=EVERY)
    with pytest.raises(DPHTError, match="no gap or duplicate"):
        write_positions(tmp_path / "a.h5", [frames[0], frames[1], frames[3]], **common)
    with pytest.raises(DPHTError, match="no gap or duplicate"):
        write_positions(tmp_path / "b.h5", [frames[0], frames[1], frames[1]], **common)
    stranger = read_dump(dump_files(tmp_path)[STEP0 + EVERY])
    stranger.ids[-1] = 999
    with pytest.raises(DPHTError, match="999"):
        write_positions(tmp_path / "c.h5", [frames[0], stranger], **common)
    with pytest.raises(DPHTError, match="precision"):
        write_positions(tmp_path / "d.h5", frames, precision="float16", **common)


def test_set_summary_and_bad_file(tmp_path):
    synthetic_run(tmp_path, frames=2)
    out = tmp_path / "positions.h5"
    gather(tmp_path, out)
    set_summary(out, {"mass_flow_kg_s": 1.5e-3})
    with PositionsFile(out) as f:
        assert f.summary == {"mass_flow_kg_s": 1.5e-3}
        with pytest.raises(DPHTError, match="out of range"):
            f.frame(2)
    (tmp_path / "other.h5").write_bytes(b"not hdf5")
    with pytest.raises(DPHTError, match="other.h5"):
        PositionsFile(tmp_path / "other.h5")


def test_positions_past_a_periodic_boundary_are_wrapped(tmp_path):
    # LIGGGHTS wraps only at re-neighbouring: a dump may hold z slightly below 0 with iz unchanged.
    pos = np.array([[0.001, 0.0, -3.0e-5], [0.0, 0.001, 0.05 + 2.0e-6], [0.0, 0.0, 0.01]])
    image = np.array([[0, 0, 0], [0, 0, -2], [0, 0, 1]])
    write_dump(tmp_path / "dump.0.txt", 0, [1, 2, 3], pos, image)
    frame = read_dump(tmp_path / "dump.0.txt")
    np.testing.assert_allclose(frame.positions[:, 2], [0.05 - 3.0e-5, 2.0e-6, 0.01], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(frame.image[:, 2], [-1, -1, 1])
    np.testing.assert_array_equal(frame.positions[:, :2], pos[:, :2])  # x, y are not periodic
    # The unwrapped position is unchanged.
    np.testing.assert_allclose(frame.positions[:, 2] + 0.05 * frame.image[:, 2], pos[:, 2] + 0.05 * image[:, 2])


def dump_lines(path):
    lines = path.read_text().splitlines()
    return lines[:9], lines[9:]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda atoms: atoms[:2] + ["3 nan 0.001 0.02 0 0 0"] + atoms[3:], r"non-finite positions, ids \[3\]"),
        (lambda atoms: atoms[:2] + ["4 0.0 0.0 1e999 0 0 0"] + atoms[3:], "non-finite positions"),
        (lambda atoms: atoms[:3] + [atoms[3].replace("4 ", "3 ", 1)] + atoms[4:], r"ids \[3\] appear more than once"),
        (lambda atoms: atoms[:2] + [atoms[3], atoms[2]] + atoms[4:], "not sorted"),
        (lambda atoms: atoms[:2] + ["3.5 0.0 0.0 0.01 0 0 0"] + atoms[3:], "non-integer id"),
        (lambda atoms: atoms[:2] + ["3 0.0 0.0 0.01 0 0 0.25"] + atoms[3:], "non-integer id or image flag"),
        (lambda atoms: atoms[:2] + ["-3 0.0 0.0 0.01 0 0 0"] + atoms[3:], "positive integers"),
    ],
    ids=["nan", "inf", "duplicate", "unsorted", "fractional id", "fractional image", "negative id"],
)
def test_bad_dump_content_is_refused_naming_the_file(tmp_path, edit, message):
    synthetic_run(tmp_path, n=6, frames=1)
    path = tmp_path / f"dump.{STEP0}.txt"
    header, atoms = dump_lines(path)
    path.write_text("\n".join(header + edit(atoms)) + "\n")
    with pytest.raises(DPHTError, match=message) as err:
        read_dump(path)
    assert str(path) in str(err.value)


def test_binary_and_negative_headers_are_refused(tmp_path):
    path = tmp_path / "dump.0.txt"
    path.write_bytes(b"\xff\xfe" * 100)
    with pytest.raises(DPHTError, match="cannot be read as text"):
        read_dump(path)
    synthetic_run(tmp_path, n=3, frames=1)
    good = tmp_path / f"dump.{STEP0}.txt"
    header, atoms = dump_lines(good)
    header[3] = "-3"
    good.write_text("\n".join(header + atoms) + "\n")
    with pytest.raises(DPHTError, match="must not be negative"):
        read_dump(good)


def test_losing_more_than_the_threshold_stops_the_gather(tmp_path):
    synthetic_run(tmp_path, n=50, frames=4, lose=(7, 2))
    frames = list(read_dumps(dump_files(tmp_path).values()))
    common = dict(radius=5e-4, density=3560.0, timestep=DT, dump_interval=EVERY)
    write_positions(tmp_path / "ok.h5", frames, **common)  # 1 of 50 is below the default 5%
    with pytest.raises(DPHTError, match=r"dump step 39000: 1 of the 50 particles are missing, more than 1%.*\[7\]"):
        write_positions(tmp_path / "lost.h5", frames, max_lost_fraction=0.01, **common)


def test_positions_files_of_another_version_or_damaged_say_what_to_do(tmp_path):
    synthetic_run(tmp_path, frames=2)
    out = tmp_path / "positions.h5"
    gather(tmp_path, out)
    for tag, message in (("dpht-positions-0", "older version of dpht .*re-run the stage"),
                         ("dpht-positions-7", "newer version of dpht"),
                         ("dpht-thermal-1", "not a positions file")):  # fmt: skip
        with h5py.File(out, "r+") as h5:
            h5.attrs["format"] = tag
        with pytest.raises(DPHTError, match=message):
            PositionsFile(out)
    with h5py.File(out, "r+") as h5:
        h5.attrs["format"] = "dpht-positions-1"
        del h5.attrs["format"]
    with pytest.raises(DPHTError, match="no format tag"):
        PositionsFile(out)
    with h5py.File(out, "r+") as h5:
        h5.attrs["format"] = "dpht-positions-1"
        del h5["lost"]
        h5["lost"] = np.zeros((3, 50), dtype=bool)
    with pytest.raises(DPHTError, match=r"/lost is bool \(3, 50\), expected \(2, 50\).*delete it"):
        PositionsFile(out)


# --- a sheared (triclinic xy) box -----------------------------------------------------------------

SHEAR_LO, SHEAR_HI = np.array([0.0, -0.004, 0.001]), np.array([0.006, 0.002, 0.007])
SHEAR_RATE = 150.0  # 1/s: the tilt passes half the x length (a flip) within a few frames


def shear_tilt(t):
    """The xy tilt as LIGGGHTS' fix deform xy erate keeps it: the strain's tilt, flipped by whole x
    lengths into [-Lx/2, Lx/2]."""
    length = SHEAR_HI - SHEAR_LO
    tilt = SHEAR_RATE * length[1] * t
    return tilt - length[0] * np.round(tilt / length[0])


def write_triclinic_dump(path, step, ids, positions, image, tilt, boundary="pp pp pp"):
    """A dump of a triclinic box as LIGGGHTS writes it: the bounding box and tilts with %g."""
    lo_bound = SHEAR_LO + [min(0.0, tilt), 0.0, 0.0]
    hi_bound = SHEAR_HI + [max(0.0, tilt), 0.0, 0.0]
    lines = [
        "ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", str(len(ids)), f"ITEM: BOX BOUNDS xy xz yz {boundary}",
        *(f"{lo:g} {hi:g} {t:g}" for lo, hi, t in zip(lo_bound, hi_bound, (tilt, 0.0, 0.0))), "ITEM: ATOMS id x y z ix iy iz ",
    ]
    lines += [f"{i} {x:.10g} {y:.10g} {z:.10g} {a} {b} {c} " for i, (x, y, z), (a, b, c) in zip(ids, positions, image)]
    path.write_text("\n".join(lines) + "\n")


def sheared_run(folder, n=80, frames=8, seed=1):
    """Particles streaming along x at the shear rate times their height, written as LIGGGHTS holds
    them: in the tilted cell (positions and image flags from the unwrapped ones and the tilt), some
    a little outside it as between re-neighbourings. Returns the ids, unwrapped positions and tilts."""
    rng = np.random.default_rng(seed)
    length = SHEAR_HI - SHEAR_LO
    ids = np.arange(1, n + 1)
    start = SHEAR_LO + rng.random((n, 3)) * length
    truth, tilts = [], []
    for k in range(frames):
        t = k * EVERY * DT
        tilt = shear_tilt(t)
        u = start.copy()
        u[:, 0] += SHEAR_RATE * (start[:, 1] - SHEAR_LO[1]) * t  # the streaming velocity
        u[:, 1] += rng.normal(0.0, 1e-4, n)  # and some motion across the layers
        image = np.zeros((n, 3), dtype=np.int64)
        image[:, 1] = np.floor((u[:, 1] - SHEAR_LO[1]) / length[1])
        pos = u - image[:, [1]] * [tilt, length[1], 0.0]
        shift = tilt * (pos[:, 1] - SHEAR_LO[1]) / length[1]  # the tilted cell's x offset at this height
        image[:, 0] = np.floor((pos[:, 0] - SHEAR_LO[0] - shift) / length[0])
        image[:, 2] = np.floor((pos[:, 2] - SHEAR_LO[2]) / length[2])
        pos -= image[:, [0]] * [length[0], 0, 0] + image[:, [2]] * [0, 0, length[2]]
        # Some not yet remapped: a micrometre past the y faces, with their old flags.
        past = np.where(rng.random(n) < 0.1, np.where(rng.random(n) < 0.5, SHEAR_HI[1] + 1e-6, SHEAR_LO[1] - 1e-6), pos[:, 1])
        u[:, 1] += past - pos[:, 1]
        pos[:, 1] = past
        write_triclinic_dump(folder / f"dump.{STEP0 + k * EVERY}.txt", STEP0 + k * EVERY, ids, pos, image, tilt)
        truth.append(u)
        tilts.append(tilt)
    return ids, truth, np.array(tilts)


def test_triclinic_dump_gives_the_box_the_tilt_and_the_unwrapped_positions(tmp_path):
    """Through flips of the box (tilt back by an x length) and particles past the y faces, the
    positions come back in the orthogonal box with flags that unwrap them to where they are."""
    ids, truth, tilts = sheared_run(tmp_path)
    assert np.any(np.diff(tilts) < 0), "the run flips the box"
    for k, path in enumerate(dump_files(tmp_path).values()):
        frame = read_dump(path)
        np.testing.assert_allclose(frame.box_lo, SHEAR_LO, rtol=0, atol=1e-12)
        np.testing.assert_allclose(frame.box_hi, SHEAR_HI, rtol=0, atol=1e-12)
        assert frame.periodic == (True, True, True) and abs(frame.tilt - tilts[k]) <= 5e-6 * abs(tilts[k])
        assert np.all(frame.positions >= SHEAR_LO) and np.all(frame.positions < SHEAR_HI)
        exact = read_dump(path, {frame.step: Box(SHEAR_LO, SHEAR_HI, tilts[k])})
        assert exact.tilt == tilts[k]
        np.testing.assert_allclose(unwrapped(exact.positions, exact.image, SHEAR_LO, SHEAR_HI, exact.tilt), truth[k],
                                   rtol=0, atol=1e-11)


def test_a_box_given_at_full_precision_must_be_the_headers(tmp_path):
    sheared_run(tmp_path, frames=2)
    path = tmp_path / f"dump.{STEP0 + EVERY}.txt"
    tilt = shear_tilt(EVERY * DT)
    with pytest.raises(DPHTError, match="not the header's"):
        read_dump(path, {STEP0 + EVERY: Box(SHEAR_LO, SHEAR_HI, tilt * 1.001)})
    with pytest.raises(DPHTError, match="not the header's"):
        read_dump(path, {STEP0 + EVERY: Box(SHEAR_LO, SHEAR_HI + [1e-4, 0, 0], tilt)})
    with pytest.raises(DPHTError, match=f"no full-precision box for step {STEP0 + EVERY}"):
        read_dump(path, {STEP0: Box(SHEAR_LO, SHEAR_HI, tilt)})
    header, atoms = dump_lines(path)
    for line, message in ((6, "only a shear along x"), (4, "BOX BOUNDS")):
        edited = list(header)
        edited[line] = {6: "-0.004 0.002 1e-4", 4: "ITEM: BOX BOUNDS xy xz pp pp pp"}[line]
        path.write_text("\n".join(edited + atoms) + "\n")
        with pytest.raises(DPHTError, match=message):
            read_dump(path)
    header[4] = "ITEM: BOX BOUNDS xy xz yz ff pp pp"
    path.write_text("\n".join(header + atoms) + "\n")
    with pytest.raises(DPHTError, match="periodic x and y"):
        read_dump(path)


def test_sheared_positions_file_keeps_the_tilt_of_every_frame(tmp_path):
    ids, truth, tilts = sheared_run(tmp_path, frames=5)
    out = tmp_path / "positions.h5"
    boxes = {STEP0 + k * EVERY: Box(SHEAR_LO, SHEAR_HI, t) for k, t in enumerate(tilts)}
    write_positions(out, read_dumps(dump_files(tmp_path).values(), boxes), radius=5e-4, density=3560.0, timestep=DT,
                    dump_interval=EVERY)
    with PositionsFile(out) as f:
        assert f.sheared
        for frame in f.frames():
            assert frame.tilt == tilts[frame.index]
            np.testing.assert_allclose(unwrapped(frame.positions, frame.image, SHEAR_LO, SHEAR_HI, frame.tilt),
                                       truth[frame.index], rtol=0, atol=1e-11)
    with h5py.File(out) as h5:
        digest = content_digest(h5)
    with h5py.File(out, "r+") as h5:
        h5["tilt"][2] += 1e-9
        assert content_digest(h5) != digest
    # An orthogonal run's file has no tilt; a run may not change its box while dumping.
    tube = tmp_path / "tube"
    tube.mkdir()
    synthetic_run(tube, frames=2)
    gather(tube, tmp_path / "tube.h5")
    with PositionsFile(tmp_path / "tube.h5") as f:
        assert not f.sheared and f.frame(1).tilt == 0.0
    frames = list(read_dumps(dump_files(tmp_path).values()))
    mixed = [frames[0], dataclasses.replace(frames[1], tilt=None)]
    with pytest.raises(DPHTError, match="may only tilt"):
        write_positions(tmp_path / "mixed.h5", mixed, radius=5e-4, density=3560.0, timestep=DT, dump_interval=EVERY)
