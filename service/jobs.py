"""Job operations behind the routes: submit (with admission checks), cancel or delete.

Route handlers stay thin; everything that decides something lives here or in the store.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

from .admission import admit
from .faults import check_space, is_storage_fault, rejection, result_estimate, result_size_fields
from .queue import Queue
from .settings import Settings
from .storage import Storage, display_name, new_job_id
from .store import Job, JobStore, request_hash, scoped_key, utcnow

log = logging.getLogger("voxelastic.jobs")


class QueueFull(Exception):
    """Too many queued jobs; ``retry_after`` is a guess of when a slot frees up [s]."""

    def __init__(self, queued: int, retry_after: int):
        super().__init__(f"{queued} jobs are queued, the limit is reached (VOXELASTIC_MAX_QUEUED); retry later")
        self.retry_after = retry_after


class QueueUnavailable(Exception):
    """The broker refused the job (Celery backend); nothing of the submission was kept."""

    retry_after = 30  # seconds: a broker that restarts is back in about this long


@dataclass
class Submitted:
    job: Job
    created: bool  # False: an earlier job with the same Idempotency-Key


def submit(
    store: JobStore,
    storage: Storage,
    queue: Queue,
    settings: Settings,
    *,
    spec_text: str | bytes,
    mesh: bytes | None,
    mesh_filename: str | None,
    idempotency_key: str | None,
    owner: str | None = None,
) -> Submitted:
    """Check a submission, store its mesh and row (status queued) and hand it to the queue.

    Raises ``admission.Rejected`` (422), ``store.IdempotencyConflict`` (409), :class:`QueueFull`
    (429) or :class:`QueueUnavailable` (503). ``owner``: the hash of the submitting token
    (:func:`service.store.owner_of`), None without authentication.
    """
    admitted = admit(spec_text, mesh, mesh_filename, settings)
    fingerprint = request_hash(admitted.spec_json, mesh or b"", admitted.suffix)
    # keys are per tenant: another token's key must neither return nor reveal that tenant's job
    stored_key = scoped_key(idempotency_key, owner) if idempotency_key is not None else None
    if stored_key is not None:
        # a repeated request gets its job back even when the queue has filled up since
        existing = store.for_idempotency_key(stored_key, fingerprint, shown_as=idempotency_key)
        if existing is not None:
            return Submitted(existing, False)
    queued = store.queued_count()
    if queued >= settings.max_queued:
        raise QueueFull(queued, retry_after(store, settings, queued))

    job = Job(
        id=new_job_id(),
        status="queued",
        created_at=utcnow(),
        spec=admitted.spec_json,
        mesh_suffix=admitted.suffix,
        mesh_name=display_name(mesh_filename or admitted.mesh_field, admitted.suffix) if mesh else "",
        mesh_bytes=len(mesh or b""),
        precision=admitted.precision,
        arch=admitted.arch,
        request_hash=fingerprint,
        idempotency_key=stored_key,
        owner=owner,
        summary={"triangles": admitted.triangles, "grid": list(admitted.grid_shape),
                 "memory_estimate_bytes": admitted.memory_estimate},
    )
    # 507 now rather than a failed write after the solve (issue 18)
    check_space(storage.root, result_estimate(admitted.spec_json, admitted.grid_shape, admitted.triangles)
                + len(mesh or b""), "this job's result", result_size_fields(admitted.spec_json))
    if mesh:
        try:
            storage.save_mesh(job.id, admitted.suffix, mesh)
        except OSError as exc:
            storage.delete(job.id)
            if not is_storage_fault(exc):
                raise
            raise rejection(exc, "the uploaded mesh") from None
    try:
        stored, created = store.create(job, shown_key=idempotency_key)
    except BaseException:  # the job table unavailable (503 by the app's handler): no orphaned mesh
        storage.delete(job.id)
        raise
    if not created:  # lost a race with the same Idempotency-Key
        storage.delete(job.id)
        return Submitted(stored, False)
    try:
        queue.enqueue(job.id)
    except Exception as exc:
        log.warning("job %s: the broker refused it (%s: %s); its row and mesh are removed", job.id,
                    type(exc).__name__, exc)
        # "not queued" must mean nothing was kept: no failed row in the tenant's list, no stored mesh,
        # and a retry with the same Idempotency-Key makes a new job. Failed first, so the counters
        # (submitted = finished + live) stay consistent; then deleted
        store.fail_queued(job.id, "the job queue is unavailable; the job was not queued", "internal")
        store.delete(job.id)
        storage.delete(job.id)
        raise QueueUnavailable("the job queue is unavailable: the job was not queued and nothing of it was kept; "
                               f"submit it again in {QueueUnavailable.retry_after} s") from None
    return Submitted(stored, True)


def retry_after(store: JobStore, settings: Settings, queued: int) -> int:
    """Seconds until a queue slot is likely free: recent mean run time x queue depth / workers."""
    mean = store.mean_run_seconds() or 10.0
    return int(min(3600, max(1, math.ceil(mean * max(1, queued - settings.max_queued + 1) / settings.workers))))


@dataclass
class Removal:
    outcome: str  # "deleted" | "cancelled" | "cancelling" | "finished"
    job: Job | None


def cancel_or_delete(store: JobStore, storage: Storage, job: Job, wait: float = 5.0) -> Removal:
    """Delete a finished job with its files; cancel a queued or running one.

    A running job's worker process is stopped by its supervisor within a fraction of a second;
    this waits up to ``wait`` seconds for that so the answer usually carries the final status.
    """
    if job.terminal:
        if store.delete(job.id):
            storage.delete(job.id)
            return Removal("deleted", None)
        job = store.get(job.id) or job
        return Removal("deleted", None) if job is None else Removal("finished", job)
    current = store.request_cancel(job.id)
    deadline = time.monotonic() + wait
    while current is not None and not current.terminal and time.monotonic() < deadline:
        time.sleep(0.05)
        current = store.get(job.id)
    if current is None:
        return Removal("deleted", None)
    if current.status == "cancelled":
        return Removal("cancelled", current)
    return Removal("finished" if current.terminal else "cancelling", current)
