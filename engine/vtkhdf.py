"""The solid as a VTKHDF file (``<stem>.vtkhdf``): what ``pyvista.read``, VTK's ``vtkHDFReader``
and ParaView (5.12 on) open as they are, time series included.

Why a second format beside the XDMF views: PyVista's XDMF reader fails on a file without time
values (a static result), and meshio refuses an XDMF grid that has one, so no single static XDMF
file serves both. VTKHDF (format 2.0, an ``UnstructuredGrid``) does for VTK and PyVista; meshio
reads the XDMF views.

Content: the material cells of ``engine.views.solid_mesh`` (hexahedra, quadrilaterals in 2D, 2D
points padded with z = 0), cell data ``volume_fraction`` and every cell field, point data
displacement / velocity / von Mises at the corners. A quasi-static or dynamic result is temporal:
the geometry is stored once and every step's values follow each other in the data arrays, with
``/VTKHDF/Steps`` giving each step's time and offsets (VTKHDF 2.0, "Temporal data"), and the field
data ``Time`` holding it too (what VTK shows of a single step's time).
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

VERSION = (2, 0)
_CELL_TYPE = {3: 12, 2: 9}  # VTK_HEXAHEDRON, VTK_QUAD


def _pad(values: np.ndarray) -> np.ndarray:
    """[n, 2] vectors/points -> [n, 3] with a zero z (VTK's vectors are 3D)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 2 and values.shape[1] == 2:
        return np.column_stack([values, np.zeros(len(values))])
    return values


def _ascii(text: str) -> np.bytes_:
    return np.bytes_(text)  # a fixed-length ASCII string: what vtkHDFReader reads for Type


def write_vtkhdf(result, path: str | os.PathLike) -> Path:
    """Write the solid of ``result`` (an ``engine.output.Result``) to the VTKHDF file ``path``.

    Not atomic on its own: ``engine.output.write_result`` writes it under a temporary name and
    renames it together with the other files."""
    from .views import solid_mesh
    from .xdmf import _NODE_FIELDS

    d = result.dim
    vf = np.asarray(result.volume_fraction)
    solid = solid_mesh(result.grid, vf)
    levels = result.steps or [result.fields]
    n_cells, n_points, corners = len(solid.cells), len(solid.points), solid.cells.shape[1]
    with h5py.File(path, "w") as f:
        root = f.create_group("VTKHDF")
        root.attrs["Version"] = np.array(VERSION, dtype=np.int64)
        root.attrs["Type"] = _ascii("UnstructuredGrid")
        root.create_dataset("NumberOfPoints", data=np.array([n_points], dtype=np.int64))
        root.create_dataset("NumberOfCells", data=np.array([n_cells], dtype=np.int64))
        root.create_dataset("NumberOfConnectivityIds", data=np.array([n_cells * corners], dtype=np.int64))
        root.create_dataset("Points", data=_pad(solid.points), **_compressed(n_points))
        root.create_dataset("Connectivity", data=solid.cells.reshape(-1), **_compressed(n_cells * corners))
        root.create_dataset("Offsets", data=np.arange(n_cells + 1, dtype=np.int64) * corners)
        root.create_dataset("Types", data=np.full(n_cells, _CELL_TYPE[d], dtype=np.uint8))
        cell_data, point_data = root.create_group("CellData"), root.create_group("PointData")
        cell_arrays: dict[str, list[np.ndarray]] = {"volume_fraction": [solid.cell_values(vf)] * len(levels)}
        point_arrays: dict[str, list[np.ndarray]] = {}
        for level in levels:
            for name, dense in level.cells.items():
                cell_arrays.setdefault(name, []).append(_pad(solid.cell_values(dense)))
                if name in _NODE_FIELDS:
                    point_arrays.setdefault(name, []).append(_pad(solid.node_values(dense, vf)))
        for group, arrays in ((cell_data, cell_arrays), (point_data, point_arrays)):
            for name, per_level in arrays.items():
                data = np.concatenate(per_level)
                group.create_dataset(name, data=data, **_compressed(data.size))
        if result.steps:
            _steps(root, [s.time for s in result.steps], n_cells, n_points, cell_arrays, point_arrays)
    return Path(path)


def _steps(root: h5py.Group, times: list[float], n_cells: int, n_points: int,
           cell_arrays: dict, point_arrays: dict) -> None:
    """/VTKHDF/Steps: one geometry for every step (offsets 0), step k's values at k * count."""
    n = len(times)
    steps = root.create_group("Steps")
    steps.attrs["NSteps"] = np.int64(n)
    steps.create_dataset("Values", data=np.asarray(times, dtype=np.float64))
    zeros = np.zeros(n, dtype=np.int64)
    steps.create_dataset("PartOffsets", data=zeros)
    steps.create_dataset("NumberOfParts", data=np.ones(n, dtype=np.int64))
    steps.create_dataset("PointOffsets", data=zeros)
    steps.create_dataset("CellOffsets", data=zeros.reshape(n, 1))
    steps.create_dataset("ConnectivityIdOffsets", data=zeros.reshape(n, 1))
    k = np.arange(n, dtype=np.int64)
    for group, arrays, count in (("CellDataOffsets", cell_arrays, n_cells), ("PointDataOffsets", point_arrays, n_points)):
        g = steps.create_group(group)
        for name in arrays:
            g.create_dataset(name, data=k * count)
    # VTK reads Steps only for two or more: a one-step result (a dynamic job of one step) had no
    # time at all, which the field "Time", one value per step, carries either way
    root.create_group("FieldData").create_dataset("Time", data=np.asarray(times, dtype=np.float64))
    steps.create_group("FieldDataOffsets").create_dataset("Time", data=k)


def _compressed(size: int) -> dict:
    return {"chunks": True, "compression": "gzip", "shuffle": True} if size >= 1 << 10 else {}
