"""The job resource: submit, inspect, follow, download, cancel/delete. Handlers stay thin."""

from __future__ import annotations

import json
import re
from typing import Annotated

from fastapi import APIRouter, Depends, File, Form, Header, HTTPException, Query, Request, Response, UploadFile, status
from fastapi.responses import FileResponse, StreamingResponse
from starlette.datastructures import Headers
from starlette.types import Receive, Scope, Send

from ...admission import Rejected
from ...sandbox import SandboxBusy
from ...jobs import QueueFull, QueueUnavailable, Submitted, cancel_or_delete, submit
from ...queue import Queue
from ...settings import Settings
from ...storage import Storage
from ...store import IdempotencyConflict, JobStatus, JobStore
from ..deps import JobBriefDep, JobDep, Principal, PrincipalDep, QueueDep, SettingsDep, StorageDep, StoreDep
from ..events import job_events, last_seen
from ..models import JobOut, JobPage, job_json, job_out, output_surface
from ..preview import RenderFailed

router = APIRouter(prefix="/jobs", tags=["jobs"])

HDF5_TYPE = "application/x-hdf5"
LIST_SPECS = 4  # a list page holds at most this many largest specs' bytes of specs (at least one job)
XDMF_TYPE = "application/xml"

_ERRORS = {
    401: {"description": "Missing or invalid bearer token (when tokens are configured)."},
    404: {"description": "No such job."},
}


async def _one_part_each(request: Request) -> None:
    """422 naming a form field sent more than once: the framework would silently take the last
    ``mesh`` or ``spec``, and which one the client meant cannot be told. (The form is the one
    FastAPI has parsed already: Starlette keeps it on the request.)"""
    form = await request.form()
    for name in ("spec", "mesh"):
        count = len(form.getlist(name))
        if count > 1:
            raise HTTPException(422, detail=[{
                "loc": ["body", name], "type": "duplicate",
                "msg": f"the form has {count} '{name}' parts; send exactly one (which one was meant cannot be told)"}])


@router.post(
    "",
    dependencies=[Depends(_one_part_each)],
    status_code=status.HTTP_202_ACCEPTED,
    response_model=JobOut,
    responses={
        **_ERRORS,
        409: {"description": "Idempotency-Key reused for a different submission."},
        413: {"description": "Request body over VOXELASTIC_MAX_UPLOAD_BYTES, a compressed mesh inflating past "
                             "VOXELASTIC_MAX_INFLATED_BYTES, or reading it past VOXELASTIC_ADMISSION_MEMORY_BYTES."},
        422: {"description": "Invalid spec or mesh, too many facets, grid over the memory limit, a form field sent "
                             "twice (field path + reason)."},
        429: {"description": "Queue full; see Retry-After."},
        503: {"description": "The job queue (broker) or the job table is unavailable, or too many submissions "
                             "are being checked; see Retry-After."},
    },
    summary="Submit a job (multipart: spec JSON + mesh file)",
)
def create_job(
    response: Response,
    settings: SettingsDep,
    store: StoreDep,
    storage: StorageDep,
    queue: QueueDep,
    principal: PrincipalDep,
    spec: Annotated[
        UploadFile | str, Form(description="The job spec as JSON (a text field or a file part; schemas/json/job.schema.json).")
    ],
    mesh: Annotated[UploadFile | None, File(description="The surface mesh; its file name's suffix tells the format.")] = None,
    idempotency_key: Annotated[
        str | None, Header(min_length=1, max_length=255, description="Repeat-safe submission: same key, same job.")
    ] = None,
) -> JobOut:
    outcome = _submit(settings, store, storage, queue, principal, spec, mesh, idempotency_key)
    if isinstance(outcome, HTTPException):
        # raised here, after the frames that held the upload have returned: an exception keeps its
        # traceback's frames and their locals, and the framework's handling of it makes reference
        # cycles that only the garbage collector frees (60 MB a rejected upload until it ran)
        raise outcome
    response.headers["Location"] = f"/jobs/{outcome.job.id}"
    if not outcome.created:
        response.headers["Idempotent-Replayed"] = "true"
    return job_out(outcome.job)


