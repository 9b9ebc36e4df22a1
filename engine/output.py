"""Simulation results: the ``Result`` data classes and the HDF5 result file.

The file's layout (the contract: groups, datasets, shapes, units, attributes) is documented in
docs/result-format.md; ``validate_result`` enforces it before writing and ``read_result`` reads it
back. Files are written atomically (temporary name beside the target, fsync, ``os.replace``)
together with XDMF sidecars (``engine.xdmf``) that ParaView, PyVista, meshio and VTK open directly.
"""

from __future__ import annotations

import errno
import json
import math
import os
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
from schemas.job import MAX_STEPS as _MAX_STEPS  # step groups are named with 4 digits

from . import __version__
from .errors import ResultFormatError
from .guarded_file import GuardedFile
from .targets import replace_problem
from .grid import Grid

FORMAT = "voxelastic-result"
FORMAT_VERSION = 1

AXES = ("x", "y", "z")
VOIGT = {3: ("xx", "yy", "zz", "yz", "xz", "xy"), 2: ("xx", "yy", "xy")}


@dataclass(frozen=True)
class FieldKind:
    """units: SI unit string; rank: "scalar" (no trailing axis), "vector" [d], "voigt" [6 | 3]."""

    units: str
    rank: str


FIELDS: dict[str, FieldKind] = {
    "displacement": FieldKind("m", "vector"),
    "velocity": FieldKind("m/s", "vector"),
    "strain": FieldKind("1", "voigt"),
    "stress": FieldKind("Pa", "voigt"),
    "von_mises": FieldKind("Pa", "scalar"),
    "pressure": FieldKind("Pa", "scalar"),  # -tr(sigma) / 3, positive in compression
}

# Cell arrays are chunked to about this many bytes and gzip-compressed (shuffle helps floats).
_CHUNK_BYTES = 1 << 20
_GZIP_LEVEL = 4
# Probe/surface arrays below this many elements are stored contiguous, uncompressed.
_COMPRESS_MIN_ELEMENTS = 1 << 16
_VF_TOLERANCE = 1e-9  # exact cut-cell volumes may exceed 1 by round-off


def components(name: str, dim: int) -> tuple[str, ...]:
    """Component labels of field ``name`` in ``dim`` dimensions; () for scalars."""
    return _rank_components(FIELDS[name].rank, dim)


def _rank_components(rank: str, dim: int) -> tuple[str, ...]:
    return {"scalar": (), "vector": AXES[:dim], "voigt": VOIGT[dim]}[rank]


@dataclass
class FieldData:
    """Fields at one time level; each dict maps a ``FIELDS`` name to an array.

    cells: [*grid.shape, *c] at cell centres (NaN where empty); probes: [n, *c] at the probe
    points; surface: [m, *c] at the surface vertices. ``c`` is () / (d,) / (6 | 3,) by rank.
    time: [s] for time steps (quasi-static: the load parameter); None for a static state.
    """

    cells: dict[str, np.ndarray] = field(default_factory=dict)
    probes: dict[str, np.ndarray] = field(default_factory=dict)
    surface: dict[str, np.ndarray] = field(default_factory=dict)
    time: float | None = None


@dataclass
class SolverReport:
    """iterations of the (last) linear solve; residual: its final relative residual;
    stage_times: wall time per pipeline stage [s], in execution order; warnings: for the user."""

    iterations: int
    residual: float
    stage_times: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


