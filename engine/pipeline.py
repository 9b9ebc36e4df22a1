"""Job spec + mesh -> geometry -> grid -> cut-cell geometry -> (discretization -> solve) -> Result.

The same function serves the CLI, the Python API (``engine.simulate``) and the service workers.
Stages report through ``progress(stage, fraction, info)``. The method comes from the registry
(``engine.method``): it names the cut-cell geometry it needs, estimates its memory and builds its
discretization, which the shared analysis drivers run.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from schemas import JobSpec, OutputSpec, parse_job

from .errors import BoundaryError, GeometryError, GridError, VoxelasticError
from .files import read_input
from .geometry.cache import GeometryCache, cache_key, default_directory
from .geometry.containment import in_solid
from .geometry.fractions import VolumeFractions, volume_fractions
from .geometry.loading import load_surface
from .geometry.polygon import polygon_surface
from .geometry.surface import Surface
from .analysis import Progress
from .grid import Grid, make_grid
from .method import Method, Setup, method_entry
from .output import FieldData, Result, SolverReport, components

if TYPE_CHECKING:
    from .geometry.slicing import CutCells

MeshInput = bytes | str | os.PathLike | None


@dataclass(frozen=True)
class Limits:
    """Work a job may ask for; checked before anything large is allocated.

    max_cells: cells of the background grid; max_memory_bytes: estimated peak of the whole job;
    max_triangles: surface facets after loading.
    """

    max_cells: int = 2**28
    max_memory_bytes: int = int(float(os.environ.get("VOXELASTIC_MAX_MEMORY_GB", "16")) * 2**30)
    max_triangles: int = 5_000_000


@dataclass
class Geometry:
    """What the geometry stages produce for one job."""

    surface: Surface
    grid: Grid
    fractions: VolumeFractions | None = None
    cut_cells: CutCells | None = None
    warnings: list[str] = field(default_factory=list)
    stage_times: dict[str, float] = field(default_factory=dict)
    cache_hit: bool = False


def _quiet(stage: str, fraction: float, info: dict) -> None:
    pass


def estimate_memory(grid: Grid, method_spec, surface: Surface | None = None, job: JobSpec | None = None) -> int:
    """Upper estimate of a job's peak memory [bytes] from the grid, the spec's ``method`` and the solid's
    ``surface`` (before any cut-cell work): the method's own estimate (``engine.method``), and with the
    whole spec ``job`` the steps its run keeps (``held_steps_bytes``)."""
    need = method_entry(method_spec.kind).estimate_memory(grid, method_spec, surface=surface)
    return need + (held_steps_bytes(job, grid, surface) if job is not None else 0)


def held_steps_bytes(spec: JobSpec, grid: Grid, surface: Surface | None = None) -> int:
    """Memory [bytes] of the states a quasi-static or dynamic run keeps until its result is written:
    every kept step's output fields (``JobSpec.kept_steps``), dense over the grid and on the surface's
    vertices and the probes (``FieldData``), but the last, which the method's own estimate holds; 0
    for a static run."""
    if spec.analysis.kind == "static":
        return 0
    per_point = sum(max(1, len(components(name, grid.dim))) for name in spec.output.fields)
    # the surface carries every field but the velocity
    on_surface = per_point - (grid.dim if "velocity" in spec.output.fields else 0)
    vertices = len(surface.vertices) if surface is not None and spec.output.surface else 0
    per_step = (grid.num_cells + len(spec.output.probes)) * per_point + vertices * on_surface
    return 8 * (spec.kept_steps - 1) * per_step


def memory_refusal(need: int, limit: int, spec: JobSpec, grid: Grid, surface: Surface | None = None,
                   ) -> tuple[tuple[str, ...], str, str] | None:
    """(the spec's field to change, what exceeds the limit, what to do) when a job's estimate ``need``
    [bytes] exceeds ``limit`` [bytes], None when it fits: the steps the run keeps when they are most of
    it, else the grid. The caller names the limit (its setting differs) between the two sentences."""
    if need <= limit:
        return None
    shape = "x".join(map(str, grid.shape))
    held = held_steps_bytes(spec, grid, surface)
    if 2 * held > need:
        what = (f"{spec.kept_steps} steps of output.fields [{', '.join(spec.output.fields)}] on a {shape} grid are "
                f"kept until the result is written: {held / 2**30:.2f} GiB of the {need / 2**30:.2f} GiB the job needs "
                f"with method '{spec.method.kind}'")
        return ("analysis", "steps"), what, ("keep fewer steps (output.every), lower analysis.steps, output fewer "
                                             "fields or increase grid.cell_size")
    what = f"a {shape} grid needs about {need / 2**30:.2f} GiB for method '{spec.method.kind}'"
    return ("grid",), what, "increase grid.cell_size or lower grid.resolution"


def _check_memory(need: int, limits: Limits, spec: JobSpec, grid: Grid, surface: Surface | None = None) -> None:
    refused = memory_refusal(need, limits.max_memory_bytes, spec, grid, surface)
    if refused is not None:
        where, what, advice = refused
        limit = limits.max_memory_bytes / 2**30
        raise GridError(f"{'.'.join(where)}: {what}, over the limit of {limit:.2f} GiB; {advice}")


def read_mesh_input(spec: JobSpec, mesh: MeshInput, filename: str | None, base_dir: Path | None) -> tuple[bytes, str]:
    """The mesh bytes and file name for a job: given bytes/path, or ``geometry.mesh`` on disk."""
    if isinstance(mesh, (bytes, bytearray)):
        name = filename or spec.geometry.mesh
        if not name:
            raise GeometryError("geometry.mesh: a file name is needed to tell the mesh format of uploaded bytes")
        return bytes(mesh), name
    path = Path(mesh) if mesh is not None else None
    if path is None:
        if spec.geometry.mesh is None:
            raise GeometryError("geometry: neither a mesh file nor a polygon is given")
        path = Path(spec.geometry.mesh)
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
    try:
        return read_input(path), path.name
    except OSError as exc:
        raise GeometryError(f"geometry.mesh: cannot read '{path}': {exc.strerror or exc}") from None


def load_geometry(spec: JobSpec, mesh: MeshInput = None, *, filename: str | None = None, base_dir: Path | None = None) -> tuple[Surface, bytes]:
    """The validated surface of a job and the bytes that identify it (for the cache key)."""
    g = spec.geometry
    transform = np.asarray(g.transform, dtype=float) if g.transform is not None else None
    if g.polygon is not None:
        try:
            surface = polygon_surface([np.asarray(loop, dtype=float) for loop in g.polygon], scale=g.scale,
                                      transform=transform)
        except GeometryError as exc:
            # the CLI prints the message and the service files it under the field it starts with, as
            # load_surface's 'geometry.mesh:'; those naming geometry.scale or .transform keep theirs
            if not str(exc).startswith("geometry."):
                exc.args = (f"geometry.polygon: {exc}",)
            raise
        return surface, json.dumps(g.polygon).encode()
    data, name = read_mesh_input(spec, mesh, filename, base_dir)
    surface = load_surface(data, filename=name, dimension=spec.dimension, scale=g.scale, transform=transform)
    return surface, data


def prepare_geometry(
    spec: JobSpec,
    mesh: MeshInput = None,
    *,
    filename: str | None = None,
    base_dir: Path | None = None,
    progress: Progress = _quiet,
    cache: GeometryCache | None = None,
    limits: Limits = Limits(),
) -> Geometry:
    """Load and check the surface, build the grid, and compute the cut-cell geometry the method needs."""
    times: dict[str, float] = {}
    t = time.perf_counter()
    progress("geometry", 0.0, {})
    surface, identity = load_geometry(spec, mesh, filename=filename, base_dir=base_dir)
    if len(surface.faces) > limits.max_triangles:
        raise GeometryError(f"geometry.mesh: {len(surface.faces)} facets exceed the limit of {limits.max_triangles}")
    times["geometry"] = time.perf_counter() - t

    t = time.perf_counter()
    gs = spec.grid
    grid = make_grid(*surface.bounds, cell_size=gs.cell_size, resolution=gs.resolution, padding=gs.padding, max_cells=limits.max_cells)
    entry = method_entry(spec.method.kind)
    entry.check_dimension(spec.dimension)
    _check_memory(estimate_memory(grid, spec.method, surface, job=spec), limits, spec, grid, surface)
    entry.check_job(spec, grid)
    times["grid"] = time.perf_counter() - t
    progress("grid", 0.1, {"shape": list(grid.shape), "spacing": grid.spacing})

    t = time.perf_counter()
    cache = cache if cache is not None else GeometryCache(default_directory())
    params = {
        "dimension": spec.dimension,
        "geometry": spec.geometry.model_dump(mode="json", exclude={"mesh"}),
        "grid": grid.to_dict(),
    }
    geo = compute_geometry(entry.kind, surface, grid, cache=cache, identity=identity, params=params)
    if geo.cut_cells is not None:  # cells holding several pieces hold several elements: the count, not the bound
        need = entry.estimate_memory(grid, spec.method, occupied=geo.cut_cells.num_pieces)
        _check_memory(need + held_steps_bytes(spec, grid, surface), limits, spec, grid, surface)
    times["cut_cells"] = time.perf_counter() - t
    geo.stage_times = times
    progress("cut_cells", 0.3, {"cache_hit": geo.cache_hit})
    return geo


def compute_geometry(method_kind: str, surface: Surface, grid: Grid, *, cache: GeometryCache | None = None,
                     identity: bytes = b"", params: dict | None = None) -> Geometry:
    """The cut-cell geometry that method ``method_kind`` needs on ``grid``: from ``cache`` under the
    key of the mesh ``identity`` and the job's ``params`` when given, else computed (studies that
    pin their own grid)."""
    entry = method_entry(method_kind)
    cache_kind, compute = _GEOMETRY[entry.geometry]
    geo = Geometry(surface=surface, grid=grid, warnings=list(surface.warnings))
    if cache is None:
        value = compute(surface, grid)
    else:
        value, geo.cache_hit = cache.get_or_compute(cache_key(cache_kind, identity, params or {}),
                                                    lambda: compute(surface, grid))
    setattr(geo, entry.geometry, value)
    geo.warnings += list(value.warnings)
    return geo


def cell_fractions(geo: Geometry) -> np.ndarray:
    """Dense cell volume fractions [*grid.shape] for output, from whichever geometry was computed."""
    if geo.fractions is not None:
        return geo.fractions.dense()
    cut = geo.cut_cells
    out = np.zeros(geo.grid.shape)
    np.add.at(out, tuple(np.asarray(cut.piece_cell).T), np.asarray(cut.volume) / geo.grid.spacing**3)
    return out


def geometry_result(spec_dict: dict, geo: Geometry, method: str) -> Result:
    """A result holding only geometry: cell fractions and the reference surface (no fields)."""
    surface = geo.surface
    return Result(
        grid=geo.grid,
        method=method,
        spec=spec_dict,
        volume_fraction=cell_fractions(geo),
        fields=FieldData(),
        surface_vertices=surface.vertices,
        surface_faces=surface.faces,
        solver=SolverReport(iterations=0, residual=0.0, stage_times=geo.stage_times, warnings=geo.warnings),
    )


@dataclass
class Functions:
    """Python-API callables for manufactured solutions (all take points [N, d] [m]).

    body_force -> [N, d] [N/m^3] replaces loads.gravity; displacement[name] -> [N, d] [m] and
    traction[name] -> [N, d] [Pa] replace the value of the boundary with that name; stress[name] ->
    [N, d, d] [Pa] makes a traction boundary apply sigma n, on the surface triangles (stress_form
    "quadrature") or as the volume form of thesis eq. 4.16 ("divergence"); regions[name] -> bool [N] replaces that
    boundary's region (membership of DOF samples; a surface facet counts when its centroid does).
    """

    body_force: Callable | None = None
    displacement: dict[str, Callable] = field(default_factory=dict)
    traction: dict[str, Callable] = field(default_factory=dict)
    stress: dict[str, Callable] = field(default_factory=dict)
    regions: dict[str, Callable] = field(default_factory=dict)
    # how a stress field becomes loads: "divergence" (thesis eq. 4.16, the operator's own weights) or
    # "quadrature" (sigma n on the surface); the divergence form converges faster on the annulus and
    # the ball (docs/benchmarks.md, "Boundaries on the surface patch")
    stress_form: str = "divergence"
    pressure_form: str = "divergence"  # how a pressure becomes loads (sigma = -p I in the divergence form)

    def __post_init__(self) -> None:
        for name in ("stress_form", "pressure_form"):  # anything else used to mean "quadrature" silently
            if getattr(self, name) not in ("divergence", "quadrature"):
                raise BoundaryError(f"functions.{name}: 'divergence' or 'quadrature', got {getattr(self, name)!r}")
        for name in ("displacement", "traction", "stress", "regions"):
            if not isinstance(getattr(self, name), Mapping):
                raise BoundaryError(f"functions.{name}: a dict of boundary name -> function, got "
                                    f"{type(getattr(self, name)).__name__}")


def check_boundaries(spec: JobSpec, surface: Surface) -> list[str]:
    """What ``run`` refuses about the boundaries, found without a grid or a solve (``voxelastic
    validate``, the service's admission): a region that holds no surface, two holds that disagree on
    a common patch (BoundaryError naming the boundaries); returns the holds' warnings."""
    from .boundary import check_holds, make_boundaries, select_patch
    from .material import Material

    b = make_boundaries(spec, Functions(), Material.from_spec(spec.material))
    facets = surface.vertices[surface.faces]
    for bc in [*b.prescribed, *b.loads]:
        select_patch(bc.region, facets, bc.name)
    return check_holds(b.prescribed, surface)


def run(
    spec: JobSpec | dict | str | bytes,
    mesh: MeshInput = None,
    *,
    filename: str | None = None,
    base_dir: Path | None = None,
    progress: Progress = _quiet,
    cache: GeometryCache | None = None,
    limits: Limits = Limits(),
    functions: Functions | None = None,
) -> Result:
    """Run a job end to end. ``mesh``: bytes (with ``filename``) or a path; default geometry.mesh."""
    if not isinstance(spec, JobSpec):
        spec = parse_job(spec)
    from .runtime import init

    init(spec.solver.arch, spec.solver.precision)
    geo = prepare_geometry(spec, mesh, filename=filename, base_dir=base_dir, progress=progress, cache=cache, limits=limits)
    from .analysis import run_analysis

    times = dict(geo.stage_times)
    warnings = geo.warnings
    method = None
    try:
        t = time.perf_counter()
        progress("discretization", 0.32, {})

        def setup(part: str, share: float) -> None:
            progress("discretization", 0.32 + 0.08 * min(max(share, 0.0), 1.0), {"part": part})

        if functions is not None and not isinstance(functions, Functions):
            raise BoundaryError(f"functions: an engine.pipeline.Functions, got {type(functions).__name__}")
        method = _discretize(spec, geo, functions or Functions(), setup)
        times["discretization"] = time.perf_counter() - t
        # The method keeps what it needs of the geometry; the result takes the cell fractions now and
        # the rest goes before the solve (for the staggered method: its face and edge fractions)
        result = geometry_result(spec.model_dump(mode="json"), geo, spec.method.kind)
        probes = np.asarray(spec.output.probes, dtype=float) if spec.output.probes else None
        inside = None if probes is None else in_solid(geo.surface, probes, geo.grid.spacing)
        del geo
        t = time.perf_counter()
        outcome = run_analysis(method, spec.analysis, sampled_output(spec.output, inside), progress)
    except VoxelasticError as exc:
        # what loading and setup noticed often explains the failure (an inverted mesh, bodies the
        # grid joins): the CLI prints it with the error
        exc.warnings = list(warnings) + list(getattr(method, "warnings", []))
        raise
    times["solve"] = time.perf_counter() - t
    result.fields, result.steps = outcome.final, outcome.steps
    result.probe_points = probes
    if inside is not None and not inside.all():
        spread_probes([result.fields, *result.steps], inside, spec.dimension)
    if not spec.output.surface:
        result.surface_vertices = result.surface_faces = None
    result.solver = SolverReport(
        iterations=outcome.iterations,
        residual=outcome.residual,
        stage_times=times,
        warnings=warnings + method.warnings,
    )
    progress("done", 1.0, {"iterations": outcome.iterations, "residual": outcome.residual})
    return result


def sampled_output(output: OutputSpec, inside: np.ndarray | None) -> OutputSpec:
    """``output`` with only the probes ``inside`` [P] bool the solid: a method is not asked for
    values where there is nothing to sample (a probe at 1e308 m overflowed the staggered method's
    strain fit into an exception); :func:`spread_probes` gives the others NaN."""
    if inside is None or inside.all():
        return output
    return output.model_copy(update={"probes": [p for p, keep in zip(output.probes, inside) if keep]})


def spread_probes(levels: list[FieldData], inside: np.ndarray, dimension: int) -> None:
    """Every probe's values in each of ``levels``, from those the method gave at the probes
    ``inside`` [P] bool: NaN at the probes outside the solid, which have no value to report. Each
    field's components are those of its cell values ([*grid.shape, *c] -> [P, *c]), which are there
    even when no probe is inside. Levels that share their probe values (the final state of a stepped
    analysis is its last step) are spread once."""
    for level in {id(level.probes): level for level in levels}.values():
        for name, cells in level.cells.items():
            values = np.full((len(inside), *np.shape(cells)[dimension:]), np.nan)
            if name in level.probes:
                values[inside] = level.probes[name]
            level.probes[name] = values


def _discretize(spec: JobSpec, geo: Geometry, functions: Functions, progress: Setup | None = None) -> Method:
    return method_entry(spec.method.kind).build(spec, geo, functions, progress)


def _slice_cells(surface: Surface, grid: Grid):
    from .geometry.slicing import slice_cells  # only the methods on cut cells load the slicer

    if not surface.closed:  # the slicer's own error named no field and no way out
        why = next((w.split(":", 1)[1].split(";")[0].strip() for w in surface.warnings
                    if w.startswith("the surface is not closed:")), "it has holes")
        raise GeometryError(
            f"geometry.mesh: the surface is not closed ({why}); the DG method cuts cells into pieces of a closed solid: "
            "close the mesh in a modelling program, or use method.kind 'staggered', which reads an open surface by its "
            "generalized winding number")
    return slice_cells(surface, grid)


# the cut-cell geometries a method may ask for (engine.method.MethodEntry.geometry): the cache's
# name for each and how it is computed; the result goes to the Geometry attribute of that name
_GEOMETRY: dict[str, tuple[str, Callable]] = {
    "fractions": ("fractions", volume_fractions),
    "cut_cells": ("slicing", _slice_cells),
}
