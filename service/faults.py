"""Storage faults in words: a full disk, a file-size limit, a quota or a permission, named.

A write that fails for one of these reasons is not a bug and not a problem of the job's input:
the job ends ``failed`` with ``error_kind = "storage"`` and a message naming the cause (never a
retry: the next attempt would hit the same wall), and a request whose upload cannot be stored
is answered 507 Insufficient Storage instead of "400 There was an error parsing the body".
Paths are left out of the messages: they describe the server, not the user's job.
"""

from __future__ import annotations

import errno
import resource
import shutil
from collections.abc import Awaitable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # worker processes import this module too: they need no web framework
    from fastapi import FastAPI

ERROR_KIND = "storage"
STATUS = 507  # Insufficient Storage (RFC 4918): the server cannot store what the request needs

# the causes a retry cannot fix; anything else (EIO, ...) is reported as it comes
_CAUSES = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "the disk quota is exhausted",
    errno.EFBIG: "the file-size limit",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.EROFS: "the file system is read-only",
}


def is_storage_fault(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno in _CAUSES


def file_size_limit() -> int | None:
    """This process's RLIMIT_FSIZE [bytes], None when unlimited."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def describe(exc: OSError, what: str) -> str:
    """``what`` could not be written, and why, e.g. "the result could not be written: no space left
    on the device (errno ENOSPC)"."""
    code = exc.errno
    if code == errno.EFBIG:
        limit = file_size_limit()
        cause = (f"it exceeds the file-size limit of the server's process (RLIMIT_FSIZE = {limit} bytes)"
                 if limit is not None else "it exceeds the largest file the file system allows")
    elif code in _CAUSES:
        cause = _CAUSES[code]
    else:
        cause = exc.strerror or type(exc).__name__
    name = errno.errorcode.get(code, "") if code is not None else ""
    return f"{what} could not be written: {cause}" + (f" (errno {name})" if name else "")


def _storage_cause(exc: BaseException) -> OSError | None:
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if is_storage_fault(cur):
            return cur  # type: ignore[return-value]
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return None


def install(app: FastAPI) -> None:
    """Answer 507 with the cause when parsing a request failed because its body could not be
    stored (Starlette spools uploads over 1 MB to a temporary file: under a file-size limit or
    on a full disk FastAPI turns that OSError into "400 There was an error parsing the body").

    Other HTTP errors go on to whatever handler the app had (its own, or FastAPI's default).
    """
    from fastapi import Request
    from fastapi.exception_handlers import http_exception_handler
    from fastapi.responses import JSONResponse, Response
    from starlette.exceptions import HTTPException as StarletteHTTPException

    previous = app.exception_handlers.get(StarletteHTTPException, http_exception_handler)

    async def handler(request: Request, exc: Exception) -> Response:
        cause = _storage_cause(exc)
        if isinstance(exc, StarletteHTTPException) and exc.status_code == 400 and cause is not None:
            return JSONResponse({"detail": describe(cause, "the upload") + "; the server cannot take a request "
                                 "of this size now (a smaller mesh, or compressed, may fit)"}, status_code=STATUS)
        out = previous(request, exc)
        return await out if isinstance(out, Awaitable) else out

    app.add_exception_handler(StarletteHTTPException, handler)


def result_estimate(spec_json: str, grid_shape: tuple[int, ...], triangles: int) -> int:
    """Upper bound of a job's result file [bytes] from its canonical spec (see
    ``engine.output.estimate_result_bytes``)."""
    import json

    from engine.output import estimate_result_bytes

    spec = json.loads(spec_json)
    analysis = spec.get("analysis", {})
    output = spec.get("output", {})
    # the steps the result keeps (schemas.JobSpec.kept_steps)
    steps = -(-int(analysis.get("steps", 0)) // int(output.get("every", 1))) if analysis.get("kind") != "static" else 0
    # a closed triangle mesh has about half as many vertices as facets
    vertices = triangles // 2 + 3 if output.get("surface", True) else 0
    return estimate_result_bytes(grid_shape, output.get("fields", []), levels=steps + 1,
                                 surface_vertices=vertices, probes=len(output.get("probes", [])))


def check_space(root: str | Path, need: int, what: str, sized_by: tuple[str, ...] = ("grid",)) -> None:
    """Refuse when the file system of ``root`` cannot take ``need`` bytes: 422 naming the spec fields
    ``sized_by`` (dotted paths, the first one carries the error) when the need is over the disk's
    whole size, which no wait can change; 507 when it is only over the space free now (better
    than after the solve, when the result cannot be written). Raises ``admission.Rejected``."""
    from .admission import Rejected

    usage = shutil.disk_usage(root)
    if need > usage.total:
        fields = " and ".join(sized_by)
        raise Rejected(422, [{"loc": ["body", "spec", *_path(sized_by[0])], "type": "value_error",
                              "msg": f"{what} needs up to {_size(need)}, more than the whole disk this server keeps "
                                     f"results on ({_size(usage.total)}); its size is set by {fields}: lower "
                                     "them (or output fewer fields)"}])
    if usage.free < need:
        raise Rejected(STATUS, [{"loc": ["body", "spec", *_path(sized_by[0])], "type": "insufficient_storage",
                                 "msg": f"the server has {_size(usage.free)} free for results, {what} needs up to "
                                        f"{_size(need)}; retry later or use a coarser grid or fewer fields"}])


def _path(dotted: str) -> list:
    return [int(p) if p.isdigit() else p for p in dotted.split(".")]


def result_size_fields(spec_json: str) -> tuple[str, ...]:
    """The spec fields that set a job's result size, the one most likely to be the culprit first."""
    import json

    analysis = json.loads(spec_json).get("analysis", {})
    steps = ("analysis.steps",) if analysis.get("kind") != "static" and int(analysis.get("steps", 0)) > 0 else ()
    return (*steps, "grid", "output.fields")


def rejection(exc: OSError, what: str):
    """A 507 ``admission.Rejected`` for an upload that could not be stored."""
    from .admission import Rejected

    return Rejected(STATUS, [{"loc": ["body", "mesh"], "type": "insufficient_storage", "msg": describe(exc, what)}])


def _size(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover - the loop returns at GiB