def _submit(settings: Settings, store: JobStore, storage: Storage, queue: Queue, principal: Principal,
            spec: UploadFile | str, mesh: UploadFile | None, idempotency_key: str | None) -> Submitted | HTTPException:
    """:func:`service.jobs.submit` on the upload; a refusal is returned, not raised (see create_job)."""
    spec_text = _spec_text(spec, settings.max_spec_bytes)
    if isinstance(spec_text, HTTPException):
        return spec_text
    data = mesh.file.read() if mesh is not None else None
    try:
        return submit(store, storage, queue, settings, spec_text=spec_text, mesh=data,
                      mesh_filename=mesh.filename if mesh is not None else None, idempotency_key=idempotency_key,
                      owner=principal.owner)
    except Rejected as exc:
        return HTTPException(exc.status_code, detail=exc.errors)
    except IdempotencyConflict as exc:
        return HTTPException(status.HTTP_409_CONFLICT, detail=str(exc))
    except QueueFull as exc:
        return HTTPException(status.HTTP_429_TOO_MANY_REQUESTS, detail=str(exc),
                             headers={"Retry-After": str(exc.retry_after)})
    except QueueUnavailable as exc:
        return HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=str(exc),
                             headers={"Retry-After": str(exc.retry_after)})
    except SandboxBusy as exc:
        return HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, headers={"Retry-After": str(exc.retry_after)},
                             detail=f"the server is busy checking other submissions (no check slot came free in "
                                    f"{exc.waited:g} s); nothing was stored: submit again in {exc.retry_after} s")


def _spec_text(spec: UploadFile | str, limit: int) -> str | bytes | HTTPException:
    """The spec's text, or 413 naming ``spec`` when it is over ``limit`` bytes. Read no further than
    that: every status poll returns the stored spec, so its size is what each poll costs."""
    text = spec if isinstance(spec, str) else spec.file.read(limit + 1)
    size = len(text.encode("utf-8", "surrogatepass")) if isinstance(text, str) else len(text)
    if size > limit:
        return HTTPException(status.HTTP_413_REQUEST_ENTITY_TOO_LARGE, detail=[{
            "loc": ["body", "spec"], "type": "too_large",
            "msg": f"the spec is over {limit} bytes ({limit / 2**20:g} MiB), this server's limit for a job spec "
                   "(VOXELASTIC_MAX_SPEC_BYTES); a spec this large is mostly probes or polygon points: "
                   "use fewer, or a mesh file for the geometry"}])
    return text


@router.get("", response_model=JobPage, responses={401: _ERRORS[401]}, summary="List jobs, newest first")
def list_jobs(
    request: Request,
    store: StoreDep,
    principal: PrincipalDep,
    settings: SettingsDep,
    limit: Annotated[int, Query(ge=1, le=200)] = 50,
    offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
    status_: Annotated[JobStatus | None, Query(alias="status")] = None,
) -> Response:
    items, total = store.list(limit=limit, offset=offset, status=status_.value if status_ else None,
                              owner=principal.owner, everyone=principal.everyone)
    # Each item carries its spec (up to max_spec_bytes): a page of 200 big ones would be 800 MB
    # built in the API's memory, so a page ends early past LIST_SPECS specs' worth and `next` goes on
    kept, size = [], 0
    for job in items:
        size += len(job.spec or "")
        if kept and size > LIST_SPECS * settings.max_spec_bytes:
            break
        kept.append(job)
    nxt = None
    if offset + len(kept) < total:
        # path and query only: the Host header is the client's to choose, so an absolute link built
        # from it could point anywhere (Host: evil.example)
        url = request.url.include_query_params(offset=offset + len(kept), limit=limit)
        nxt = f"{url.path}?{url.query}"
    # the stored specs are spliced in as they are (job_json), not parsed and encoded again
    rest = JobPage(items=[], total=total, limit=limit, offset=offset, next=nxt).model_dump_json(exclude={"items"})
    return Response(f'{{"items":[{",".join(job_json(j) for j in kept)}],{rest[1:]}', media_type="application/json")


