"""Checks of a submission before anything is queued: spec, mesh, triangles, grid, memory.

Everything that can be known without solving is checked here so that a bad job gets its 422 at
once instead of a failure minutes later: the spec (field paths from ``schemas.parse_job``), the
mesh (read and validated by the engine's own loader), the facet count, the grid size and the
engine's memory estimate for that grid. Errors use FastAPI's shape, ``{"loc", "msg", "type"}``,
so every 422 of the API reads the same.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from schemas import JobSpec, SpecError, parse_job

from .settings import Settings
from .storage import display_name, mesh_suffix


@dataclass
class Admitted:
    """A submission that passed every check."""

    spec: JobSpec
    spec_json: str  # canonical JSON (defaults filled in)
    suffix: str  # the stored mesh's suffix ('' for a polygon job)
    triangles: int
    grid_shape: tuple[int, ...]
    memory_estimate: int


class Rejected(Exception):
    """A submission refused with ``status_code`` and FastAPI-style error entries."""

    def __init__(self, status_code: int, errors: list[dict[str, Any]]):
        super().__init__("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in errors))
        self.status_code, self.errors = status_code, errors


def _error(loc: list, msg: str, kind: str = "value_error") -> dict[str, Any]:
    return {"loc": loc, "msg": msg, "type": kind}


_PATH = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)*): (.*)$", re.S)


def _split_path(line: str) -> tuple[list, str]:
    """'boundaries.0.value: reason' -> (['boundaries', 0, 'value'], 'reason')."""
    m = _PATH.match(line)
    if not m:
        # '(json): ...' and '(root): ...' concern the document as a whole
        head, sep, rest = line.partition(": ")
        return ([], rest) if sep and head.startswith("(") else ([], line)
    parts = [int(p) if p.isdigit() else p for p in m.group(1).split(".")]
    return parts, m.group(2)


def spec_errors(exc: SpecError) -> list[dict[str, Any]]:
    out = []
    for line in exc.errors:
        path, reason = _split_path(line)
        out.append(_error(["body", "spec", *path], reason, "json_invalid" if line.startswith("(json)") else "value_error"))
    return out


def _engine_error(message: str) -> dict[str, Any]:
    """An engine error message ('field.path: reason') as an error entry at that field."""
    path, reason = _split_path(message)
    if path[:2] == ["geometry", "mesh"] or not path:
        return _error(["body", "mesh"], message)
    return _error(["body", "spec", *path], reason)


def check_submission(spec_text: str | bytes, mesh: bytes | None, mesh_filename: str | None, settings: Settings) -> Admitted:
    """Validate a submission; raise :class:`Rejected` (422) naming every problem found.

    Runs the engine's geometry loading (no Taichi): call it off the event loop.
    """
    from engine.errors import VoxelasticError
    from engine.grid import make_grid
    from engine.pipeline import estimate_memory, load_geometry

    try:
        spec = parse_job(spec_text)
    except SpecError as exc:
        raise Rejected(422, spec_errors(exc)) from None

    uses_mesh = spec.geometry.mesh is not None
    suffix = ""
    if uses_mesh:
        if mesh is None:
            raise Rejected(422, [_error(["body", "mesh"], "required: geometry.mesh names a file; upload it as the 'mesh' part", "missing")])
        if len(mesh) == 0:
            raise Rejected(422, [_error(["body", "mesh"], "the uploaded mesh file is empty")])
        suffix = mesh_suffix(mesh_filename) or mesh_suffix(spec.geometry.mesh)
        if not suffix:
            raise Rejected(422, [_error(["body", "mesh"], "cannot tell the mesh format: neither the uploaded file's name "
                                        f"({mesh_filename!r}) nor geometry.mesh has a suffix such as .stl")])
    elif mesh:
        raise Rejected(422, [_error(["body", "mesh"], "this spec defines geometry.polygon; do not upload a mesh")])

    try:
        # bytes, never a path: the loader then reads no sibling files; the name is for messages
        name = display_name(mesh_filename or spec.geometry.mesh, suffix)
        surface, _ = load_geometry(spec, mesh if uses_mesh else None, filename=name)
    except VoxelasticError as exc:
        raise Rejected(422, [_engine_error(str(exc))]) from None
    except Exception as exc:  # a loader crash on hostile bytes is still bad input, not a 500
        raise Rejected(422, [_error(["body", "mesh"], f"cannot read the mesh: {type(exc).__name__}: {exc}")]) from None
    triangles = len(surface.faces)
    if triangles > settings.max_triangles:
        raise Rejected(422, [_error(["body", "mesh"], f"{triangles} facets exceed the limit of {settings.max_triangles} "
                                    "(VOXELASTIC_MAX_TRIANGLES)")])
    g = spec.grid
    try:
        grid = make_grid(*surface.bounds, cell_size=g.cell_size, resolution=g.resolution, padding=g.padding,
                         max_cells=settings.max_cells)
    except VoxelasticError as exc:
        raise Rejected(422, [_engine_error(str(exc))]) from None
    need = estimate_memory(grid, spec.method.kind, getattr(spec.method, "degree", 1))
    limit = int(settings.max_job_memory_bytes)
    if need > limit:
        shape = "x".join(map(str, grid.shape))
        raise Rejected(422, [_error(["body", "spec", "grid"],
                                    f"a {shape} grid needs about {need / 2**30:.2f} GiB for method '{spec.method.kind}', "
                                    f"over this server's limit of {limit / 2**30:.2f} GiB per job; "
                                    "increase grid.cell_size or lower grid.resolution")])
    return Admitted(spec=spec, spec_json=spec.to_json(), suffix=suffix, triangles=triangles,
                    grid_shape=tuple(grid.shape), memory_estimate=need)