@dataclass
class Result:
    """Everything a result file holds.

    volume_fraction: [*grid.shape] in [0, 1]. probe_points: [n, d] [m] or None. surface_vertices:
    [m, d] [m] (reference configuration) and surface_faces: [k, d] int (triangles in 3D, segments
    in 2D), both or neither. fields: the final state; steps: the time series of quasi-static and
    dynamic runs (each with ``time``), empty for static runs. spec: the job spec as a JSON-able dict.
    """

    grid: Grid
    method: str
    spec: dict
    volume_fraction: np.ndarray
    fields: FieldData = field(default_factory=FieldData)
    steps: list[FieldData] = field(default_factory=list)
    probe_points: np.ndarray | None = None
    surface_vertices: np.ndarray | None = None
    surface_faces: np.ndarray | None = None
    solver: SolverReport | None = None
    version: str = __version__

    @property
    def dim(self) -> int:
        return self.grid.dim

    def to_xarray(self):
        """The result as an ``xarray.DataTree`` with named dimensions, coordinates and units
        (``engine.convert.to_xarray``; needs xarray)."""
        from .convert import to_xarray

        return to_xarray(self)

    def to_pyvista(self, step: int | None = None):
        """The final state (or ``steps[step]``) as a ``pyvista.MultiBlock`` of the solid, the
        refined surface and the probes (``engine.convert.to_pyvista``; needs PyVista)."""
        from .convert import to_pyvista

        return to_pyvista(self, step)


# ---------------------------------------------------------------------------------------------
# validation


