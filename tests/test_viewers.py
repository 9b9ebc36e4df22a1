"""Result files in the readers users reach for: meshio, PyVista, VTK (XDMF and VTKHDF), xarray;
the refined surface of a coarse bar; the preview picture.

Values are checked against the HDF5 contract's own datasets (read with h5py), at cells located
by the readers' geometry, not by index."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

import engine
from engine.output import read_result, write_result

ROOT = Path(__file__).resolve().parents[1]
meshio = pytest.importorskip("meshio", reason="needs meshio (test extra)")
pv = pytest.importorskip("pyvista")


def bar_spec(analysis: dict, resolution: int) -> dict:
    spec = json.loads((ROOT / "examples" / "cantilever.json").read_text())
    spec["grid"] = {"resolution": resolution, "padding": 1}
    spec["analysis"] = analysis
    spec["output"]["fields"] = ["displacement", "stress", "von_mises"]
    spec["solver"]["rtol"] = 1e-9
    return spec


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A static and a dynamic (3 steps) job on the bundled bar, written with their viewer files."""
    out = {}
    base = tmp_path_factory.mktemp("viewers")
    for name, analysis, res in (("static", {"kind": "static"}, 20),
                                ("dynamic", {"kind": "dynamic", "time_step": 2e-3, "steps": 3}, 12)):
        result = engine.simulate(bar_spec(analysis, res), ROOT / "examples" / "cantilever.stl")
        out[name] = write_result(result, base / f"{name}.h5")
    return out


def contract(path: Path, level: str = "") -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, float]:
    """(grid origin, {field: dense cell array}, volume fraction, spacing) from the HDF5 datasets."""
    with h5py.File(path, "r") as f:
        g = f["grid"].attrs
        fields = {k: ds[()] for k, ds in f[f"{level}fields"].items()}
        return np.asarray(g["origin"]), fields, f["cells/volume_fraction"][()], float(g["spacing"])