@router.get("/{job_id}", response_model=JobOut, responses=_ERRORS, summary="Status, progress, timings, result links")
async def get_job(job: JobDep) -> Response:
    # async, like its dependencies: a poll never waits for the shared thread pool (service.api.reads)
    return Response(job_json(job), media_type="application/json")


@router.get(
    "/{job_id}/events",
    responses={**_ERRORS, 200: {"content": {"text/event-stream": {}}, "description": "Progress snapshots until the end."}},
    summary="Server-sent events of a job until it ends",
)
async def job_event_stream(
    request: Request,
    job: JobBriefDep,
    store: StoreDep,
    last_event_id: Annotated[
        str | None, Header(max_length=64, description="The id of the last event seen (a reconnecting client); "
                                                      "anything but a revision number is ignored.")
    ] = None,
) -> Response:
    if request.method == "HEAD":  # the headers alone; a stream would poll until the job ends, unread
        return Response(media_type="text/event-stream", headers={"Cache-Control": "no-cache"})
    return StreamingResponse(
        job_events(store, job.id, last_seen(last_event_id)),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


def _finished_file(job, path, media_type: str) -> FileResponse:
    if job.status != JobStatus.succeeded.value:
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            detail=f"job {job.id} is {job.status}; a result exists only once it has succeeded",
        )
    if not path.is_file():  # deleted between the status read and now
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"the result of job {job.id} is gone")
    return Download(path, media_type=media_type, filename=path.name)


_RANGE_SPEC = re.compile(r"\s*(?:(\d+)-(\d*)|-\d+)\s*")


def _valid_range(value: str) -> bool:
    """Whether a Range header is a byte-range set as RFC 7233 writes it, every last >= its first."""
    unit, eq, ranges = value.partition("=")
    if not eq or unit.strip().lower() != "bytes":
        return False
    for part in ranges.split(","):
        m = _RANGE_SPEC.fullmatch(part)
        if m is None or (m.group(1) is not None and m.group(2) and int(m.group(2)) < int(m.group(1))):
            return False
    return True