def _real_array(a: object, where: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.kind in "f":
        return a
    if a.dtype.kind in "iub":
        return a.astype(np.float64)
    raise ValueError(f"{where}: expected a real-valued array, got dtype {a.dtype}")


def _expect_shape(a: np.ndarray, expected: tuple[int, ...], where: str, meaning: str) -> None:
    if a.shape != expected:
        raise ValueError(f"{where}: shape {a.shape}, expected {expected} ({meaning})")


def _check_level(level: FieldData, r: Result, prefix: str) -> None:
    d = r.dim
    n = None if r.probe_points is None else (len(r.probe_points),)
    m = None if r.surface_vertices is None else (len(r.surface_vertices),)
    places = (("fields", level.cells, r.grid.shape, "grid.shape", "grid"),
              ("probes", level.probes, n, "probe count", "probe_points"),
              ("surface", level.surface, m, "surface vertex count", "surface_vertices"))
    for group, arrays, lead, meaning, owner in places:
        for name, a in arrays.items():
            where = f"{prefix}{group}/{name}"
            if name not in FIELDS:
                raise ValueError(f"{where}: unknown field name; known fields: {', '.join(FIELDS)}")
            if lead is None:
                raise ValueError(f"{where}: the result has no {owner}")
            comps = components(name, d)
            _expect_shape(_real_array(a, where), tuple(lead) + ((len(comps),) if comps else ()), where,
                          f"{meaning} + {FIELDS[name].rank} components")


def validate_result(r: Result) -> None:
    """Raise ValueError naming the dataset whose shape, dtype or values break the file contract."""
    if not isinstance(r.grid, Grid):
        raise ValueError(f"grid: expected an engine.grid.Grid, got {type(r.grid).__name__}")
    if not (isinstance(r.method, str) and r.method):
        raise ValueError(f"method: expected a non-empty string, got {r.method!r}")
    try:
        json.dumps(r.spec)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"spec: not JSON-serialisable ({exc})") from None
    d = r.dim
    vf = _real_array(r.volume_fraction, "cells/volume_fraction")
    _expect_shape(vf, r.grid.shape, "cells/volume_fraction", "grid.shape")
    if not np.all((vf >= -_VF_TOLERANCE) & (vf <= 1 + _VF_TOLERANCE)):
        raise ValueError("cells/volume_fraction: values must lie in [0, 1] (NaN not allowed)")
    if r.probe_points is not None:
        p = _real_array(r.probe_points, "probes/points")
        if p.ndim != 2 or p.shape[1] != d or not np.all(np.isfinite(p)):
            raise ValueError(f"probes/points: expected finite [n, {d}] coordinates, got shape {p.shape}")
    if (r.surface_vertices is None) != (r.surface_faces is None):
        raise ValueError("surface: give both surface_vertices and surface_faces, or neither")
    if r.surface_vertices is not None:
        v = _real_array(r.surface_vertices, "surface/vertices")
        f = np.asarray(r.surface_faces)
        if v.ndim != 2 or v.shape[1] != d or not np.all(np.isfinite(v)):
            raise ValueError(f"surface/vertices: expected finite [m, {d}] coordinates, got shape {v.shape}")
        if f.dtype.kind not in "iu" or f.ndim != 2 or f.shape[1] != d:
            raise ValueError(f"surface/faces: expected integer [k, {d}] vertex indices, got {f.dtype} {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"surface/faces: vertex indices must lie in [0, {len(v)}), got {f.min()}..{f.max()}")
    _check_level(r.fields, r, "")
    if len(r.steps) > _MAX_STEPS:
        raise ValueError(f"steps: {len(r.steps)} steps, at most {_MAX_STEPS} fit the 4-digit step names")
    previous = -math.inf
    for i, step in enumerate(r.steps):
        t = step.time
        if t is None or not math.isfinite(t) or t <= previous:
            raise ValueError(f"steps/{i:04d}: time {t} must be finite and greater than the previous step's")
        previous = t
        _check_level(step, r, f"steps/{i:04d}/")
    if r.solver is not None:
        s = r.solver
        if not all(isinstance(k, str) and math.isfinite(float(v)) for k, v in s.stage_times.items()):
            raise ValueError("solver.stage_times: expected {stage name: seconds} with finite times")
        if not all(isinstance(w, str) for w in s.warnings):
            raise ValueError("solver.warnings: expected a list of strings")


# ---------------------------------------------------------------------------------------------
# writing


def _cell_chunks(shape: tuple[int, ...], itemsize: int, dim: int) -> tuple[int, ...]:
    """Chunk of about _CHUNK_BYTES: a cube over the spatial axes, whole over the components."""
    per_cell = itemsize * int(np.prod(shape[dim:], dtype=np.int64))
    edge = max(1, int((_CHUNK_BYTES / per_cell) ** (1.0 / dim)))
    return tuple(min(n, edge) for n in shape[:dim]) + tuple(shape[dim:])


def _dataset(group: h5py.Group, name: str, data: np.ndarray, units: str, location: str,
             comps: tuple[str, ...] = (), chunks: tuple[int, ...] | None = None) -> h5py.Dataset:
    if chunks is not None:
        ds = group.create_dataset(name, data=data, chunks=chunks, compression="gzip",
                                  compression_opts=_GZIP_LEVEL, shuffle=True)
    elif data.size >= _COMPRESS_MIN_ELEMENTS:
        ds = group.create_dataset(name, data=data, chunks=True, compression="gzip",
                                  compression_opts=_GZIP_LEVEL, shuffle=True)
    else:
        ds = group.create_dataset(name, data=data)
    ds.attrs["units"] = units
    ds.attrs["location"] = location
    if comps:
        ds.attrs["components"] = np.array(comps, dtype=h5py.string_dtype())
    return ds


# The dimension scale of each rank's component axis.
_COMPONENT_SCALE = {"scalar": None, "vector": "component", "voigt": "voigt"}


def _cell_dataset(group: h5py.Group, name: str, data: np.ndarray, kind: FieldKind,
                  scales: dict[str, h5py.Dataset]) -> None:
    """Cell array with every axis on a dimension scale (netCDF readers reject partly labelled ones)."""
    dim = data.ndim - (kind.rank != "scalar")
    ds = _dataset(group, name, data, kind.units, "cell_center", _rank_components(kind.rank, dim),
                  _cell_chunks(data.shape, data.itemsize, dim))
    labels = list(AXES[:dim]) + ([_COMPONENT_SCALE[kind.rank]] if kind.rank != "scalar" else [])
    for axis, label in enumerate(labels):
        ds.dims[axis].attach_scale(scales[label])
        ds.dims[axis].label = label


def _write_nodes(group: h5py.Group, grid: Grid) -> None:
    """Cell-corner coordinates [*shape+1, d], written in slabs that match the chunks along x."""
    d = grid.dim
    axes = [grid.axis_coordinates(a, offset=1) for a in range(d)]
    shape = tuple(len(c) for c in axes) + (d,)
    chunks = (16,) * d + (d,)
    chunks = tuple(min(c, n) for c, n in zip(chunks, shape))
    ds = group.create_dataset("nodes", shape=shape, dtype=np.float64, chunks=chunks,
                              compression="gzip", compression_opts=_GZIP_LEVEL, shuffle=True)
    for i0 in range(0, shape[0], chunks[0]):
        ds[i0:i0 + chunks[0]] = np.stack(np.meshgrid(axes[0][i0:i0 + chunks[0]], *axes[1:], indexing="ij"), -1)
    ds.attrs["units"] = "m"
    ds.attrs["location"] = "cell_corner"
    ds.attrs["components"] = np.array(AXES[:d], dtype=h5py.string_dtype())


def _write_level(parent: h5py.Group, level: FieldData, r: Result, scales: dict[str, h5py.Dataset]) -> None:
    d = r.dim
    fields = parent.require_group("fields")
    if level.time is not None:
        parent.attrs["time"] = float(level.time)
    for name, a in level.cells.items():
        _cell_dataset(fields, name, _real_array(a, name), FIELDS[name], scales)
    for group, arrays, location in (("probes", level.probes, "probe"), ("surface", level.surface, "surface_vertex")):
        if arrays:
            g = parent.require_group(group)
            for name, a in arrays.items():
                _dataset(g, name, _real_array(a, name), FIELDS[name].units, location, components(name, d))


def _write_h5(f: h5py.File, r: Result, nodes: bool) -> None:
    d = r.dim
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = FORMAT_VERSION
    f.attrs["method"] = r.method
    f.attrs["spec"] = json.dumps(r.spec)
    f.attrs["version"] = r.version
    g = f.create_group("grid")
    g.attrs["origin"] = np.asarray(r.grid.origin, dtype=np.float64)
    g.attrs["spacing"] = float(r.grid.spacing)
    g.attrs["shape"] = np.asarray(r.grid.shape, dtype=np.int64)
    # Coordinate variables live at the root: netCDF resolves a dimension in the variable's own group
    # or an ancestor, so scales under /grid would be invisible from /fields.
    scales = {}
    for axis in range(d):
        scales[AXES[axis]] = _dataset(f, AXES[axis], r.grid.axis_coordinates(axis), "m", "cell_center")
    scales["component"] = f.create_dataset("component", data=np.array(AXES[:d], dtype=h5py.string_dtype()))
    scales["voigt"] = f.create_dataset("voigt", data=np.array(VOIGT[d], dtype=h5py.string_dtype()))
    for label, scale in scales.items():
        scale.make_scale(label)
    if nodes:
        _write_nodes(f.create_group("xdmf"), r.grid)
    _cell_dataset(f.create_group("cells"), "volume_fraction", _real_array(r.volume_fraction, ""),
                  FieldKind("1", "scalar"), scales)
    if r.probe_points is not None:
        _dataset(f.require_group("probes"), "points", _real_array(r.probe_points, ""), "m", "probe", AXES[:d])
    if r.surface_vertices is not None:
        s = f.require_group("surface")
        _dataset(s, "vertices", _real_array(r.surface_vertices, ""), "m", "surface_vertex", AXES[:d])
        _dataset(s, "faces", np.asarray(r.surface_faces, dtype=np.int64), "1", "surface_face")
    _write_level(f, r.fields, r, scales)
    if r.steps:
        steps = f.create_group("steps")
        for i, step in enumerate(r.steps):
            _write_level(steps.create_group(f"{i:04d}"), step, r, scales)
    _write_peaks(f, r)
    if r.solver is not None:
        s = f.create_group("solver")
        s.attrs["iterations"] = int(r.solver.iterations)
        s.attrs["residual"] = float(r.solver.residual)
        s.attrs["stage_times"] = json.dumps({k: float(v) for k, v in r.solver.stage_times.items()})
        s.attrs["stage_times_units"] = "s"
        s.attrs["warnings"] = np.array(r.solver.warnings, dtype=h5py.string_dtype())


def _write_peaks(f: h5py.File, r: Result) -> None:
    """/peak: the largest von Mises on the surface and in the volume (engine.peaks), where the
    result holds a stress: attrs <place>_von_mises [Pa], <place>_location [d] [m] and, for a time
    series, <place>_time [s]."""
    from .peaks import peaks  # computed from the result itself (peaks imports this module)

    found = peaks(r)
    if not found:
        return
    g = f.create_group("peak")
    g.attrs["units"] = "Pa"
    g.attrs["location_units"] = "m"
    for place, peak in found.items():
        g.attrs[f"{place}_von_mises"] = peak.value
        g.attrs[f"{place}_location"] = np.asarray(peak.location, dtype=np.float64)
        if peak.time is not None:
            g.attrs[f"{place}_time"] = float(peak.time)


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # some platforms cannot open directories; the rename is then as durable as it gets
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def outside_probes_warning(result: Result, shown: int = 5) -> str | None:
    """A warning naming the probes that lie outside the solid (their values are NaN), or None.

    A probe in a cell without material has nothing to sample; a NaN in the file without a word
    looked like a solver failure (issue 18).
    """
    if result.probe_points is None or not result.fields.probes:
        return None
    # the pipeline decides "outside" from the surface and blanks every field there
    # (engine.geometry.containment); a result made some other way may have NaN in only some
    n = len(result.probe_points)
    outside = np.zeros(n, dtype=bool)
    for values in result.fields.probes.values():
        outside |= np.isnan(np.asarray(values, dtype=float).reshape(n, -1)).any(axis=1)
    count = int(outside.sum())
    if count == 0:
        return None
    where = ", ".join("(" + ", ".join(f"{c:.12g}" for c in point) + ")" for point in result.probe_points[outside][:shown])
    more = f" and {count - shown} more" if count > shown else ""
    return (f"{count} of {n} probes lie outside the solid, where there is nothing to sample "
            f"(NaN in their values): {where}{more}")


def estimate_result_bytes(shape: Sequence[int], fields: Sequence[str], *, levels: int = 1,
                          surface_vertices: int = 0, probes: int = 0) -> int:
    """Size of the result files before compression [bytes]: what a job needs free on the disk.

    Every cell array is stored dense over the grid (``shape``): the volume fraction, the cell
    corners for XDMF, and each of ``fields`` per level (the final state, plus one per step of a
    quasi-static or dynamic job: ``levels`` = steps + 1); surface and probe values per level. The
    viewer files (``sidecar_paths``) hold the material cells again, at most every cell, twice (the
    XDMF views and the VTKHDF file) with their corners, and the refined surface (at most
    ``engine.views.MAX_REFINED_FACES`` facets). gzip shrinks empty cells to almost nothing, so real
    files are smaller; an upper bound is what a check of free space wants.
    """
    from .views import MAX_REFINED_FACES

    dim = len(shape)
    cells = int(np.prod(shape, dtype=np.int64))
    corners = int(np.prod([n + 1 for n in shape], dtype=np.int64))
    per_point = sum(max(1, len(components(name, dim))) for name in fields)
    per_level = (cells + surface_vertices + probes) * per_point
    dense = cells + corners * dim + 3 * surface_vertices + levels * per_level
    # a surface meets about cells^((d-1)/d) cells of the grid around it; refined to the cell size it
    # has a few vertices in each (8 allowed), and never more than the facet cap allows
    refined = min(MAX_REFINED_FACES // 2, max(surface_vertices, 8 * math.ceil(cells ** ((dim - 1) / dim))))
    refined = refined if surface_vertices else 0
    views = 2 * (corners * 3 + cells * (2**dim + dim + 1) + levels * (cells * per_point + corners * (dim + 1))) \
        + refined * (2 * dim + 1 + levels * (per_point + 1))
    return 8 * (dense + views) + 64 * 1024


def sidecar_paths(path: str | os.PathLike) -> dict[str, Path]:
    """The XDMF files written beside the HDF5 result ``path``: "all" (``<stem>.xdmf``: every cell,
    the surface and the probes; ParaView/VTK), "solid" (``<stem>.solid.xdmf``: the material cells
    with corner values) and "surface" (``<stem>.surface.xdmf``: the refined surface); the last two
    hold one grid or one time series each, which is what meshio reads), and "vtkhdf"
    (``<stem>.vtkhdf``: the solid for PyVista, VTK and ParaView; ``engine.vtkhdf``)."""
    path = Path(path)
    return {"all": path.with_suffix(".xdmf"), "solid": path.with_name(f"{path.stem}.solid.xdmf"),
            "surface": path.with_name(f"{path.stem}.surface.xdmf"), "vtkhdf": path.with_suffix(".vtkhdf")}


def write_result(result: Result, path: str | os.PathLike, *, xdmf: bool = True) -> Path:
    """Write ``result`` to the HDF5 file ``path`` and, if ``xdmf``, the files of ``sidecar_paths``
    beside it (the surface one only when the result has a surface).

    Validates first (ValueError naming the dataset); ``FileExistsError`` when a target must not be
    replaced (``replace_problem``). The files appear complete or not at all: they
    are written under temporary names in the target directory, fsynced and renamed into place; on
    any error the temporaries are removed and existing files at the targets are left untouched.
    Returns the HDF5 path.
    """
    from .vtkhdf import write_vtkhdf
    from .xdmf import view_document, write_view_datasets, xdmf_document  # they read this layout

    path = Path(path)
    if path.suffix in (".xdmf", ".vtkhdf"):
        raise ValueError(f"{path}: the HDF5 result needs another suffix than {path.suffix} (e.g. .h5)")
    problem = replace_problem(path)
    if problem:
        raise FileExistsError(errno.EEXIST, problem)
    validate_result(result)
    token = uuid.uuid4().hex[:12]
    tmp_h5 = path.with_name(f".{path.name}.{token}.tmp")
    sidecars: dict[Path, str] = {}
    temporaries = [tmp_h5]
    try:
        with open(tmp_h5, "x+b", buffering=0) as fh:
            guard = GuardedFile(fh)
            try:
                with h5py.File(guard, "w") as f:
                    _write_h5(f, result, nodes=xdmf)
                    if xdmf:
                        write_view_datasets(f, result)
                    f.flush()
                    if xdmf:
                        targets = sidecar_paths(path)
                        sidecars[targets["all"]] = xdmf_document(f, path.name)
                        for part in ("solid", "surface"):
                            text = view_document(f, part, path.name)
                            if text is not None:
                                sidecars[targets[part]] = text
            except BaseException as exc:
                if guard.error is not None:  # what HDF5 tripped over after the disk said no
                    raise guard.error from exc
                raise
            if guard.error is not None:
                raise guard.error
            os.fsync(fh.fileno())
        staged = []
        if xdmf:
            target = sidecar_paths(path)["vtkhdf"]
            tmp = target.with_name(f".{target.name}.{token}.tmp")
            temporaries.append(tmp)
            write_vtkhdf(result, tmp)
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
            staged.append((tmp, target))
        for target, text in sidecars.items():
            tmp = target.with_name(f".{target.name}.{token}.tmp")
            temporaries.append(tmp)
            with open(tmp, "x", encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            staged.append((tmp, target))
        os.replace(tmp_h5, path)
        for tmp, target in staged:
            os.replace(tmp, target)
        _fsync_dir(path.parent)
    except BaseException:
        for tmp in temporaries:
            tmp.unlink(missing_ok=True)
        raise
    return path


# ---------------------------------------------------------------------------------------------
# reading


def _attr(obj: h5py.HLObject, name: str, path: Path):
    if name not in obj.attrs:
        raise ResultFormatError(f"{path}: attribute '{name}' missing on {obj.name}")
    return obj.attrs[name]


def _group(parent: h5py.Group, name: str, path: Path) -> h5py.Group:
    g = parent.get(name)
    if not isinstance(g, h5py.Group):
        raise ResultFormatError(f"{path}: group {parent.name.rstrip('/')}/{name} missing")
    return g


def _arrays(parent: h5py.Group, group: str, skip: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    g = parent.get(group)
    if g is None:
        return {}
    return {k: ds[()] for k, ds in g.items() if k not in skip and isinstance(ds, h5py.Dataset)}


def _read_level(parent: h5py.Group) -> FieldData:
    time = parent.attrs.get("time")
    return FieldData(cells=_arrays(parent, "fields"), probes=_arrays(parent, "probes", ("points",)),
                     surface=_arrays(parent, "surface", ("vertices", "faces")),
                     time=None if time is None else float(time))


def _strings(values) -> list[str]:
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.atleast_1d(values)]


def check_format(f: h5py.File, path: Path) -> None:
    """Raise ResultFormatError unless ``f`` is a voxelastic result of FORMAT_VERSION."""
    fmt = f.attrs.get("format")
    if fmt is None:
        raise ResultFormatError(f"{path}: not a voxelastic result (no 'format' attribute)")
    if fmt != FORMAT:
        raise ResultFormatError(f"{path}: not a voxelastic result (format '{fmt}', expected '{FORMAT}')")
    version = int(_attr(f, "format_version", path))
    if version != FORMAT_VERSION:
        raise ResultFormatError(
            f"{path}: result file has format_version {version}, this voxelastic reads {FORMAT_VERSION}")


def read_result(path: str | os.PathLike) -> Result:
    """Read a result file written by ``write_result`` (all arrays loaded into memory).

    Raises ResultFormatError when the file is missing, not HDF5, not a voxelastic result, of another
    format_version, or lacks a required group/attribute.
    """
    path = Path(path)
    if not path.is_file():
        raise ResultFormatError(f"{path}: no such file")
    if not h5py.is_hdf5(path):
        raise ResultFormatError(f"{path}: not an HDF5 file")
    with h5py.File(path, "r") as f:
        check_format(f, path)
        g = _group(f, "grid", path)
        grid = Grid(origin=tuple(float(o) for o in _attr(g, "origin", path)),
                    spacing=float(_attr(g, "spacing", path)),
                    shape=tuple(int(n) for n in _attr(g, "shape", path)))
        cells = _group(f, "cells", path)
        if "volume_fraction" not in cells:
            raise ResultFormatError(f"{path}: dataset /cells/volume_fraction missing")
        probes, surface = f.get("probes"), f.get("surface")
        steps = f.get("steps")
        solver = None
        if "solver" in f:
            s = f["solver"]
            solver = SolverReport(iterations=int(_attr(s, "iterations", path)),
                                  residual=float(_attr(s, "residual", path)),
                                  stage_times=json.loads(_attr(s, "stage_times", path)),
                                  warnings=_strings(_attr(s, "warnings", path)))
        return Result(
            grid=grid,
            method=str(_attr(f, "method", path)),
            spec=json.loads(_attr(f, "spec", path)),
            volume_fraction=cells["volume_fraction"][()],
            fields=_read_level(f),
            steps=[_read_level(steps[k]) for k in sorted(steps)] if steps is not None else [],
            probe_points=probes["points"][()] if probes is not None and "points" in probes else None,
            surface_vertices=surface["vertices"][()] if surface is not None and "vertices" in surface else None,
            surface_faces=surface["faces"][()] if surface is not None and "faces" in surface else None,
            solver=solver,
            version=str(_attr(f, "version", path)),
        )
