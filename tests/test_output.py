"""Result file: HDF5 round trip, layout/attributes, validation, reader errors, atomic writes, XDMF."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest

import engine.output as output
import engine.xdmf as xdmf
from engine.errors import ResultFormatError
from engine.grid import Grid
from engine.output import FieldData, Result, SolverReport, read_result, write_result

SHAPES = {3: (3, 4, 5), 2: (3, 4)}


def surface_mesh(dim: int) -> tuple[np.ndarray, np.ndarray]:
    if dim == 3:  # a tetrahedron, outward triangles
        v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        return v * 0.3 + 0.1, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    v = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    return v * 0.3 + 0.1, np.array([[0, 1], [1, 2], [2, 0]])


def field_level(dim: int, rng: np.random.Generator, n: int, m: int, time: float | None) -> FieldData:
    shape = SHAPES[dim]
    nv = 6 if dim == 3 else 3
    u = rng.standard_normal(shape + (dim,))
    u[0, 0] = np.nan  # empty cells carry NaN
    return FieldData(
        cells={"displacement": u, "stress": rng.standard_normal(shape + (nv,)) * 1e5,
               "von_mises": rng.random(shape).astype(np.float32)},  # f32 must survive as f32
        probes={"displacement": rng.standard_normal((n, dim)), "stress": rng.standard_normal((n, nv))},
        surface={"displacement": rng.standard_normal((m, dim))},
        time=time,
    )


def make_result(dim: int, steps: int = 2, seed: int = 0) -> Result:
    rng = np.random.default_rng(seed)
    grid = Grid(origin=(-0.5, 0.25, 1.0)[:dim], spacing=0.125, shape=SHAPES[dim])
    vertices, faces = surface_mesh(dim)
    probes = rng.random((2, dim))
    vf = rng.random(SHAPES[dim])
    vf[0, 0] = 0.0
    return Result(
        grid=grid, method="staggered",
        spec={"grid": {"cell_size": 0.125}, "output": {"probes": probes.tolist(), "surface": True}, "e": 1e6},
        volume_fraction=vf,
        fields=field_level(dim, rng, 2, len(vertices), None),
        steps=[field_level(dim, rng, 2, len(vertices), 0.25 * (i + 1)) for i in range(steps)],
        probe_points=probes, surface_vertices=vertices, surface_faces=faces,
        solver=SolverReport(iterations=42, residual=3.5e-9, stage_times={"geometry": 0.25, "solve": 1.5},
                            warnings=["2 cells below volume fraction 1e-3 merged"]),
    )


def assert_levels_equal(a: FieldData, b: FieldData) -> None:
    assert a.time == b.time
    for group in ("cells", "probes", "surface"):
        x, y = getattr(a, group), getattr(b, group)
        assert sorted(x) == sorted(y), group
        for name in x:
            assert x[name].dtype == y[name].dtype, (group, name)
            np.testing.assert_array_equal(x[name], y[name])  # exact, NaN == NaN


@pytest.mark.parametrize("dim", [3, 2])
def test_round_trip_is_exact(tmp_path, dim):
    r = make_result(dim)
    path = write_result(r, tmp_path / "result.h5")
    assert path == tmp_path / "result.h5"
    s = read_result(path)
    assert s.grid == r.grid and s.method == r.method and s.spec == r.spec and s.version == r.version
    np.testing.assert_array_equal(s.volume_fraction, r.volume_fraction)
    np.testing.assert_array_equal(s.probe_points, r.probe_points)
    np.testing.assert_array_equal(s.surface_vertices, r.surface_vertices)
    np.testing.assert_array_equal(s.surface_faces, r.surface_faces)
    assert s.surface_faces.dtype == np.int64
    assert_levels_equal(s.fields, r.fields)
    assert len(s.steps) == 2
    for a, b in zip(s.steps, r.steps):
        assert_levels_equal(a, b)
    assert s.solver == r.solver


def test_minimal_result_round_trip(tmp_path):
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(2, 1, 1))
    r = Result(grid=grid, method="dg", spec={}, volume_fraction=np.array([[[1.0]], [[0.5]]]))
    s = read_result(write_result(r, tmp_path / "r.h5", xdmf=False))
    assert (s.probe_points, s.surface_vertices, s.surface_faces, s.solver, s.steps) == (None, None, None, None, [])
    assert s.fields == FieldData()  # no datasets, no time
    assert not (tmp_path / "r.xdmf").exists()
    with h5py.File(tmp_path / "r.h5") as f:
        assert "xdmf" not in f and "steps" not in f and "solver" not in f


def test_layout_units_and_dimension_scales(tmp_path):
    r = make_result(3)
    write_result(r, tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5") as f:
        assert dict(f.attrs) | {"spec": None} == {"format": "voxelastic-result", "format_version": 1,
                                                 "method": "staggered", "spec": None, "version": "0.2.0"}
        assert json.loads(f.attrs["spec"]) == r.spec
        g = f["grid"].attrs
        np.testing.assert_array_equal(g["origin"], [-0.5, 0.25, 1.0])
        np.testing.assert_array_equal(g["shape"], [3, 4, 5])
        assert g["spacing"] == 0.125
        np.testing.assert_array_equal(f["y"][()], 0.25 + 0.125 * (np.arange(4) + 0.5))
        expected = {  # dataset: (units, location, components)
            "cells/volume_fraction": ("1", "cell_center", None),
            "fields/displacement": ("m", "cell_center", ["x", "y", "z"]),
            "fields/stress": ("Pa", "cell_center", ["xx", "yy", "zz", "yz", "xz", "xy"]),
            "fields/von_mises": ("Pa", "cell_center", None),
            "steps/0001/fields/stress": ("Pa", "cell_center", ["xx", "yy", "zz", "yz", "xz", "xy"]),
            "probes/points": ("m", "probe", ["x", "y", "z"]),
            "probes/stress": ("Pa", "probe", ["xx", "yy", "zz", "yz", "xz", "xy"]),
            "steps/0000/probes/displacement": ("m", "probe", ["x", "y", "z"]),
            "surface/vertices": ("m", "surface_vertex", ["x", "y", "z"]),
            "surface/faces": ("1", "surface_face", None),
            "surface/displacement": ("m", "surface_vertex", ["x", "y", "z"]),
            "steps/0001/surface/displacement": ("m", "surface_vertex", ["x", "y", "z"]),
            "x": ("m", "cell_center", None),
        }
        for name, (units, location, comps) in expected.items():
            a = f[name].attrs
            assert (a["units"], a["location"]) == (units, location), name
            assert (list(a["components"]) if "components" in a else None) == comps, name
        for name, last in [("cells/volume_fraction", None), ("fields/von_mises", None),
                           ("fields/displacement", "/component"), ("steps/0000/fields/stress", "/voigt")]:
            ds = f[name]
            scales = [ds.dims[i][0].name for i in range(ds.ndim)]
            assert scales == ["/x", "/y", "/z"] + ([last] if last else []), name
            assert ds.compression == "gzip" and ds.compression_opts == 4 and ds.chunks is not None
        assert [s.decode() for s in f["voigt"][()]] == ["xx", "yy", "zz", "yz", "xz", "xy"]
        assert f["steps/0000"].attrs["time"] == 0.25 and f["steps/0001"].attrs["time"] == 0.5
        s = f["solver"].attrs
        assert (s["iterations"], s["residual"]) == (42, 3.5e-9)
        assert json.loads(s["stage_times"]) == {"geometry": 0.25, "solve": 1.5} and s["stage_times_units"] == "s"
        assert list(s["warnings"]) == ["2 cells below volume fraction 1e-3 merged"]


def test_cell_chunks_are_about_a_mebibyte():
    assert output._cell_chunks((256, 256, 256), 8, 3) == (50, 50, 50)
    assert output._cell_chunks((256, 256, 256, 6), 8, 3) == (27, 27, 27, 6)
    assert output._cell_chunks((4, 300), 8, 2) == (4, 300)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda r: r.fields.cells.update(stress=np.zeros((3, 4, 5, 3))),
         "fields/stress: shape (3, 4, 5, 3), expected (3, 4, 5, 6) (grid.shape + voigt components)"),
        (lambda r: r.steps[1].cells.update(von_mises=np.zeros((3, 4))),
         "steps/0001/fields/von_mises: shape (3, 4), expected (3, 4, 5) (grid.shape + scalar components)"),
        (lambda r: r.fields.probes.update(displacement=np.zeros((3, 3))),
         "probes/displacement: shape (3, 3), expected (2, 3) (probe count + vector components)"),
        (lambda r: r.fields.surface.update(displacement=np.zeros((4, 2))),
         "surface/displacement: shape (4, 2), expected (4, 3) (surface vertex count + vector components)"),
        (lambda r: r.fields.cells.update(temperature=np.zeros((3, 4, 5))),
         "fields/temperature: unknown field name; known fields: displacement, velocity, strain, stress, von_mises, "
         "pressure"),
        (lambda r: setattr(r, "probe_points", None), "probes/displacement: the result has no probe_points"),
        (lambda r: setattr(r.steps[1], "time", 0.25),
         "steps/0001: time 0.25 must be finite and greater than the previous step's"),
        (lambda r: r.volume_fraction.__setitem__((1, 1, 1), 1.5),
         "cells/volume_fraction: values must lie in [0, 1] (NaN not allowed)"),
        (lambda r: setattr(r, "surface_faces", np.array([[0, 1, 4]])),
         "surface/faces: vertex indices must lie in [0, 4), got 0..4"),
        (lambda r: setattr(r, "surface_faces", None),
         "surface: give both surface_vertices and surface_faces, or neither"),
        (lambda r: r.fields.cells.update(displacement=np.zeros((3, 4, 5, 3), dtype=complex)),
         "fields/displacement: expected a real-valued array, got dtype complex128"),
        (lambda r: setattr(r, "spec", {"f": object()}),
         "spec: not JSON-serialisable (Object of type object is not JSON serializable)"),
    ],
)
def test_writer_rejects_inconsistent_data_and_writes_nothing(tmp_path, mutate, message):
    r = make_result(3)
    mutate(r)
    with pytest.raises(ValueError) as info:
        write_result(r, tmp_path / "r.h5")
    assert str(info.value) == message
    assert list(tmp_path.iterdir()) == []


def fail_on_steps(monkeypatch):
    """Make the writer fail after the root fields are on disk, while writing the first step."""
    original = output._write_level

    def write_level(parent, level, r, scales):
        if parent.name.startswith("/steps"):
            raise OSError("disk full (simulated)")
        original(parent, level, r, scales)

    monkeypatch.setattr(output, "_write_level", write_level)


def test_failed_write_leaves_no_file_and_no_temporary(tmp_path, monkeypatch):
    fail_on_steps(monkeypatch)
    with pytest.raises(OSError, match="disk full"):
        write_result(make_result(3), tmp_path / "r.h5")
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_previous_files_intact(tmp_path, monkeypatch):
    write_result(make_result(3, seed=1), tmp_path / "r.h5")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert sorted(before) == ["r.h5", "r.solid.xdmf", "r.surface.xdmf", "r.vtkhdf", "r.xdmf"]

    def broken_xdmf(f, name):  # fails after the whole HDF5 temporary is written
        raise RuntimeError("xdmf failed")

    monkeypatch.setattr(xdmf, "xdmf_document", broken_xdmf)
    with pytest.raises(RuntimeError, match="xdmf failed"):
        write_result(make_result(3, seed=2), tmp_path / "r.h5")
    monkeypatch.undo()
    fail_on_steps(monkeypatch)
    with pytest.raises(OSError, match="disk full"):
        write_result(make_result(3, seed=3), tmp_path / "r.h5")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    previous = make_result(3, seed=1).volume_fraction
    np.testing.assert_array_equal(read_result(tmp_path / "r.h5").volume_fraction, previous)


def test_xdmf_suffix_for_the_result_is_rejected(tmp_path):
    with pytest.raises(ValueError, match=r"the HDF5 result needs another suffix than \.xdmf"):
        write_result(make_result(2), tmp_path / "r.xdmf")


def test_reader_errors(tmp_path):
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(ResultFormatError) as info:
        read_result(text)
    assert str(info.value) == f"{text}: not an HDF5 file"

    with pytest.raises(ResultFormatError) as info:
        read_result(tmp_path / "missing.h5")
    assert str(info.value) == f"{tmp_path / 'missing.h5'}: no such file"

    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["data"] = np.zeros(3)
    with pytest.raises(ResultFormatError) as info:
        read_result(other)
    assert str(info.value) == f"{other}: not a voxelastic result (no 'format' attribute)"
    with h5py.File(other, "a") as f:
        f.attrs["format"] = "netcdf"
    with pytest.raises(ResultFormatError) as info:
        read_result(other)
    assert str(info.value) == f"{other}: not a voxelastic result (format 'netcdf', expected 'voxelastic-result')"

    path = write_result(make_result(2), tmp_path / "r.h5")
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 2
    with pytest.raises(ResultFormatError) as info:
        read_result(path)
    assert str(info.value) == f"{path}: result file has format_version 2, this voxelastic reads 1"
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 1
        del f["grid"]
    with pytest.raises(ResultFormatError) as info:
        read_result(path)
    assert str(info.value) == f"{path}: group /grid missing"


# ---------------------------------------------------------------------------------------------
# XDMF through a real reader (VTK's XDMF reader, the one ParaView ships)


def read_vtk(xdmf_path, time: float | None = None) -> dict:
    """Blocks of the XDMF file as {grid name: vtkDataSet}, at ``time`` for temporal files."""
    xdmf2 = pytest.importorskip("vtkmodules.vtkIOXdmf2", reason="needs vtk (test extra)")
    reader = xdmf2.vtkXdmfReader()
    reader.SetFileName(str(xdmf_path))
    reader.UpdateInformation()
    reader.UpdateTimeStep(time if time is not None else 0.0)
    out = reader.GetOutputDataObject(0)
    return {out.GetMetaData(b).Get(out.NAME()): out.GetBlock(b) for b in range(out.GetNumberOfBlocks())}


def vtk_array(data, name: str) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    array = data.GetArray(name)
    assert array is not None, name
    return vtk_to_numpy(array)


def check_cells(block, grid: Grid, vf: np.ndarray, level: FieldData) -> None:
    """Every VTK cell, located by its own geometry, carries the values of the cell index at that place."""
    d = grid.dim
    assert block.GetNumberOfCells() == grid.num_cells
    data = block.GetCellData()
    for c in range(block.GetNumberOfCells()):
        lo, hi = np.array(block.GetCell(c).GetBounds()).reshape(3, 2).T
        centre = 0.5 * (lo + hi)[:d]
        np.testing.assert_allclose(hi[:d] - lo[:d], grid.spacing, rtol=1e-12)
        index = tuple(int(i) for i in np.floor((centre - np.asarray(grid.origin)) / grid.spacing))
        assert vtk_array(data, "volume_fraction")[c] == vf[index]
        assert vtk_array(data, "von_mises")[c] == level.cells["von_mises"][index]
        u = vtk_array(data, "displacement")[c]
        np.testing.assert_array_equal(u[:d], level.cells["displacement"][index])
        assert np.all(u[d:] == 0)  # VTK pads 2D vectors with a zero z component
        for k, label in enumerate(output.VOIGT[d]):
            assert vtk_array(data, f"stress_{label}")[c] == level.cells["stress"][index + (k,)]


def check_points(block, points: np.ndarray, values: dict[str, np.ndarray], cells: np.ndarray | None) -> None:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    d = points.shape[1]
    xyz = vtk_to_numpy(block.GetPoints().GetData())
    np.testing.assert_array_equal(xyz[:, :d], points)
    u = vtk_array(block.GetPointData(), "displacement")
    np.testing.assert_array_equal(u[:, :d], values["displacement"])
    if cells is not None:
        assert all(block.GetCell(c).GetNumberOfPoints() == d for c in range(block.GetNumberOfCells()))
        ids = [[block.GetCell(c).GetPointId(j) for j in range(d)] for c in range(block.GetNumberOfCells())]
        np.testing.assert_array_equal(ids, cells)


@pytest.mark.parametrize("dim", [3, 2])
def test_xdmf_static_values_through_vtk(tmp_path, dim):
    r = make_result(dim, steps=0)
    (tmp_path / "a").mkdir()
    write_result(r, tmp_path / "a" / "result.h5")
    text = (tmp_path / "a" / "result.xdmf").read_text()
    assert '<Xdmf Version="3.0">' in text and ">result.h5:/fields/displacement<" in text
    assert "tmp" not in text and str(tmp_path) not in text
    shutil.move(tmp_path / "a", tmp_path / "b")  # the sidecar refers to the HDF5 file relatively
    blocks = read_vtk(tmp_path / "b" / "result.xdmf")
    assert sorted(blocks) == ["cells", "probes", "surface"]
    check_cells(blocks["cells"], r.grid, r.volume_fraction, r.fields)
    check_points(blocks["surface"], r.surface_vertices, r.fields.surface, r.surface_faces)
    check_points(blocks["probes"], r.probe_points, r.fields.probes, None)
    assert blocks["surface"].GetCell(0).GetClassName() == ("vtkTriangle" if dim == 3 else "vtkPolyLine")


def test_xdmf_time_steps_through_vtk(tmp_path):
    r = make_result(3, steps=2)
    write_result(r, tmp_path / "r.h5")
    for step in r.steps:
        blocks = read_vtk(tmp_path / "r.xdmf", step.time)
        check_cells(blocks["cells"], r.grid, r.volume_fraction, step)
        check_points(blocks["surface"], r.surface_vertices, step.surface, r.surface_faces)
        check_points(blocks["probes"], r.probe_points, step.probes, None)


def test_netcdf_readers_see_coordinates(tmp_path):
    xr = pytest.importorskip("xarray", reason="needs xarray + h5netcdf")
    pytest.importorskip("h5netcdf")
    r = make_result(3)
    write_result(r, tmp_path / "r.h5")
    tree = xr.open_datatree(tmp_path / "r.h5", engine="h5netcdf", phony_dims="sort")
    stress = tree["fields"]["stress"]
    assert stress.dims == ("x", "y", "z", "voigt") and stress.attrs["units"] == "Pa"
    x, y, z = (r.grid.axis_coordinates(a)[i] for a, i in enumerate((1, 0, 2)))
    assert float(stress.sel(x=x, y=y, z=z, voigt="yz")) == r.fields.cells["stress"][1, 0, 2, 3]
