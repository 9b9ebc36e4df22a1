"""Dependencies of the routes, as ``Annotated`` aliases (``SettingsDep``, ``StoreDep``, ...).

All async: FastAPI runs a sync dependency on the shared thread pool, which waiting submissions can
fill; the job reads go to :mod:`service.api.reads` instead (a status poll must stay prompt)."""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from ..queue import Queue
from ..settings import Settings
from ..storage import JOB_ID_PATTERN, Storage
from ..store import Job, JobStore, owner_of
from .reads import read


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_store(request: Request) -> JobStore:
    return request.app.state.store


async def get_storage(request: Request) -> Storage:
    return request.app.state.storage


async def get_queue(request: Request) -> Queue:
    return request.app.state.queue


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[JobStore, Depends(get_store)]
StorageDep = Annotated[Storage, Depends(get_storage)]
QueueDep = Annotated[Queue, Depends(get_queue)]

_bearer = HTTPBearer(auto_error=False, description="Required when the server has VOXELASTIC_TOKENS set.")


@dataclass(frozen=True)
class Principal:
    """Who is asking: the tenant (hash of its token; None without authentication) and whether it
    sees every tenant's jobs (an admin token, or a server without tokens)."""

    owner: str | None
    everyone: bool


def _matches(given: bytes, tokens: list[str]) -> bool:
    # every token compared in constant time: no early exit that leaks which one matched
    return any([hmac.compare_digest(given, t.encode()) for t in tokens])


async def require_token(
    settings: SettingsDep, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> Principal:
    """401 unless no tokens are configured or the request carries one of them as a Bearer token."""
    if not settings.auth_enabled:
        return Principal(owner=None, everyone=True)
    if credentials is not None and credentials.scheme.lower() == "bearer":
        given = credentials.credentials.encode()
        admin, tenant = _matches(given, settings.admin_tokens), _matches(given, settings.tokens)
        if admin or tenant:
            return Principal(owner=owner_of(credentials.credentials), everyone=admin)
    raise HTTPException(
        status.HTTP_401_UNAUTHORIZED,
        detail="missing or invalid bearer token",
        headers={"WWW-Authenticate": "Bearer"},
    )


PrincipalDep = Annotated[Principal, Depends(require_token)]
JobId = Annotated[str, Path(pattern=JOB_ID_PATTERN, description="Job id (22 URL-safe characters).")]


async def get_job(job_id: JobId, store: StoreDep, principal: PrincipalDep) -> Job:
    """The job named in the path if the caller may see it, else 404 (another tenant's job is absent,
    not forbidden: a 403 would confirm that the id exists)."""
    job = await read(store.get_owned, job_id, principal.owner, principal.everyone)
    if job is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no job {job_id}")
    return job


JobDep = Annotated[Job, Depends(get_job)]


async def get_job_brief(job_id: JobId, store: StoreDep, principal: PrincipalDep) -> Job:
    """:func:`get_job` without the spec (``Job.spec`` None): for routes that never show it."""
    job = await read(store.get_owned, job_id, principal.owner, principal.everyone, with_spec=False)
    if job is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, detail=f"no job {job_id}")
    return job


JobBriefDep = Annotated[Job, Depends(get_job_brief)]
