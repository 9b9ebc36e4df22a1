"""Checks of a submission before anything is queued: spec, mesh, triangles, grid, memory.

Everything that can be known without solving is checked here so that a bad job gets its 422 at
once instead of a failure minutes later: the spec (field paths from ``schemas.parse_job``), the
mesh (read and validated by the engine's own loader), the facet count, the grid size and the
engine's memory estimate for that grid. Errors use FastAPI's shape, ``{"loc", "msg", "type"}``,
so every 422 of the API reads the same.

:func:`admit` is what the API calls: it runs :func:`check_submission` in a short-lived child
process (``service.sandbox``) with an address-space and a time limit, so that no spec or mesh,
however it inflates, can grow the API process. Messages never carry an exception's own text:
they say which field or file is wrong and why, in words.
"""

from __future__ import annotations

import logging
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from schemas import SpecError, parse_job

from .settings import Settings
from .storage import display_name, mesh_suffix

log = logging.getLogger("voxelastic.admission")


@dataclass
class Admitted:
    """A submission that passed every check (plain values: it crosses a process boundary)."""

    spec_json: str  # canonical JSON (defaults filled in)
    suffix: str  # the stored mesh's suffix ('' for a polygon job)
    triangles: int
    grid_shape: tuple[int, ...]
    memory_estimate: int
    mesh_field: str | None  # geometry.mesh of the spec
    precision: str
    arch: str