def sample_cells(vf: np.ndarray) -> list[tuple[int, ...]]:
    """A few full cells along the bar: near the clamp, mid-span, near the tip."""
    full = np.argwhere(vf >= 1 - 1e-12)
    xs = np.unique(full[:, 0])
    picks = []
    for x in (xs[1], xs[len(xs) // 2], xs[-2]):
        row = full[full[:, 0] == x]
        picks.append(tuple(row[len(row) // 2]))
    return picks


def check_cells(centres: np.ndarray, cell_values: dict[str, np.ndarray], path: Path, level: str = "") -> None:
    """Each sampled cell, found by its centre among the reader's cells, has the contract's values."""
    origin, fields, vf, h = contract(path, level)
    for index in sample_cells(vf):
        centre = origin + h * (np.asarray(index) + 0.5)
        hit = np.nonzero(np.all(np.abs(centres - centre) < 1e-9 * max(1.0, h), axis=1))[0]
        assert len(hit) == 1, (index, centre)
        np.testing.assert_allclose(cell_values["displacement"][hit[0]], fields["displacement"][index], rtol=1e-12)
        np.testing.assert_allclose(cell_values["von_mises"][hit[0]], fields["von_mises"][index], rtol=1e-12)
        np.testing.assert_allclose(cell_values["stress"][hit[0]], fields["stress"][index], rtol=1e-12)
        assert fields["von_mises"][index] > 0 and np.abs(fields["displacement"][index]).max() > 0


def check_nodes(points: np.ndarray, node_u: np.ndarray, path: Path, level: str = "") -> None:
    """A corner inside the material carries the mean displacement of its 8 (full) cells."""
    origin, fields, vf, h = contract(path, level)
    for index in sample_cells(vf):
        around = [tuple(np.asarray(index) - np.asarray(o)) for o in np.ndindex(2, 2, 2)]
        if not all(vf[c] >= 1 - 1e-12 for c in around):
            continue
        corner = origin + h * np.asarray(index)
        hit = np.nonzero(np.all(np.abs(points - corner) < 1e-9, axis=1))[0]
        assert len(hit) == 1
        expected = np.mean([fields["displacement"][c] for c in around], axis=0)
        np.testing.assert_allclose(node_u[hit[0]], expected, rtol=1e-10)


def vtk_centres(mesh) -> np.ndarray:
    return np.asarray(pv.wrap(mesh).cell_centers().points)


def test_meshio_reads_the_static_solid_and_surface(results):
    path = results["static"]
    mesh = meshio.read(path.with_name("static.solid.xdmf"))
    assert [c.type for c in mesh.cells] == ["hexahedron"]
    centres = mesh.points[mesh.cells[0].data].mean(axis=1)
    check_cells(centres, {k: v[0] for k, v in mesh.cell_data.items()}, path)
    check_nodes(mesh.points, mesh.point_data["displacement"], path)
    surface = meshio.read(path.with_name("static.surface.xdmf"))
    assert surface.cells[0].type == "triangle" and {"displacement", "von_mises"} <= set(surface.point_data)


def test_meshio_reads_the_dynamic_time_steps(results):
    path = results["dynamic"]
    with meshio.xdmf.TimeSeriesReader(path.with_name("dynamic.solid.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == 3
        centres = points[cells[0].data].mean(axis=1)
        for k in range(3):
            t, point_data, cell_data = reader.read_data(k)
            assert t == pytest.approx(2e-3 * (k + 1))
            check_cells(centres, {n: v[0] for n, v in cell_data.items()}, path, f"steps/{k:04d}/")
            check_nodes(points, point_data["displacement"], path, f"steps/{k:04d}/")
    first, last = contract(path, "steps/0000/")[1], contract(path, "steps/0002/")[1]
    assert not np.allclose(np.nan_to_num(first["displacement"]), np.nan_to_num(last["displacement"]))


def test_pyvista_and_vtk_read_the_vtkhdf_file(results):
    path = results["static"]
    mesh = pv.read(path.with_suffix(".vtkhdf"))
    assert isinstance(mesh, pv.UnstructuredGrid)
    check_cells(vtk_centres(mesh), {k: np.asarray(mesh.cell_data[k]) for k in mesh.cell_data.keys()}, path)
    check_nodes(np.asarray(mesh.points), np.asarray(mesh.point_data["displacement"]), path)

    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as pipeline
    from vtkmodules.vtkIOHDF import vtkHDFReader

    dynamic = results["dynamic"]
    reader = vtkHDFReader()
    reader.SetFileName(str(dynamic.with_suffix(".vtkhdf")))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(pipeline.TIME_STEPS())
    np.testing.assert_allclose(times, [2e-3, 4e-3, 6e-3])
    for k, t in enumerate(times):
        reader.UpdateTimeStep(t)
        step = pv.wrap(reader.GetOutputDataObject(0))
        check_cells(vtk_centres(step), {n: np.asarray(step.cell_data[n]) for n in step.cell_data.keys()},
                    dynamic, f"steps/{k:04d}/")


def test_a_one_step_vtkhdf_file_carries_its_time(results, tmp_path):
    """VTK reads /VTKHDF/Steps only for two steps or more: a dynamic job of one step wrote a file
    without the time that the HDF5 result and the .solid.xdmf carry; the field "Time" holds it."""
    from vtkmodules.vtkIOHDF import vtkHDFReader

    spec = bar_spec({"kind": "dynamic", "time_step": 2e-3, "steps": 1}, 8)
    one = write_result(engine.simulate(spec, ROOT / "examples" / "cantilever.stl"), tmp_path / "one.h5")
    np.testing.assert_array_equal(pv.read(one.with_suffix(".vtkhdf")).field_data["Time"], [2e-3])
    assert 'Time Value="0.002"' in one.with_suffix(".solid.xdmf").read_text()
    reader = vtkHDFReader()  # and the time series keeps one value per step
    reader.SetFileName(str(results["dynamic"].with_suffix(".vtkhdf")))
    for k in range(3):
        reader.SetStep(k)
        reader.Update()
        time = reader.GetOutput().GetFieldData().GetArray("Time")
        assert (time.GetNumberOfTuples(), time.GetValue(0)) == (1, pytest.approx(2e-3 * (k + 1)))


def test_vtk_xdmf_reader_opens_the_solid_time_series(results):
    from vtkmodules.vtkIOXdmf2 import vtkXdmfReader

    path = results["dynamic"]
    reader = vtkXdmfReader()
    reader.SetFileName(str(path.with_name("dynamic.solid.xdmf")))
    reader.UpdateInformation()
    for k, t in enumerate((2e-3, 4e-3, 6e-3)):
        reader.UpdateTimeStep(t)
        grid = pv.wrap(reader.GetOutputDataObject(0))
        check_cells(vtk_centres(grid), {n: np.asarray(grid.cell_data[n]) for n in grid.cell_data.keys()},
                    path, f"steps/{k:04d}/")


def test_result_to_xarray_and_to_pyvista(results):
    static, dynamic = read_result(results["static"]), read_result(results["dynamic"])
    tree = static.to_xarray()
    u = tree["displacement"]
    assert u.dims == ("x", "y", "z", "component") and u.attrs["units"] == "m"
    assert list(tree["component"].values) == ["x", "y", "z"]
    assert tree["von_mises"].attrs["units"] == "Pa" and tree["stress"].dims[-1] == "voigt"
    origin, fields, vf, h = contract(results["static"])
    i, j, k = sample_cells(vf)[1]
    at = u.sel(x=origin[0] + h * (i + 0.5), y=origin[1] + h * (j + 0.5), z=origin[2] + h * (k + 0.5), method="nearest")
    np.testing.assert_array_equal(at.values, fields["displacement"][i, j, k])
    assert tree["probes"]["displacement"].dims == ("probe", "component")
    assert tree["surface"]["displacement"].dims == ("vertex", "component")
    series = dynamic.to_xarray()
    np.testing.assert_allclose(series["time"].values, [2e-3, 4e-3, 6e-3])
    assert series["displacement"].dims == ("time", "x", "y", "z", "component")
    blocks = static.to_pyvista()
    solid = blocks["solid"]
    check_cells(vtk_centres(solid), {n: np.asarray(solid.cell_data[n]) for n in solid.cell_data.keys()},
                results["static"])


def test_refined_surface_of_a_coarse_bar_bends_as_its_cells(results):
    # the bundled bar's STL has vertices at its two ends only: its deformed surface must bend anyway
    path = results["static"]
    result = read_result(path)
    assert len(result.surface_vertices) == 8
    surface = meshio.read(path.with_name("static.surface.xdmf"))
    x, u = surface.points, surface.point_data["displacement"]
    h = result.grid.spacing
    assert np.linalg.norm(x[surface.cells[0].data[:, 1]] - x[surface.cells[0].data[:, 0]], axis=1).max() <= h
    top = np.nonzero((np.abs(x[:, 2] - x[:, 2].max()) < 1e-12) & (np.abs(x[:, 1] - x[:, 1].max()) < 1e-12))[0]
    top = top[np.argsort(x[top, 0])]
    w = u[top, 2]
    assert len(top) >= 1 / h  # vertices along the whole edge
    assert np.all(np.diff(w) < 0)  # the tip load and gravity bend it down, more at every step along x
    mid = top[np.argmin(np.abs(x[top, 0] - 0.5))]
    # a cantilever's deflection at half span is 5/16 of the tip's (Euler-Bernoulli); a rigid
    # rotation (what the 8 vertices alone would show) gives 1/2
    assert 0.25 < u[mid, 2] / w[-1] < 0.4
    # and it moves as the cells of that cross-section say
    origin, fields, vf, _ = contract(path)
    s = (x[mid, 0] - origin[0]) / h - 0.5  # between the cross-sections of two cell columns
    i, t = int(np.floor(s)), s - np.floor(s)
    section = [fields["displacement"][c][..., 2][vf[c] > 0.5].mean() for c in (i, i + 1)]
    assert u[mid, 2] == pytest.approx((1 - t) * section[0] + t * section[1], rel=0.03)


def test_preview_shows_the_object(results, tmp_path):
    from PIL import Image

    from engine.preview import render_preview

    png = render_preview(read_result(results["static"]), tmp_path / "p.png", size=(480, 300))
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert image.shape == (300, 480, 3)
    coloured = np.abs(image - image.max(axis=2, keepdims=True)).sum(axis=2) > 60  # neither white nor grey
    assert coloured.mean() > 0.05  # the object and its colour bar, not a blank picture
    centre = coloured[60:240, 60:380]
    assert centre.mean() > 0.05  # the bar itself, in the middle of the picture


def test_facets_of_zero_area_refine_without_a_singular_matrix(tmp_path):
    from engine.views import refine_surface

    # a box with a stray facet whose corners lie on one line (the loader keeps it: its corners
    # differ): writing the voxelized result's viewer files raised "Singular matrix"
    vertices = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [2, 2, 2]], dtype=float)
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 6, 6]])
    refined = refine_surface(vertices, faces, 0.25)
    corners = vertices[faces[refined.parent]]
    assert np.isfinite(refined.weights).all()
    assert np.allclose(refined.weights.sum(axis=1), 1.0)
    assert np.allclose(np.einsum("mk,mkd->md", refined.weights, corners), refined.vertices)
    box = "".join(f"v {x} {y} {z}\n" for x in (0, 1) for y in (0, 1) for z in (0, 1))
    box += "f 1 2 4 3\nf 5 7 8 6\nf 1 5 6 2\nf 3 4 8 7\nf 1 3 7 5\nf 2 6 8 4\n"
    (tmp_path / "box.obj").write_text(box + "v 0.5 0.5 0.5\nv 0.6 0.5 0.5\nv 0.9 0.5 0.5\nf 9 10 11\n")
    from engine.cli import main

    assert main(["voxelize", str(tmp_path / "box.obj"), "--resolution", "8", "-o", str(tmp_path / "box.h5")]) == 0
    assert meshio.read(tmp_path / "box.surface.xdmf").points.shape[1] == 3
