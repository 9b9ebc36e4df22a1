"""Dependencies of the routes, as ``Annotated`` aliases (``SettingsDep``, ``StoreDep``, ...)."""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from ..queue import Queue
from ..settings import Settings
from ..storage import JOB_ID_PATTERN, Storage
from ..store import Job, JobStore


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_store(request: Request) -> JobStore:
    return request.app.state.store


def get_storage(request: Request) -> Storage:
    return request.app.state.storage


def get_queue(request: Request) -> Queue:
    return request.app.state.queue


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[JobStore, Depends(get_store)]
StorageDep = Annotated[Storage, Depends(get_storage)]
QueueDep = Annotated[Queue, Depends(get_queue)]

_bearer = HTTPBearer(auto_error=False, description="Required when the server has VOXELASTIC_TOKENS set.")


def require_token(
    settings: SettingsDep, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> None:
    """401 unless no tokens are configured or the request carries one of them as a Bearer token."""
    if not settings.tokens:
        return
    if credentials is not None and credentials.scheme.lower() == "bearer":
        given = credentials.credentials.encode()
        # compare against every token in constant time: no early exit that leaks which matched
        if any([hmac.compare_digest(given, t.encode()) for t in settings.tokens]):
            return
    raise HTTPException(
        status.HTTP_401_UNAUTHORIZED,
        detail="missing or invalid bearer token",
        headers={"WWW-Authenticate": "Bearer"},
    )


JobId = Annotated[str, Path(pattern=JOB_ID_PATTERN, description="Job id (22 URL-safe characters).")]


def get_job(job_id: JobId, store: StoreDep) -> Job:
    """The job named in the path, or 404."""
    job = store.get(job_id)
    if job is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no job {job_id}")
    return job


JobDep = Annotated[Job, Depends(get_job)]
