"""Response models of the API (what OpenAPI documents and clients receive)."""

from __future__ import annotations

import json
from dataclasses import replace
from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, Field

from ..store import Job, JobStatus, utcnow


class Progress(BaseModel):
    """Progress of the current attempt, as reported by the engine."""

    stage: str | None = Field(None, description="geometry, grid, cut_cells, discretization, solve, done")
    fraction: float = Field(0.0, ge=0, le=1, description="Share of the whole job done, 0..1.")
    iterations: int | None = Field(None, description="Iterations of the current linear solve.")
    residual: float | None = Field(None, description="Its relative residual.")
    step: int | None = Field(None, description="Current load/time step (quasi-static, dynamic).")
    steps: int | None = Field(None, description="Number of steps.")


class Timings(BaseModel):
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    queued_seconds: float | None = Field(None, description="From submission to the start of the last attempt.")
    run_seconds: float | None = Field(None, description="Wall time of the last attempt (so far, while running).")
    stages: dict[str, float] = Field(default_factory=dict, description="Wall time per engine stage [s].")


class ResultInfo(BaseModel):
    url: str = Field(description="The HDF5 result (Range requests supported).")
    xdmf_url: str = Field(description="The XDMF sidecar; save it beside the HDF5 file under the names given.")
    files: dict[str, str] = Field(default_factory=dict, description=(
        "Viewer files (docs/result-format.md): vtkhdf (PyVista, VTK, ParaView), solid_xdmf and surface_xdmf "
        "(meshio; they refer to <id>.h5, save them beside it)."))
    preview_url: str | None = Field(None, description="A PNG of the deformed surface (when the job output a surface).")
    bytes: int | None = None
    filename: str


class JobOut(BaseModel):
    """A job: status, progress, timings, warnings, error, and where its result is."""

    id: str
    status: JobStatus
    progress: Progress
    timings: Timings
    attempts: int = Field(description="Attempts started (a lost worker process starts another).")
    worker: str | None = Field(None, description="host:pid of the worker process of the current attempt.")
    cancel_requested: bool = False
    warnings: list[str] = Field(default_factory=list)
    error: str | None = Field(None, description="Why the job failed or stopped.")
    error_kind: Literal["input", "limit", "storage", "worker_lost", "internal", "cancelled"] | None = None
    result: ResultInfo | None = None
    spec: dict[str, Any] = Field(description="The validated job spec, defaults filled in.")
    summary: dict[str, Any] = Field(default_factory=dict, description=(
        "Grid, facets, memory estimate, solver figures; when the result holds a stress, \"peak\": the largest von "
        "Mises [Pa] on the surface and in the volume, each {value, location [m], time}."))


def job_json(job: Job) -> str:
    """``job_out(job)`` as JSON with the stored spec copied in as it is: it is canonical JSON made
    by the server, and parsing and re-encoding it on every status poll cost the most CPU of all
    (a spec of megabytes)."""
    surface = output_surface(job.spec) if job.status == "succeeded" else None
    head = job_out(replace(job, spec=None), surface=surface).model_dump_json(exclude={"spec"})
    return f'{head[:-1]},"spec":{job.spec}}}'


class JobPage(BaseModel):
    items: list[JobOut]
    total: int
    limit: int
    offset: int
    next: str | None = Field(None, description="The next page, if any, as a path with its query (relative to this "
                             "server, e.g. /jobs?limit=50&offset=50).")


class Health(BaseModel):
    status: Literal["ok", "unavailable"]
    database: str
    queue: dict[str, Any]
    version: str


def output_surface(spec_json: str | None) -> bool:
    """Whether a stored spec asks for the surface output (its default: yes)."""
    return bool(json.loads(spec_json or "{}").get("output", {}).get("surface", True))


def job_out(job: Job, *, surface: bool | None = None) -> JobOut:
    """The API view of a stored job. A job read without its spec (``job.spec`` None) gets ``spec =
    {}`` (callers exclude it) and, once succeeded, needs ``surface`` for its result links."""
    now = utcnow()
    queued = None
    if job.started_at is not None:
        queued = (job.started_at - job.created_at).total_seconds()
    elif job.status == "queued":
        queued = (now - job.created_at).total_seconds()
    run = job.run_seconds
    if run is None and job.status == "running" and job.started_at is not None:
        run = (now - job.started_at).total_seconds()
    result = None
    if job.status == "succeeded":
        base = f"/jobs/{job.id}"
        if surface is None:
            surface = output_surface(job.spec)
        files = {"vtkhdf": f"{base}/result.vtkhdf", "solid_xdmf": f"{base}/result.solid.xdmf"}
        if surface:
            files["surface_xdmf"] = f"{base}/result.surface.xdmf"
        result = ResultInfo(url=f"{base}/result", xdmf_url=f"{base}/result.xdmf", files=files,
                            preview_url=f"{base}/preview.png" if surface else None,
                            bytes=job.result_bytes, filename=f"{job.id}.h5")
    summary = {k: v for k, v in job.summary.items() if k not in ("warnings", "stage_times")}
    return JobOut(
        id=job.id,
        status=JobStatus(job.status),
        progress=Progress(stage=job.stage, fraction=min(max(job.fraction or 0.0, 0.0), 1.0), iterations=job.iterations,
                          residual=job.residual, step=job.step, steps=job.steps),
        timings=Timings(created_at=job.created_at, started_at=job.started_at, finished_at=job.finished_at,
                        queued_seconds=queued, run_seconds=run, stages=job.stage_times),
        attempts=job.attempts,
        worker=job.worker,
        cancel_requested=job.cancel_requested,
        warnings=job.warnings,
        error=job.error,
        error_kind=job.error_kind,
        result=result,
        spec=json.loads(job.spec) if job.spec is not None else {},
        summary=summary,
    )
