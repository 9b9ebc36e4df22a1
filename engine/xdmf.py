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
