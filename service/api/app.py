"""The FastAPI application: wiring of settings, store, storage and queue; error shapes; limits.

``create_app(settings)`` builds an app whose lifespan opens the job table, starts the queue
(the local pool's worker processes, or nothing for Celery) and stops it again.
"""

from __future__ import annotations

import logging
import re
import threading
from functools import lru_cache
from contextlib import asynccontextmanager

from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.exception_handlers import http_exception_handler
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import FormData
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .. import sandbox
from ..admission import capped_errors
from ..queue import make_queue
from ..settings import Settings, get_settings
from ..storage import Storage
from ..store import DATABASE_DOWN, JobStore
from .deps import require_token
from .preview import RenderGate
from .routes import jobs, system

log = logging.getLogger("voxelastic.api")

DESCRIPTION = """Simulation jobs of voxelastic: submit a job spec with its mesh, follow its
progress, download the HDF5 result (+ XDMF sidecar). With `VOXELASTIC_TOKENS` set, every endpoint
but `/health` needs `Authorization: Bearer <token>`, and a job is visible only to the token that
submitted it (others get 404); tokens in `VOXELASTIC_ADMIN_TOKENS` see every job."""


class UploadLimit:
    """413 for a ``POST /jobs`` body over ``limit`` bytes, before the whole body is read.

    A declared Content-Length over the limit is refused at once; a body without one is counted
    as it arrives and cut off at the limit (the app's own answer is then replaced by the 413).
    """

    def __init__(self, app: ASGIApp, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"].rstrip("/") != "/jobs":
            await self.app(scope, receive, send)
            return
        headers = dict(scope["headers"])
        encoding = headers.get(b"content-encoding", b"identity").strip().lower()
        if encoding != b"identity":  # a compressed body read as multipart is "Invalid multipart data"
            body = JSONResponse({"detail": [{
                "loc": ["header", "content-encoding"], "type": "unsupported_encoding",
                "msg": f"a request body in content-encoding {encoding.decode('latin-1')!r} is not read: send it "
                       "uncompressed (a compressed mesh file such as part.stl.gz is read as it is)"}]},
                status_code=415)
            await body(scope, receive, send)
            return
        declared = headers.get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            await self._refuse(send, int(declared))
            return
        seen = 0
        over = False

        async def counting_receive() -> Message:
            nonlocal seen, over
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    over = True
                    return {"type": "http.disconnect"}
            return message

        started = False

        async def guarded_send(message: Message) -> None:
            nonlocal started
            if over:
                return  # the app saw a cut-off body; our 413 goes out instead
            started = True
            await send(message)

        await self.app(scope, counting_receive, guarded_send)
        if over and not started:
            await self._refuse(send, seen)

    async def _refuse(self, send: Send, size: int) -> None:
        body = JSONResponse(
            {"detail": f"request body of {size} bytes or more exceeds the upload limit of {self.limit} bytes "
                       "(VOXELASTIC_MAX_UPLOAD_BYTES)"},
            status_code=413,
        )
        await send({"type": "http.response.start", "status": 413, "headers": body.raw_headers})
        await send({"type": "http.response.body", "body": body.body})


def create_app(settings: Settings | None = None) -> FastAPI:
    """The API with its own store, storage and queue (started and stopped by the lifespan)."""
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        store = JobStore(settings.db_url)
        storage = Storage(settings.data_dir)
        queue = make_queue(store, storage, settings)
        # the admission checks' forkserver imports the engine (~1 s): meanwhile the API starts
        threading.Thread(target=sandbox.start, name="admission-forkserver", daemon=True).start()
        await run_in_threadpool(queue.start)
        app.state.settings, app.state.store, app.state.storage, app.state.queue = settings, store, storage, queue
        log.info("voxelastic service: queue=%s, data in %s", queue.backend, settings.data_dir)
        try:
            yield
        finally:
            await run_in_threadpool(queue.stop)
            store.close()

    from engine import __version__

    app = FastAPI(
        title="voxelastic",
        version=__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
        openapi_url=None,  # served by system.router, behind the same authentication
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.render_gate = RenderGate(settings.preview_renders, settings.preview_wait)
    app.add_middleware(UploadLimit, limit=settings.max_upload_bytes)
    authorized = [Depends(require_token)]
    for router in (system.public, jobs.router, system.router):
        _add_head(router)
    app.include_router(system.public)
    app.include_router(jobs.router, dependencies=authorized)
    app.include_router(system.router, dependencies=authorized)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        # the same compact shape as our own 422s; echoing the input back would return whole uploads
        detail = capped_errors([_plain(e, exc.body) for e in exc.errors()])
        return JSONResponse({"detail": detail}, status_code=422)

    for unavailable in DATABASE_DOWN:
        app.add_exception_handler(unavailable, _database_unavailable)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException):
        too_large = _PART_TOO_LARGE.fullmatch(str(exc.detail)) if exc.status_code == 400 else None
        if too_large:
            return JSONResponse({"detail": [_part_too_large(exc, int(too_large.group(1)) * 1024)]}, status_code=413)
        if exc.status_code == 400 and exc.detail == _INVALID_MULTIPART:
            return JSONResponse({"detail": [_multipart_error(exc)]}, status_code=400)
        too_many = _TOO_MANY_PARTS.fullmatch(str(exc.detail)) if exc.status_code == 400 else None
        if too_many:
            return JSONResponse({"detail": [_too_many_parts(*too_many.groups())]}, status_code=400)
        if exc.status_code == 405:
            # Starlette's Allow names the methods of the first route that matched the path only
            # (GET of /jobs/{id}); a client must learn every method the path has (DELETE too)
            allowed = _allowed_methods(request)
            if allowed:
                exc.headers = {**(exc.headers or {}), "Allow": ", ".join(allowed)}
        return await http_exception_handler(request, exc)

    return app


DATABASE_RETRY_AFTER = 5  # seconds


async def _database_unavailable(request: Request, exc: Exception) -> JSONResponse:
    """503 + Retry-After saying the job table is unavailable, instead of a bare 500 and a traceback."""
    log.warning("%s %s: the job table is unavailable (%s)", request.method, request.url.path, type(exc).__name__)
    return JSONResponse({"detail": "the job table is unavailable (the database does not answer); "
                                   f"retry in {DATABASE_RETRY_AFTER} s"},
                        status_code=503, headers={"Retry-After": str(DATABASE_RETRY_AFTER)})


def _add_head(router: APIRouter) -> None:
    """A HEAD route beside every GET route of ``router`` (same handler, left out of the schema).

    FastAPI's routes, unlike Starlette's, do not answer HEAD, though Allow names it (RFC 9110: a
    GET resource should). The request keeps its method, so a file is not read (Starlette sends its
    headers only) and uvicorn drops any other body.
    """
    present = {(r.path, m) for r in router.routes if isinstance(r, APIRoute) for m in r.methods}
    for route in list(router.routes):
        if isinstance(route, APIRoute) and "GET" in route.methods and (route.path, "HEAD") not in present:
            router.add_api_route(route.path.removeprefix(router.prefix), route.endpoint, methods=["HEAD"],
                                 response_class=route.response_class, include_in_schema=False,
                                 name=f"{route.name}_head")


# Starlette's words for a text (non-file) part of a multipart form over its 1 MiB limit
_PART_TOO_LARGE = re.compile(r"Part exceeded maximum size of (\d+)KB\.")


def _part_too_large(exc: Exception, limit: int) -> dict:
    """The 413 entry for a text part over Starlette's limit, naming the part: its message names
    neither the part nor that a file part has no such limit."""
    name = _parsed_part_name(exc.__context__)
    where = f"the form field '{name}'" if name else "a text field of the form"
    msg = (f"{where} is over {limit} bytes ({limit / 2**20:g} MiB), the limit for a text field of a multipart "
           "form; send it as a file part instead (curl -F 'spec=@job.json'; a spec may be up to "
           "VOXELASTIC_MAX_SPEC_BYTES, the mesh is always a file part)")
    return {"loc": ["body", name] if name else ["body"], "msg": msg, "type": "too_large"}


_INVALID_MULTIPART = "Invalid multipart data."  # Starlette's words for every multipart parse error


def _multipart_error(exc: Exception) -> dict:
    """The 400 entry for a body the multipart parser refused, saying what and which limit: its own
    message names neither."""
    from python_multipart.multipart import DEFAULT_MAX_HEADER_COUNT, DEFAULT_MAX_HEADER_SIZE

    cause = getattr(exc.__context__, "__cause__", None)
    reason = str(cause) if cause is not None else ""
    if reason.startswith("Maximum header size exceeded"):
        msg = (f"a header line of a part of the multipart form is over {DEFAULT_MAX_HEADER_SIZE} bytes, the "
               "multipart parser's limit; it is usually the file name in Content-Disposition: send a shorter one")
        return {"loc": ["body"], "msg": msg, "type": "header_too_large"}
    if reason.startswith("Maximum header count exceeded"):
        msg = (f"a part of the multipart form has more than {DEFAULT_MAX_HEADER_COUNT} header lines, the multipart "
               "parser's limit")
        return {"loc": ["body"], "msg": msg, "type": "too_many_headers"}
    return {"loc": ["body"], "type": "multipart_invalid",
            "msg": "the request body is not valid multipart/form-data (a boundary, a part header or the end of "
                   "the form is malformed)"}


# Starlette's words for a form over its count of text fields or of file parts (1000 each)
_TOO_MANY_PARTS = re.compile(r"Too many (fields|files)\. Maximum number of (?:fields|files) is (\d+)\.")


def _too_many_parts(kind: str, limit: str) -> dict:
    """The 400 entry for a form with more parts than the parser takes, in our shape: Starlette's
    own answer is a bare string, which names neither the part of the request nor what a job needs."""
    what = "text fields" if kind == "fields" else "file parts"
    msg = (f"the form has more than {limit} {what}, the limit of this server's form parser; a job "
           "needs one 'spec' field (or file part) and at most one 'mesh' file part")
    return {"loc": ["body"], "msg": msg, "type": f"too_many_{kind}"}


def _parsed_part_name(exc: BaseException | None) -> str | None:
    """The name of the part Starlette's multipart parser was reading when it raised ``exc`` (its
    ``_current_part``, found in the traceback's frames); None when it cannot be told."""
    tb = getattr(exc, "__traceback__", None)
    while tb is not None:
        part = getattr(tb.tb_frame.f_locals.get("self"), "_current_part", None)
        if isinstance(getattr(part, "field_name", None), str):
            return part.field_name[:64] or None
        tb = tb.tb_next
    return None


def _plain(error: dict, body: object) -> dict:
    """A request-validation error in our shape; an empty spec field says so instead of 'Field required'
    (FastAPI treats an empty form field as a missing one)."""
    loc, msg, kind = list(error.get("loc", ())), error.get("msg", ""), error.get("type", "")
    if loc == ["body", "spec"] and kind == "missing":
        if isinstance(body, FormData) and "spec" in body:
            msg = "the spec is empty: send the job spec as JSON in the 'spec' form field or file part"
        else:
            msg = "required: send the job spec as JSON in a 'spec' form field or file part"
    elif loc == ["body", "mesh"] and kind != "missing":
        # FastAPI's own words here name Python classes ("Expected UploadFile, received: <class 'str'>")
        msg = "the mesh must be a file part (with a filename, e.g. part.stl), not a text field"
    return {"loc": loc, "msg": msg, "type": kind}


def _allowed_methods(request: Request) -> list[str]:
    """Every method the API documents for the request's path (HEAD wherever GET is)."""
    methods: set[str] = set()
    for template, operations in request.app.openapi().get("paths", {}).items():
        if _template_regex(template).fullmatch(request.url.path):
            methods |= {m.upper() for m in operations if m.upper() in _METHODS}
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)


_METHODS = {"GET", "PUT", "POST", "DELETE", "PATCH", "HEAD", "OPTIONS", "TRACE"}


@lru_cache(maxsize=64)
def _template_regex(template: str) -> re.Pattern:
    return re.compile(re.sub(r"\\\{[^/]+?\\\}", "[^/]+", re.escape(template)))
