"""The thermal output file (HDF5) and its XDMF sidecar for ParaView.

Layout (``format = "dpht-thermal-1"``), F frames, N particles, M wall elements::

    /ids              (N,)        int64, particle ids (same order as the positions file)
    /dem_frame        (F,)        int64, the positions file's frame of each thermal frame (with
                                  thermal.frame_stride n: 0, n, 2n, ...; absent in files written
                                  before it was added, whose frames are the positions file's)
    /time             (F,)        s
    /temperature      (F, N)      float32 K; NaN for a lost particle
    /wall_heat        (F, P)      W into the particles per particle-wall mode (the P = 3 columns of
                                  attr wall_modes: PW_MODES of dpht.thermal.modes, whether enabled
                                  or not), mean over the interval that starts at the frame
                                  (instantaneous at the last)
    /element_heat     (F, M, P)   float32 W per wall element and mode, same meaning
    /substeps         (F,)        int32 time steps taken in the interval (explicit: sub-steps; multirate:
                                  micro-steps of the finest level; implicit: 1; 0 at the last frame)
    /energy/particles (F,)        J, total particle enthalpy (relative to the table's T0)
    /energy/wall      (F,)        J, wall heat received since the first frame
    /energy/recycled  (F,)        J, enthalpy change from resetting re-entering particles
    /energy/convected (F,)        J, heat received from the gas (thermal.convection) since the first
                                  frame (0 without convection)
    attrs: format, wall_modes, modes (JSON), inlet_temperature, positions (file name), spec (JSON),
           complete (bool), summary (JSON, once complete)
    /outlet           a chain's segment only: what left the run, in float64 (dpht/chain/outlet.py)

Large datasets are gzip-compressed (not h5py's LZF), so ParaView's XDMF reader can read them.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from dpht.thermal.modes import PW_MODES

FORMAT = "dpht-thermal-1"


@dataclass(frozen=True)
class Row:
    """One frame of the output file (see the layout above)."""

    time: float  # s
    temperature: np.ndarray  # (N,) float32 K at the frame, NaN for a lost particle
    element_heat: np.ndarray  # (M, P) W, mean over the interval that starts at the frame
    substeps: int
    energy_particles: float  # J at the frame, after re-entering particles were reset
    energy_wall: float  # J received from the walls before the frame
    energy_recycled: float  # J, from resets up to and including the frame's
    energy_convected: float = 0.0  # J received from the gas before the frame


# Datasets with one entry per frame; those chunked one frame per chunk can be copied chunk by chunk.
ROW_DATASETS = ("time", "temperature", "wall_heat", "element_heat", "substeps", "energy/particles", "energy/wall",
                "energy/recycled", "energy/convected")  # fmt: skip
FRAME_CHUNKED = ("temperature", "element_heat")


class ThermalWriter:
    """Writes frames as they are computed; the file is complete only after :meth:`finish`.

    The thermal stage writes its rows in segments (files of this layout holding ``n_frames`` rows
    from some frame on, see :mod:`dpht.thermal.checkpoint`) and copies them into the final file with
    :meth:`copy_rows`.
    """

    def __init__(self, path, *, ids, dem_frames, n_elements: int, attrs: dict):
        self.path = Path(path)
        self.file = h5py.File(self.path, "w")
        f = self.file
        n, n_frames = len(ids), len(dem_frames)
        f.create_dataset("ids", data=np.asarray(ids, dtype=np.int64))
        f.create_dataset("dem_frame", data=np.asarray(dem_frames, dtype=np.int64))
        f.create_dataset("time", shape=(n_frames,), dtype=np.float64)
        f.create_dataset("temperature", shape=(n_frames, n), dtype=np.float32, chunks=(1, max(n, 1)), compression="gzip", compression_opts=1, shuffle=True)
        p = len(PW_MODES)
        f.create_dataset("wall_heat", shape=(n_frames, p), dtype=np.float64)
        f.create_dataset(
            "element_heat", shape=(n_frames, n_elements, p), dtype=np.float32,
            chunks=(1, max(n_elements, 1), p), compression="gzip", compression_opts=1, shuffle=True,
        )  # fmt: skip
        f.create_dataset("substeps", shape=(n_frames,), dtype=np.int32)
        for name in ("particles", "wall", "recycled", "convected"):
            f.create_dataset(f"energy/{name}", shape=(n_frames,), dtype=np.float64)
        f.attrs.update(format=FORMAT, wall_modes=list(PW_MODES), complete=False, **attrs)

    def write(self, k: int, row: Row) -> None:
        f = self.file
        f["time"][k] = row.time
        f["temperature"][k] = row.temperature
        f["element_heat"][k] = row.element_heat
        f["wall_heat"][k] = row.element_heat.sum(axis=0)
        f["substeps"][k] = row.substeps
        f["energy/particles"][k] = row.energy_particles
        f["energy/wall"][k] = row.energy_wall
        f["energy/recycled"][k] = row.energy_recycled
        f["energy/convected"][k] = row.energy_convected

    def copy_rows(self, source, start: int, rows: int) -> None:
        """Rows 0..rows-1 of the file ``source`` (same layout) into rows start.. of this one; the
        compressed frame chunks are copied as they are (no decompression)."""
        with h5py.File(source, "r") as src:
            for name in ROW_DATASETS:
                target, origin = self.file[name], src[name]
                if name in FRAME_CHUNKED and origin.size:
                    tail = (0,) * (origin.ndim - 1)
                    for k in range(rows):
                        if origin.id.get_chunk_info_by_coord((k, *tail)).byte_offset is None:
                            target[start + k] = origin[k]  # never written: the fill value
                            continue
                        mask, chunk = origin.id.read_direct_chunk((k, *tail))
                        target.id.write_direct_chunk((start + k, *tail), chunk, mask)
                else:
                    target[start : start + rows] = origin[:rows]

    def close(self) -> None:
        """Close the file as it is (a segment; still marked incomplete)."""
        self.file.close()

    def finish(self, summary: dict) -> None:
        """Store the run's summary (JSON attribute ``summary``), mark the file complete and close it."""
        self.file.attrs["summary"] = json.dumps(summary)
        self.file.attrs["complete"] = True
        self.file.close()