class Rejected(Exception):
    """A submission refused with ``status_code`` and FastAPI-style error entries."""

    expected = True  # bad input, not a fault of the service: nothing to log

    def __init__(self, status_code: int, errors: list[dict[str, Any]]):
        errors = capped_errors(errors)
        super().__init__("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in errors))
        self.status_code, self.errors = status_code, errors

    def __reduce__(self):  # pickled by the admission child: rebuild from the fields, not the message
        return (Rejected, (self.status_code, self.errors))


MAX_ERRORS = 50  # a spec with 100,000 bad coordinates made an 11 MB answer; the first ones show the pattern


def capped_errors(errors: list[dict[str, Any]], limit: int = MAX_ERRORS) -> list[dict[str, Any]]:
    """The first ``limit`` error entries, then one saying how many more were found."""
    if len(errors) <= limit or (len(errors) == limit + 1 and errors[-1].get("type") == "too_many_errors"):
        return errors  # (capped already: a Rejected is rebuilt from its entries when it leaves the child)
    more = len(errors) - limit
    return [*errors[:limit], _error(["body"], f"{more} more error{'s' if more > 1 else ''} not listed "
                                    f"({len(errors)} in all; the first {limit} are shown)", "too_many_errors")]


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


def parse_spec(spec_text: str | bytes):
    """The validated spec, or :class:`Rejected` naming the problem (never a raw exception)."""
    if not (spec_text.strip() if isinstance(spec_text, (str, bytes)) else spec_text):
        raise Rejected(422, [_error(["body", "spec"], "the spec is empty: send the job spec as JSON in the 'spec' "
                                    "form field or file part", "missing")])
    try:
        return parse_job(spec_text)
    except SpecError as exc:
        raise Rejected(422, spec_errors(exc)) from None


_LOOP = re.compile(r"^polygon '[^']*': loop (\d+) ")


def _engine_error(message: str, source: list | None = None) -> dict[str, Any]:
    """An engine error message ('field.path: reason') as an error entry at that field.

    ``source``: where the geometry came from (``["body", "mesh"]``, or the spec's polygon), which
    gets the messages that name no field.
    """
    source = source or ["body", "mesh"]
    path, reason = _split_path(message)
    if path[:2] == ["geometry", "mesh"] or not path:
        return _error(source, message)
    if path == ["geometry", "polygon"]:  # a fault of one loop is filed at that loop, geometry.polygon.<i>
        loop = _LOOP.match(reason)
        return _error(["body", "spec", *path, *([int(loop.group(1))] if loop else [])], reason)
    return _error(["body", "spec", *path], reason)


def _boundary_error(message: str, spec) -> dict[str, Any]:
    """A boundary check's error at ``boundaries.<i>`` of the boundary it begins with (its ``name``, or
    ``boundaries.<i>`` when it has none), or at ``boundaries`` for one about several ('clamp and pull:
    both prescribe u_x ...'); the message keeps the name."""
    head = message.partition(": ")[0]
    index: dict[str, int] = {}
    for i, b in enumerate(spec.boundaries):
        index.setdefault(b.name or f"boundaries.{i}", i)
    return _error(["body", "spec", "boundaries", *([index[head]] if head in index else [])], message)


def check_submission(spec_text: str | bytes, mesh: bytes | None, mesh_filename: str | None, settings: Settings) -> Admitted:
    """Validate a submission; raise :class:`Rejected` (422, 413) naming every problem found.

    Runs the engine's geometry loading (no Taichi) in this process: the API calls :func:`admit`,
    which runs this in a child process with memory and time limits.
    """
    from engine.errors import VoxelasticError
    from engine.geometry.inflate import ExtendedHeaderTooLarge, InflateLimitError
    from engine.devices import check_arch
    from engine.geometry.loading import load_surface
    from engine.grid import make_grid
    from engine.method import method_entry
    from engine.pipeline import check_boundaries, estimate_memory, load_geometry, memory_refusal

    spec = parse_spec(spec_text)
    try:
        method_entry(spec.method.kind).check_dimension(spec.dimension)
        check_arch(spec.solver.arch)
    except VoxelasticError as exc:
        raise Rejected(422, [_engine_error(str(exc))]) from None

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

    # bytes, never a path: the loader then reads no sibling files; the name is for messages
    name = display_name(mesh_filename or spec.geometry.mesh, suffix)
    try:
        if uses_mesh:
            g = spec.geometry
            surface = load_surface(mesh, filename=name, dimension=spec.dimension, scale=g.scale,
                                   transform=g.transform, max_inflated_bytes=int(settings.max_inflated_bytes))
        else:
            surface, _ = load_geometry(spec, None)
    except InflateLimitError as exc:
        setting = "" if isinstance(exc, ExtendedHeaderTooLarge) else " (VOXELASTIC_MAX_INFLATED_BYTES)"
        raise Rejected(413, [_error(["body", "mesh"], f"{exc}{setting}", "too_large")]) from None
    except VoxelasticError as exc:
        source = ["body", "mesh"] if uses_mesh else ["body", "spec", "geometry", "polygon"]
        raise Rejected(422, [_engine_error(str(exc), source)]) from None
    except (MemoryError, RecursionError):
        raise
    except Exception:  # a loader crash on hostile bytes is still bad input, not a 500
        log.warning("reading %s failed", name, exc_info=True)
        what = f"'{name}'" if uses_mesh else "geometry.polygon"
        raise Rejected(422, [_error(["body", "mesh"] if uses_mesh else ["body", "spec", "geometry", "polygon"],
                                    f"cannot read {what}: it is damaged or not valid")]) from None
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
    try:  # the method's own limits: the values its solve precision holds
        method_entry(spec.method.kind).check_job(spec, grid)
    except VoxelasticError as exc:
        raise Rejected(422, [_engine_error(str(exc))]) from None
    need = estimate_memory(grid, spec.method, surface, job=spec)
    limit = int(settings.max_job_memory_bytes)
    refused = memory_refusal(need, limit, spec, grid, surface)
    if refused is not None:
        where, what, advice = refused
        raise Rejected(422, [_error(["body", "spec", *where], f"{what}, over this server's limit of "
                                    f"{limit / 2**30:.2f} GiB per job (VOXELASTIC_MAX_JOB_MEMORY_BYTES); {advice}")])
    try:  # as `voxelastic validate`: a region holding no surface used to be a 202 and a failed job
        check_boundaries(spec, surface)
    except VoxelasticError as exc:
        raise Rejected(422, [_boundary_error(str(exc), spec)]) from None
    return Admitted(spec_json=spec.to_json(), suffix=suffix, triangles=triangles, grid_shape=tuple(grid.shape),
                    memory_estimate=need, mesh_field=spec.geometry.mesh, precision=spec.solver.precision,
                    arch=spec.solver.arch)


def _check_files(spec_path: str, mesh_path: str | None, mesh_filename: str | None, settings: Settings) -> Admitted:
    """:func:`check_submission` on the submission's files (run in the admission child)."""
    spec_text = Path(spec_path).read_bytes()
    mesh = Path(mesh_path).read_bytes() if mesh_path is not None else None
    return check_submission(spec_text, mesh, mesh_filename, settings)


def admit(spec_text: str | bytes, mesh: bytes | None, mesh_filename: str | None, settings: Settings) -> Admitted:
    """:func:`check_submission` in a child process limited to ``admission_memory_bytes`` of address
    space and ``admission_time_limit`` seconds; raises :class:`Rejected` for everything it refuses."""
    from .sandbox import SandboxBusy, SandboxCrashed, SandboxMemory, SandboxTimeout, run_limited

    scratch = Path(settings.data_dir) / "admission"
    scratch.mkdir(parents=True, exist_ok=True)
    # the child reads files, not pickled arguments: no second copy of the upload in this process
    with tempfile.TemporaryDirectory(dir=scratch) as tmp:
        spec_path = os.path.join(tmp, "spec.json")
        with open(spec_path, "wb") as f:
            f.write(spec_text.encode("utf-8", "surrogatepass") if isinstance(spec_text, str) else spec_text)
        mesh_path = None
        if mesh is not None:
            mesh_path = os.path.join(tmp, "mesh")
            with open(mesh_path, "wb") as f:
                f.write(mesh)
        try:
            return run_limited(_check_files, (spec_path, mesh_path, mesh_filename, settings),
                               memory_bytes=settings.admission_memory_bytes, time_limit=settings.admission_time_limit)
        except SandboxMemory:
            raise Rejected(413, [_error(["body"], "reading the spec and the mesh needs more than "
                                        f"{settings.admission_memory_bytes / 2**30:.2f} GiB of memory, this server's "
                                        "limit (VOXELASTIC_ADMISSION_MEMORY_BYTES); send a smaller mesh", "too_large")]) from None
        except SandboxTimeout:
            raise Rejected(422, [_error(["body"], f"checking the spec and the mesh took longer than "
                                        f"{settings.admission_time_limit:g} s, this server's limit "
                                        "(VOXELASTIC_ADMISSION_TIME_LIMIT); send a smaller mesh", "too_slow")]) from None
        except SandboxCrashed as exc:
            log.warning("admission check of %s died: %s", mesh_filename, exc.detail)
            raise Rejected(422, [_error(["body", "mesh"], "the mesh could not be read: its reader stopped "
                                        "(a damaged file, or one too large to read within this server's limits)")]) from None
        except (Rejected, SandboxBusy):  # SandboxBusy: the server's load, not the input (503)
            raise
        except Exception:  # noqa: BLE001 - whatever the input made the check raise, it is still a 4xx
            log.exception("admission check of %s raised", mesh_filename)
            raise Rejected(422, [_error(["body"], "the spec and the mesh could not be checked: one of them is "
                                        "malformed in a way this server cannot name")]) from None
