"""Celery scale-out: ``VOXELASTIC_QUEUE=celery`` on the API, and on each worker machine::

    celery -A service.celery_app worker --loglevel info

The API puts one message per job on the Redis broker (``VOXELASTIC_BROKER_URL``); a worker
claims the job in the shared job table (``VOXELASTIC_DATABASE_URL``, PostgreSQL) and runs it on
a spawned worker process exactly as the local pool does (:class:`service.worker.Supervisor`):
same limits, same cancellation, same result publishing into the shared ``VOXELASTIC_DATA_DIR``.
The job table stays the source of truth; Celery's result backend is not used.

Choices, and why:

- ``worker_pool = "solo"``: the Celery process itself never initialises Taichi (the job runs in
  a spawned child), so no CUDA context is ever forked; one job per Celery process, scale by
  running more workers (or ``--pool prefork``: each pool process supervises its own child).
- ``task_acks_late`` + ``task_reject_on_worker_lost`` + prefetch 1: a message is acknowledged
  only when its job has ended, so a worker that dies mid-job leaves it to be redelivered.
- Redis ``visibility_timeout`` above the longest job (time limit + 10 min): a message of a job
  still running is never handed to a second worker.
- ``task_soft_time_limit`` / ``task_time_limit``: backstops a little above the supervisor's own
  wall-time limit (which kills the job's process and records the reason); Celery enforces
  them with the prefork pool.
- A redelivered message whose job is still marked running is taken over only when that job's
  heartbeat is stale (its worker is gone). With the solo pool a killed worker's message would
  only come back after the visibility timeout, so every worker also sweeps the table (at start,
  then once a minute): jobs with a stale heartbeat are re-queued and sent again; at start, queued
  jobs whose message may have been lost (older than ten minutes) are sent again too. Duplicates
  are harmless: only one claim of a queued job succeeds.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from datetime import timedelta

from celery import Celery
from celery.exceptions import SoftTimeLimitExceeded
from celery.signals import worker_ready, worker_shutting_down
from sqlalchemy.exc import SQLAlchemyError

from .settings import Settings, get_settings

log = logging.getLogger("voxelastic.celery")

TASK_NAME = "voxelastic.run_job"


def make_celery(settings: Settings) -> Celery:
    """A Celery app configured from ``settings`` (used by the API to send, and by workers)."""
    app = Celery("voxelastic", broker=settings.broker_url, set_as_current=False)
    limit = settings.job_time_limit
    app.conf.update(
        task_serializer="json",
        accept_content=["json"],
        task_ignore_result=True,
        result_backend=None,
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_acks_on_failure_or_timeout=True,
        worker_prefetch_multiplier=1,
        worker_concurrency=1,
        worker_pool="solo",
        task_soft_time_limit=limit + 30,
        task_time_limit=limit + 90,
        broker_transport_options={"visibility_timeout": settings.visibility_timeout},
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
        task_default_queue="voxelastic",
    )
    return app


class _Runtime:
    """Per Celery worker process: the store, storage and the supervisor of its worker process."""

    def __init__(self, settings: Settings):
        from .storage import Storage
        from .store import JobStore
        from .worker import Supervisor

        self.settings = settings
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        self.store = JobStore(settings.db_url)
        self.storage = Storage(settings.data_dir)
        self.supervisor = Supervisor(self.store, self.storage, settings, name=f"celery@{socket.gethostname()}:{os.getpid()}")
        self.supervisor.passthrough = (SoftTimeLimitExceeded,)  # failed by run_job, naming Celery's limit


_runtime: _Runtime | None = None
_runtime_lock = threading.Lock()


def runtime() -> _Runtime:
    global _runtime
    with _runtime_lock:
        if _runtime is None:
            _runtime = _Runtime(get_settings())
        return _runtime


app = make_celery(get_settings())


@app.task(name=TASK_NAME, bind=True)
def run_job(self, job_id: str) -> str | None:
    """Claim ``job_id`` and run it to its end (retrying on this worker while attempts last)."""
    rt = runtime()
    try:
        return _run(rt, job_id)
    except SQLAlchemyError:
        # the job table failed where the supervisor could not record it (it has stopped the job's
        # process): the row is queued, or running with a heartbeat going stale. A message sent for
        # when it is stale takes it over; without one a queued row would wait for a worker restart
        delay = rt.settings.heartbeat_stale_after + 5
        log.warning("job %s: the job table is unavailable; sending the job again in %g s", job_id, delay,
                    exc_info=True)
        app.send_task(TASK_NAME, args=[job_id], countdown=delay)
        return None


def _run(rt: _Runtime, job_id: str) -> str | None:
    from .worker import stale_after

    job = rt.store.take_over(job_id, stale_after(rt.settings), rt.settings.max_attempts)
    if job is None:
        log.info("job %s: nothing to do (not queued, or running elsewhere)", job_id)
        return None
    try:
        while True:
            status = rt.supervisor.run(job)
            if status == "queued" and rt.supervisor.stopping:
                # released by a shutdown of this worker: hand it to another one
                app.send_task(TASK_NAME, args=[job_id])
                return status
            if status != "queued":  # "queued": lost its worker process, attempts left: go again here
                return status
            job = rt.store.claim(job_id)
            if job is None:
                return None
    except SoftTimeLimitExceeded:
        current = rt.store.get(job_id)
        if rt.supervisor.process is not None:
            rt.supervisor.process.kill()
            rt.supervisor.process = None
        if current is not None and current.status == "running":
            rt.store.fail(job_id, current.attempts, f"the job exceeded Celery's soft time limit of "
                          f"{app.conf.task_soft_time_limit:g} s", "limit")
        return "failed"


def sweep(resend_queued: bool) -> None:
    """Re-queue jobs whose worker died (stale heartbeat); at start also re-send old queued jobs."""
    rt = runtime()
    recovered = rt.store.recover(rt.settings.max_attempts, older_than=timedelta(seconds=rt.settings.heartbeat_stale_after))
    resend = [jid for jid, st in recovered.items() if st == "queued"]
    # a queued job older than this may have lost its message (API stopped between insert and send);
    # a duplicate message is harmless: only one claim of a queued job can succeed
    if resend_queued:  # only at start: repeated, it would pile duplicates up behind a long backlog
        resend += rt.store.queued_before(timedelta(minutes=10))
    for job_id in dict.fromkeys(resend):
        app.send_task(TASK_NAME, args=[job_id])
    if recovered or resend:
        log.warning("recovered jobs: %s; re-sent: %s", recovered, resend)


def _sweep_forever(interval: float) -> None:
    while True:
        time.sleep(interval)
        try:
            sweep(resend_queued=False)
        except Exception:  # the database or broker away for a moment: try again next round
            log.exception("recovery sweep failed")


@worker_ready.connect
def on_worker_ready(sender=None, **_) -> None:
    """Recover at start, then every heartbeat period: a worker that died (its message waits for
    the visibility timeout) gets its job re-queued by any live worker within about two minutes."""
    sweep(resend_queued=True)
    interval = runtime().settings.heartbeat_stale_after
    threading.Thread(target=_sweep_forever, args=(interval,), daemon=True, name="voxelastic-sweep").start()


@worker_shutting_down.connect
def on_shutdown(**_) -> None:
    """A warm shutdown stops the job's process; the unacknowledged message is redelivered later."""
    if _runtime is not None:
        _runtime.supervisor.stopping = True
        _runtime.supervisor.shutdown()