def write_xdmf(xdmf_path, thermal_h5, positions_h5, *, frames, n_dem_frames: int, n_particles: int, times, precision: int) -> None:
    """XDMF time series: particle positions from the DEM file, temperatures from the thermal file.

    ``frames[k]`` is the DEM frame of thermal frame k (a stride skips DEM frames).
    """
    xdmf_path = Path(xdmf_path)
    pos, therm = (os.path.relpath(Path(p).resolve(), xdmf_path.resolve().parent) for p in (positions_h5, thermal_h5))
    n_frames = len(frames)
    steps = []
    for k in range(n_frames):
        steps.append(
            f"""      <Grid Name="frame{k}" GridType="Uniform">
        <Time Value="{float(times[k])!r}"/>
        <Topology TopologyType="Polyvertex" NumberOfElements="{n_particles}"/>
        <Geometry GeometryType="XYZ">
          <DataItem ItemType="HyperSlab" Dimensions="{n_particles} 3" Type="HyperSlab">
            <DataItem Dimensions="3 3" Format="XML">{frames[k]} 0 0 1 1 1 1 {n_particles} 3</DataItem>
            <DataItem Dimensions="{n_dem_frames} {n_particles} 3" NumberType="Float" Precision="{precision}" Format="HDF">{pos}:/positions</DataItem>
          </DataItem>
        </Geometry>
        <Attribute Name="temperature" AttributeType="Scalar" Center="Node">
          <DataItem ItemType="HyperSlab" Dimensions="{n_particles}" Type="HyperSlab">
            <DataItem Dimensions="3 2" Format="XML">{k} 0 1 1 1 {n_particles}</DataItem>
            <DataItem Dimensions="{n_frames} {n_particles}" NumberType="Float" Precision="4" Format="HDF">{therm}:/temperature</DataItem>
          </DataItem>
        </Attribute>
      </Grid>"""
        )
    xdmf_path.write_text(
        '<?xml version="1.0" ?>\n<Xdmf Version="3.0">\n  <Domain>\n'
        '    <Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n'
        + "\n".join(steps)
        + "\n    </Grid>\n  </Domain>\n</Xdmf>\n"
    )
