"""Health, metrics and the API's own documentation."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Request, Response
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse

from ... import metrics
from ..deps import PrincipalDep, QueueDep, StoreDep
from ..models import Health
from ..reads import health_check

public = APIRouter(tags=["system"])
router = APIRouter(tags=["system"])


_PAGE = Path(__file__).resolve().parents[1] / "static" / "index.html"


@public.get("/", response_class=HTMLResponse, summary="The web page: jobs, a submit form, pictures, downloads")
def index() -> HTMLResponse:
    # static on purpose (no token needed to load it): the page asks for the token and sends it
    # with every request it makes
    return HTMLResponse(_PAGE.read_text(encoding="utf-8"))


@public.get(
    "/health",
    response_model=Health,
    responses={503: {"model": Health, "description": "The database or the queue does not answer."}},
    summary="Liveness and readiness: database and queue checked (no authentication)",
)
async def health(request: Request, store: StoreDep, queue: QueueDep) -> JSONResponse:
    from engine import __version__

    # on threads of its own: a probe must answer while submissions hold the shared pool
    try:
        await health_check(store.ping)
        database = "ok"
    except Exception as exc:
        database = f"unreachable: {type(exc).__name__}"
    queue_ok, queue_info = await health_check(queue.health)
    ok = database == "ok" and queue_ok
    body = Health(status="ok" if ok else "unavailable", database=database, queue=queue_info, version=__version__)
    return JSONResponse(body.model_dump(), status_code=200 if ok else 503)


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {"text/plain": {}}, "description": "Prometheus text format 0.0.4."},
               401: {"description": "Missing or invalid bearer token (when tokens are configured)."}},
    summary="Prometheus metrics: jobs by status, durations, queue length (a tenant's token: its own jobs by status)",
)
def get_metrics(store: StoreDep, queue: QueueDep, principal: PrincipalDep) -> Response:
    _, info = queue.health()
    return Response(metrics.render(store, info, principal.owner, principal.everyone), media_type=metrics.CONTENT_TYPE)


@router.get("/openapi.json", include_in_schema=False)
def openapi_document(request: Request) -> JSONResponse:
    return JSONResponse(request.app.openapi())


@router.get("/docs", include_in_schema=False)
def swagger_ui() -> HTMLResponse:
    return get_swagger_ui_html(openapi_url="/openapi.json", title="voxelastic API")
