"""XDMF 3 sidecar for a result file, so ParaView/VTK open the HDF5 datasets in place.

The document is built by walking the written HDF5 file, so it describes exactly what is there.

Why a structured mesh (``3DSMesh``) and not ``3DCoRectMesh``: XDMF lays structured data out with
x varying fastest ([nz, ny, nx] C-order), while the result contract stores cell arrays [nx, ny, nz]
C-order (z fastest). No CoRectMesh/RectMesh description can swap axes -- VTK shows such a grid
transposed (x and z exchanged, a mirror image). A structured mesh with explicit corner coordinates
(``/xdmf/nodes`` [nx+1, ny+1, nz+1, 3]) indexes points and cells in the file's own order, so every
cell value lands at its true position without a second, transposed copy of each field. The corner
array compresses to under a byte per node (256^3 cells: 8 MB, written in ~4 s).

Grids: ``cells`` (structured; ``volume_fraction`` and every ``/fields`` dataset as Center="Cell"),
``surface`` (Triangle, or Polyline with 2 nodes per element in 2D; Center="Node") and ``probes``
(Polyvertex; Center="Node"). With ``/steps`` each becomes a Collection of CollectionType="Temporal"
holding one grid per step (the final ``/fields`` then equal the last step and are not repeated).
Vectors are Vector attributes; Voigt fields are split into one Scalar per component (``stress_xx``
...) through HyperSlab items, since XDMF's Tensor6 orders components differently.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import h5py
import numpy as np

_AXES = ("x", "y", "z")


def _hdf_item(parent: ET.Element, ds: h5py.Dataset, h5_name: str) -> ET.Element:
    """A DataItem reading dataset ``ds`` of the HDF5 file named ``h5_name`` (relative path)."""
    kind = {"f": "Float", "i": "Int", "u": "UInt"}[ds.dtype.kind]
    item = ET.SubElement(parent, "DataItem", Dimensions=" ".join(map(str, ds.shape)), NumberType=kind,
                         Precision=str(ds.dtype.itemsize), Format="HDF")
    item.text = f"{h5_name}:{ds.name}"
    return item


def _component_item(parent: ET.Element, ds: h5py.Dataset, h5_name: str, c: int) -> None:
    """HyperSlab selecting component ``c`` of the last axis of ``ds``."""
    lead = ds.shape[:-1]
    rank = len(ds.shape)
    slab = ET.SubElement(parent, "DataItem", ItemType="HyperSlab", Type="HyperSlab",
                         Dimensions=" ".join(map(str, lead + (1,))))
    start = " ".join(["0"] * (rank - 1) + [str(c)])
    stride = " ".join(["1"] * rank)
    count = " ".join(map(str, lead + (1,)))
    ET.SubElement(slab, "DataItem", Dimensions=f"3 {rank}", Format="XML").text = f"{start} {stride} {count}"
    _hdf_item(slab, ds, h5_name)


def _strings(values) -> list[str]:
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.atleast_1d(values)]


def _attributes(grid: ET.Element, group: h5py.Group | None, h5_name: str, center: str, dim: int,
                skip: tuple[str, ...] = ()) -> None:
    if group is None:
        return
    for name, ds in group.items():
        if name in skip or not isinstance(ds, h5py.Dataset):
            continue
        comps = _strings(ds.attrs["components"]) if "components" in ds.attrs else []
        if not comps:
            attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType="Scalar", Center=center)
            _hdf_item(attr, ds, h5_name)
        elif comps == list(_AXES[:dim]):
            attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType="Vector", Center=center)
            _hdf_item(attr, ds, h5_name)
        else:
            for c, label in enumerate(comps):
                attr = ET.SubElement(grid, "Attribute", Name=f"{name}_{label}", AttributeType="Scalar",
                                     Center=center)
                _component_item(attr, ds, h5_name, c)


def _uniform(name: str, time: float | None) -> ET.Element:
    grid = ET.Element("Grid", Name=name, GridType="Uniform")
    if time is not None:
        ET.SubElement(grid, "Time", Value=repr(float(time)))
    return grid


def _cell_grid(f: h5py.File, level: h5py.Group, h5_name: str, name: str, time: float | None) -> ET.Element:
    dim = len(f["grid"].attrs["shape"])
    nodes = f["xdmf/nodes"]
    grid = _uniform(name, time)
    ET.SubElement(grid, "Topology", TopologyType=f"{dim}DSMesh", Dimensions=" ".join(map(str, nodes.shape[:dim])))
    _hdf_item(ET.SubElement(grid, "Geometry", GeometryType="XYZ" if dim == 3 else "XY"), nodes, h5_name)
    _attributes(grid, f["cells"], h5_name, "Cell", dim)
    _attributes(grid, level.get("fields"), h5_name, "Cell", dim)
    return grid


def _surface_grid(f: h5py.File, level: h5py.Group, h5_name: str, name: str, time: float | None) -> ET.Element:
    vertices, faces = f["surface/vertices"], f["surface/faces"]
    dim = vertices.shape[1]
    grid = _uniform(name, time)
    shape = {"TopologyType": "Triangle"} if dim == 3 else {"TopologyType": "Polyline", "NodesPerElement": "2"}
    topology = ET.SubElement(grid, "Topology", NumberOfElements=str(faces.shape[0]), **shape)
    _hdf_item(topology, faces, h5_name)
    _hdf_item(ET.SubElement(grid, "Geometry", GeometryType="XYZ" if dim == 3 else "XY"), vertices, h5_name)
    _attributes(grid, level.get("surface"), h5_name, "Node", dim, skip=("vertices", "faces"))
    return grid


def _probe_grid(f: h5py.File, level: h5py.Group, h5_name: str, name: str, time: float | None) -> ET.Element:
    points = f["probes/points"]
    dim = points.shape[1]
    grid = _uniform(name, time)
    ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(points.shape[0]),
                  NodesPerElement="1")
    _hdf_item(ET.SubElement(grid, "Geometry", GeometryType="XYZ" if dim == 3 else "XY"), points, h5_name)
    _attributes(grid, level.get("probes"), h5_name, "Node", dim, skip=("points",))
    return grid


def xdmf_document(f: h5py.File, h5_name: str) -> str:
    """XDMF 3 text describing the open result file ``f``, whose datasets it references as
    ``h5_name:/path`` -- ``h5_name`` relative to the XDMF file (normally the bare file name)."""
    steps = f.get("steps")
    if steps is not None and len(steps):
        levels = [(steps[k], float(steps[k].attrs["time"]), f"_{k}") for k in sorted(steps)]
    else:
        levels = [(f, None, "")]
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    builders = [("cells", _cell_grid)]
    if "surface" in f and "vertices" in f["surface"]:
        builders.append(("surface", _surface_grid))
    if "probes" in f and "points" in f["probes"]:
        builders.append(("probes", _probe_grid))
    for name, build in builders:
        grids = [build(f, level, h5_name, name + suffix, time) for level, time, suffix in levels]
        if levels[0][1] is None:
            domain.extend(grids)
        else:
            series = ET.SubElement(domain, "Grid", Name=name, GridType="Collection", CollectionType="Temporal")
            series.extend(grids)
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


# ---------------------------------------------------------------------------------------------
# One grid per file: the solid and the refined surface (meshio, PyVista, VTK and ParaView alike)
#
# meshio reads an XDMF file of exactly one grid, or of one temporal collection (its
# TimeSeriesReader), and reads each DataItem whole (no HyperSlab): so these documents hold one grid
# (or one collection) each, and every attribute is a whole dataset under /xdmf.

# Vector fields and von Mises also get values at the solid's corners (smooth colouring, warping).
_NODE_FIELDS = ("displacement", "velocity", "von_mises")
_TOPOLOGY = {("solid", 3): "Hexahedron", ("solid", 2): "Quadrilateral",
             ("surface", 3): "Triangle", ("surface", 2): "Polyline"}


def write_view_datasets(f: h5py.File, result) -> None:
    """The solid mesh, the refined surface and their values per level under ``/xdmf`` of the open
    file ``f``, derived from ``result`` (an ``engine.output.Result``; docs/result-format.md)."""
    from .views import refine_surface, refined_values, solid_mesh

    d = result.dim
    vf = np.asarray(result.volume_fraction)
    solid = solid_mesh(result.grid, vf)
    g = f.require_group("xdmf/solid")
    _view_dataset(g, "points", solid.points, "m", "cell_corner")
    _view_dataset(g, "cells", solid.cells, "1", "cell_corner")
    _view_dataset(g, "index", solid.index, "1", "cell_center")
    _view_dataset(g, "volume_fraction", solid.cell_values(vf), "1", "cell_center")
    surface = None
    if result.surface_vertices is not None and len(result.surface_faces):
        surface = refine_surface(result.surface_vertices, result.surface_faces, result.grid.spacing)
        s = f.require_group("xdmf/surface")
        _view_dataset(s, "vertices", surface.vertices, "m", "surface_vertex")
        _view_dataset(s, "faces", surface.faces, "1", "surface_face")
        s.attrs["max_edge"] = surface.max_edge
    levels = [(f"{i:04d}", step) for i, step in enumerate(result.steps)] or [("final", result.fields)]
    from .output import FIELDS

    for key, level in levels:
        lg = f.require_group(f"xdmf/levels/{key}")
        if level.time is not None:
            lg.attrs["time"] = float(level.time)
        cells, nodes = lg.require_group("cells"), lg.require_group("nodes")
        for name, dense in level.cells.items():
            units = FIELDS[name].units
            _view_dataset(cells, name, solid.cell_values(dense), units, "cell_center")
            if name in _NODE_FIELDS:
                _view_dataset(nodes, name, solid.node_values(dense, vf), units, "cell_corner")
        if surface is None:
            continue
        sg = lg.require_group("surface")
        # von Mises and velocity are not surface outputs of the methods: interpolated from the cells
        for name in sorted(set(level.surface) | ({"von_mises", "velocity"} & set(level.cells))):
            values = refined_values(surface, result.surface_faces, level.surface.get(name), result.grid,
                                    level.cells.get(name), vf, result.surface_vertices)
            if values is not None:
                _view_dataset(sg, name, values, FIELDS[name].units, "surface_vertex")
    f["xdmf"].attrs["dimension"] = d


def _view_dataset(group: h5py.Group, name: str, data: np.ndarray, units: str, location: str) -> None:
    data = np.ascontiguousarray(data)
    # compressed from a few kB on: connectivity and refined-surface arrays shrink 3-10x (the
    # bundled example at 32 cells: the file 1.06 MB -> 0.47 MB; 0.08 MB without the viewer data)
    big = data.size >= 1 << 10
    ds = group.create_dataset(name, data=data, **({"chunks": True, "compression": "gzip", "shuffle": True}
                                                   if big else {}))
    ds.attrs["units"] = units
    ds.attrs["location"] = location


def _whole_attribute(grid: ET.Element, ds: h5py.Dataset, h5_name: str, name: str, center: str, dim: int) -> None:
    # VTK's XDMF reader takes a "Matrix" attribute as one value, and "Tensor6" in XDMF's own order
    # (xx, xy, xz, yy, yz, zz) expanded to 9 components: a Voigt array goes as a "Vector", which VTK
    # keeps as it is (6 or 3 components in the file's order xx, yy, zz, yz, xz, xy / xx, yy, xy)
    width = ds.shape[1] if ds.ndim > 1 else 1
    kind = "Scalar" if width == 1 else "Vector"
    attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=kind, Center=center)
    _hdf_item(attr, ds, h5_name)


def _view_grid(f: h5py.File, part: str, level: h5py.Group, h5_name: str, time: float | None) -> ET.Element:
    dim = int(f["xdmf"].attrs["dimension"])
    g = f[f"xdmf/{part}"]
    points, topo = (g["points"], g["cells"]) if part == "solid" else (g["vertices"], g["faces"])
    grid = _uniform(part, time)
    extra = {"NodesPerElement": "2"} if _TOPOLOGY[part, dim] == "Polyline" else {}
    topology = ET.SubElement(grid, "Topology", TopologyType=_TOPOLOGY[part, dim],
                             NumberOfElements=str(topo.shape[0]), **extra)
    _hdf_item(topology, topo, h5_name)
    _hdf_item(ET.SubElement(grid, "Geometry", GeometryType="XYZ" if dim == 3 else "XY"), points, h5_name)
    if part == "solid":
        _whole_attribute(grid, g["volume_fraction"], h5_name, "volume_fraction", "Cell", dim)
        for group, center in (("cells", "Cell"), ("nodes", "Node")):
            for name, ds in level.get(group, {}).items():
                _whole_attribute(grid, ds, h5_name, name, center, dim)
    else:
        for name, ds in level.get("surface", {}).items():
            _whole_attribute(grid, ds, h5_name, name, "Node", dim)
    return grid


def view_document(f: h5py.File, part: str, h5_name: str) -> str | None:
    """XDMF 3 text of one view (``part`` "solid" or "surface") of the open result file ``f``: one
    uniform grid, or one temporal collection of them for a time series; None if ``f`` has no such
    view (no surface)."""
    if f"xdmf/{part}" not in f:
        return None
    levels = f["xdmf/levels"]
    keys = sorted(levels)
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    if keys == ["final"]:
        domain.append(_view_grid(f, part, levels["final"], h5_name, None))
    else:
        series = ET.SubElement(domain, "Grid", Name=part, GridType="Collection", CollectionType="Temporal")
        series.extend(_view_grid(f, part, levels[k], h5_name, float(levels[k].attrs["time"])) for k in keys)
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
