"""A ``Result`` as an xarray tree or a PyVista mesh (``Result.to_xarray`` / ``Result.to_pyvista``).

xarray and PyVista are imported here only, when asked for, so ``import engine`` stays light.
"""

from __future__ import annotations

import numpy as np

from .output import AXES, FIELDS, VOIGT, FieldData, Result, components

_LAST_AXIS = {"vector": "component", "voigt": "voigt"}


def _levels(result: Result) -> tuple[list[FieldData], np.ndarray | None]:
    """The levels to stack and their times [s] (None for a static result: no time axis)."""
    if result.steps:
        return result.steps, np.array([s.time for s in result.steps], dtype=np.float64)
    return [result.fields], None


def _variable(name: str, arrays: list[np.ndarray], lead: tuple[str, ...], times, location: str, dim: int):
    kind = FIELDS[name]
    dims = lead + ((_LAST_AXIS[kind.rank],) if kind.rank != "scalar" else ())
    data = np.stack(arrays) if times is not None else arrays[0]
    attrs = {"units": kind.units, "location": location}
    if kind.rank != "scalar":
        attrs["components"] = " ".join(components(name, dim))
    return (("time",) + dims if times is not None else dims), data, attrs


def to_xarray(result: Result):
    """An ``xarray.DataTree``: the root holds the cell fields on dimensions (``time``,) ``x``,
    ``y`` (, ``z``) (, ``component`` | ``voigt``) with cell-centre coordinates [m]; ``/probes`` and
    ``/surface`` are their own datasets on ``probe`` / ``vertex`` (and ``face``, ``corner``).
    Every variable has ``units`` and ``location`` attributes; ``time`` [s] exists for quasi-static
    (load parameter) and dynamic results only."""
    import xarray as xr

    d = result.dim
    levels, times = _levels(result)
    coords = {AXES[a]: (AXES[a], result.grid.axis_coordinates(a), {"units": "m"}) for a in range(d)}
    coords["component"] = ("component", list(AXES[:d]))
    coords["voigt"] = ("voigt", list(VOIGT[d]))
    if times is not None:
        coords["time"] = ("time", times, {"units": "s"})
    space = tuple(AXES[:d])
    cells = {"volume_fraction": (space, np.asarray(result.volume_fraction), {"units": "1", "location": "cell_center"})}
    for name in levels[0].cells:
        cells[name] = _variable(name, [lv.cells[name] for lv in levels], space, times, "cell_center", d)
    attrs = {"method": result.method, "version": result.version, "grid_spacing_m": result.grid.spacing}
    if result.solver is not None:
        attrs.update(iterations=result.solver.iterations, residual=result.solver.residual)
    tree = {"/": xr.Dataset(cells, coords=coords, attrs=attrs)}
    if result.probe_points is not None:
        probes = {"position": (("probe", "component"), np.asarray(result.probe_points), {"units": "m"})}
        for name in levels[0].probes:
            probes[name] = _variable(name, [lv.probes[name] for lv in levels], ("probe",), times, "probe", d)
        tree["/probes"] = xr.Dataset(probes)
    if result.surface_vertices is not None:
        surface = {"position": (("vertex", "component"), np.asarray(result.surface_vertices), {"units": "m"}),
                   "faces": (("face", "corner"), np.asarray(result.surface_faces), {"units": "1"})}
        for name in levels[0].surface:
            surface[name] = _variable(name, [lv.surface[name] for lv in levels], ("vertex",), times,
                                      "surface_vertex", d)
        tree["/surface"] = xr.Dataset(surface)
    return xr.DataTree.from_dict(tree)


def _pad3(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    return points if points.shape[1] == 3 else np.column_stack([points, np.zeros(len(points))])


def _flat(values: np.ndarray) -> np.ndarray:
    """2D vectors padded to 3 components (what VTK's vector operations expect)."""
    values = np.asarray(values)
    if values.ndim == 2 and values.shape[1] == 2:
        return np.column_stack([values, np.zeros(len(values))])
    return values


def to_pyvista(result: Result, step: int | None = None):
    """A ``pyvista.MultiBlock`` of one level (the final state, or ``steps[step]``): ``solid`` (the
    material cells as hexahedra / quads with cell values, and displacement, velocity, von Mises at
    the corners), ``surface`` (refined so that it bends with the cells; ``engine.views``) and
    ``probes`` (points), each present when the result has it. Coordinates in metres, 2D padded
    with z = 0; warp with ``block.warp_by_vector("displacement")``."""
    import pyvista as pv

    from .views import refine_surface, refined_values, solid_mesh
    from .xdmf import _NODE_FIELDS

    level = result.fields if step is None else result.steps[step]
    d = result.dim
    vf = np.asarray(result.volume_fraction)
    blocks = pv.MultiBlock()
    solid = solid_mesh(result.grid, vf)
    kind = pv.CellType.HEXAHEDRON if d == 3 else pv.CellType.QUAD
    grid = pv.UnstructuredGrid({kind: solid.cells}, _pad3(solid.points))
    grid.cell_data["volume_fraction"] = solid.cell_values(vf)
    for name, dense in level.cells.items():
        grid.cell_data[name] = _flat(solid.cell_values(dense))
        if name in _NODE_FIELDS:
            grid.point_data[name] = _flat(solid.node_values(dense, vf))
    blocks["solid"] = grid
    if result.surface_vertices is not None and len(result.surface_faces):
        refined = refine_surface(result.surface_vertices, result.surface_faces, result.grid.spacing)
        faces = np.column_stack([np.full(len(refined.faces), d), refined.faces]).ravel()
        mesh = (pv.PolyData(_pad3(refined.vertices), faces=faces) if d == 3
                else pv.PolyData(_pad3(refined.vertices), lines=faces))
        for name in sorted(set(level.surface) | ({"von_mises"} & set(level.cells))):
            values = refined_values(refined, result.surface_faces, level.surface.get(name), result.grid,
                                    level.cells.get(name), vf, result.surface_vertices)
            if values is not None:
                mesh.point_data[name] = _flat(values)
        blocks["surface"] = mesh
    if result.probe_points is not None:
        probes = pv.PolyData(_pad3(result.probe_points))
        for name, values in level.probes.items():
            probes.point_data[name] = _flat(values)
        blocks["probes"] = probes
    return blocks