class Download(FileResponse):
    """A file with Range support, where a Range header that is not valid is ignored (RFC 7233 3.1:
    the whole file, 200) instead of Starlette's 400 "Malformed range header"; a valid one that the
    file cannot satisfy still gets 416."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        given = Headers(scope=scope).get("range")
        if given is not None and not _valid_range(given):
            scope = {**scope, "headers": [(k, v) for k, v in scope["headers"] if k.lower() != b"range"]}
        await super().__call__(scope, receive, send)


@router.get(
    "/{job_id}/result",
    response_class=FileResponse,
    responses={**_ERRORS, 200: {"content": {HDF5_TYPE: {}}, "description": "The HDF5 result file."},
               206: {"description": "Partial content (Range)."}, 409: {"description": "Not (successfully) finished."},
               416: {"description": "Range not satisfiable."}},
    summary="Download the HDF5 result (Range requests supported)",
)
def get_result(job: JobBriefDep, storage: StorageDep) -> FileResponse:
    return _finished_file(job, storage.result_path(job.id), HDF5_TYPE)


@router.get(
    "/{job_id}/result.xdmf",
    response_class=FileResponse,
    responses={**_ERRORS, 200: {"content": {XDMF_TYPE: {}}, "description": "XDMF sidecar (refers to <id>.h5)."},
               409: {"description": "Not (successfully) finished."}},
    summary="Download the XDMF sidecar of the result",
)
def get_result_xdmf(job: JobBriefDep, storage: StorageDep) -> FileResponse:
    return _finished_file(job, storage.xdmf_path(job.id), XDMF_TYPE)


VIEWER_FILES = {  # route suffix -> (media type, what it is)
    "result.vtkhdf": ("application/x-hdf5", "The solid as VTKHDF (PyVista, VTK, ParaView; time steps)."),
    "result.solid.xdmf": (XDMF_TYPE, "The solid as one XDMF grid / time series (meshio; refers to <id>.h5)."),
    "result.surface.xdmf": (XDMF_TYPE, "The refined surface as one XDMF grid / time series (refers to <id>.h5)."),
}


def _viewer_route(route: str, media_type: str, what: str) -> None:
    suffix = route.removeprefix("result")

    def handler(job: JobBriefDep, store: StoreDep, storage: StorageDep) -> FileResponse:
        path = storage.result_file(job.id, suffix)
        if (suffix == ".surface.xdmf" and job.status == JobStatus.succeeded.value and not path.is_file()
                and not output_surface(store.spec_of(job.id))):
            raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"job {job.id} wrote no surface file: its output "
                                "has no surface (output.surface is false)")
        return _finished_file(job, path, media_type)

    router.add_api_route(f"/{{job_id}}/{route}", handler, methods=["GET"], response_class=FileResponse,
                         responses={**_ERRORS, 200: {"content": {media_type: {}}, "description": what},
                                    409: {"description": "Not (successfully) finished."}},
                         summary=f"Download {what[0].lower()}{what[1:]}", name=f"get_{route.replace('.', '_')}")


for _route, (_media, _what) in VIEWER_FILES.items():
    _viewer_route(_route, _media, _what)


@router.get(
    "/{job_id}/preview.png",
    response_class=FileResponse,
    responses={**_ERRORS, 200: {"content": {"image/png": {}}, "description": "The deformed surface, coloured."},
               409: {"description": "Not (successfully) finished."},
               503: {"description": "The picture could not be rendered (the reason is given), or other pictures "
                                    "are being rendered (see Retry-After)."}},
    summary="A picture of the result: deformed surface coloured by von Mises, undeformed outline",
)
def get_preview(request: Request, job: JobDep, store: StoreDep, storage: StorageDep) -> FileResponse:
    path = storage.result_file(job.id, ".png")
    if job.status == JobStatus.succeeded.value and not path.is_file():
        if not json.loads(job.spec).get("output", {}).get("surface", True):
            raise HTTPException(status.HTTP_404_NOT_FOUND,
                                detail=f"job {job.id} has no picture: its output has no surface (output.surface is false)")
        try:
            request.app.state.render_gate.render(storage.result_path(job.id), path)
        except RenderFailed:
            if store.get(job.id, with_spec=False) is None:  # deleted while its picture was rendered
                raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no job {job.id}") from None
            raise
    if not path.is_file() and store.get(job.id, with_spec=False) is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no job {job.id}")
    return _finished_file(job, path, "image/png")


@router.delete(
    "/{job_id}",
    responses={
        **_ERRORS,
        200: {"model": JobOut, "description": "Cancelled (queued, or running and its worker stopped)."},
        202: {"model": JobOut, "description": "Cancellation requested; the worker has not confirmed yet."},
        204: {"description": "A finished job, deleted with its files."},
        409: {"description": "The job finished before it could be cancelled (DELETE again to remove it)."},
    },
    summary="Cancel a queued/running job, or delete a finished one",
)
def delete_job(job: JobBriefDep, store: StoreDep, storage: StorageDep) -> Response:
    outcome = cancel_or_delete(store, storage, job)
    if outcome.outcome == "deleted":
        return Response(status_code=status.HTTP_204_NO_CONTENT)
    if outcome.outcome == "finished":
        raise HTTPException(status.HTTP_409_CONFLICT,
                            detail=f"job {job.id} already {outcome.job.status}; DELETE again to remove it")
    code = status.HTTP_200_OK if outcome.outcome == "cancelled" else status.HTTP_202_ACCEPTED
    return Response(job_out(outcome.job).model_dump_json(), status_code=code, media_type="application/json")
