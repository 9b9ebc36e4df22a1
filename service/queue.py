"""Where queued jobs go: the local pool of worker processes, or Celery workers.

Both backends take jobs from the same table; the queue only decides who runs them.

- :class:`LocalQueue` (``VOXELASTIC_QUEUE=local``, the default): one thread per slot in the API
  process claims the oldest queued job and runs it on its worker process
  (:class:`service.worker.Supervisor`). At start it takes a lock on the data directory (one
  server per job table) and re-queues jobs a killed server left running.
- :class:`CeleryQueue` (``VOXELASTIC_QUEUE=celery``): a message per job to the Redis broker;
  ``celery -A service.celery_app worker`` processes claim and run it the same way.
"""

from __future__ import annotations

import fcntl
import logging
import os
import threading
from pathlib import Path
from typing import Any, Protocol

from .settings import Settings
from .storage import Storage
from .store import Job, JobStore
from .worker import Supervisor, WorkerStartError

log = logging.getLogger("voxelastic.queue")

IDLE_POLL = 0.5  # an idle slot looks for work this often even without a wake-up


class Queue(Protocol):
    backend: str

    def start(self) -> None: ...

    def stop(self) -> None: ...

    def enqueue(self, job_id: str) -> None: ...

    def health(self) -> tuple[bool, dict[str, Any]]: ...


class DataDirLocked(RuntimeError):
    """Another server already runs local workers on this data directory."""


class LocalQueue:
    """A pool of ``settings.workers`` slots, each a thread supervising one worker process."""

    backend = "local"

    def __init__(self, store: JobStore, storage: Storage, settings: Settings):
        self.store, self.storage, self.settings = store, storage, settings
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._threads: list[threading.Thread] = []
        self._supervisors: list[Supervisor] = []
        self._lock_file = None
        self.recovered: dict[str, str] = {}

    def start(self) -> None:
        self._lock_data_dir()
        # Nothing can be running at our start: the lock says no other server is alive on this table.
        self.recovered = self.store.recover(self.settings.max_attempts)
        if self.recovered:
            log.warning("re-queued or failed jobs left running by a previous server: %s", self.recovered)
        for i in range(self.settings.workers):
            sup = Supervisor(self.store, self.storage, self.settings, name=f"slot{i}")
            t = threading.Thread(target=self._slot, args=(sup,), name=f"voxelastic-slot{i}", daemon=True)
            self._supervisors.append(sup)
            self._threads.append(t)
            t.start()

    def _lock_data_dir(self) -> None:
        path = Path(self.settings.data_dir) / "server.lock"
        path.parent.mkdir(parents=True, exist_ok=True)
        f = open(path, "a+")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            owner = f.read().strip() or "unknown"
            f.close()
            raise DataDirLocked(
                f"another voxelastic server (pid {owner}) runs local workers on {self.settings.data_dir}; "
                "stop it or set VOXELASTIC_DATA_DIR to another directory"
            ) from None
        f.seek(0)
        f.truncate()
        f.write(str(os.getpid()))
        f.flush()
        self._lock_file = f

    def _slot(self, sup: Supervisor) -> None:
        # The slot's worker process is started here, in the slot's own long-lived thread: the
        # process dies with the thread that started it (PR_SET_PDEATHSIG), i.e. with the server.
        try:
            sup.ensure_process((self.settings.arch, self.settings.precision))
        except WorkerStartError as exc:
            log.error("%s: %s", sup.name, exc)
        # attempts whose end could not be written yet (the job table unavailable), with the error;
        # recorded before the slot claims anything else, so no job stays "running" without a worker
        unsettled: list[tuple[Job, Exception]] = []
        while not self._stopping.is_set():
            self._wake.clear()
            if unsettled and not self._settle(sup, unsettled):
                self._wake.wait(IDLE_POLL)
                continue
            try:
                job = self.store.claim_next()
            except Exception:  # the database went away for a moment: keep the slot alive
                log.warning("%s: claiming a job failed (the job table is unavailable)", sup.name, exc_info=True)
                job = None
            if job is None:
                self._wake.wait(IDLE_POLL)
                continue
            status = None
            try:
                status = sup.run(job)
                log.info("%s: job %s ended %s", sup.name, job.id, status)
            except Exception as exc:  # the attempt's end could not be recorded: try again before the next job
                log.warning("%s: job %s: could not record the end of attempt %d", sup.name, job.id, job.attempts,
                            exc_info=True)
                unsettled.append((job, exc))
            if status == "queued":  # its worker was lost: let any idle slot retry it now
                self._wake.set()
        sup.shutdown()

    @staticmethod
    def _settle(sup: Supervisor, unsettled: list[tuple[Job, Exception]]) -> bool:
        """Record the ends of ``unsettled`` attempts (removing those done); False while one fails."""
        while unsettled:
            job, exc = unsettled[0]
            try:
                status = sup.settle(job, job.attempts, exc)
            except Exception:
                return False
            log.info("%s: job %s ended %s (recorded late)", sup.name, job.id, status)
            unsettled.pop(0)
        return True

    def enqueue(self, job_id: str) -> None:
        self._wake.set()

    def stop(self) -> None:
        """Stop the slots; a job interrupted here goes back to the queue (not counted as an attempt)."""
        self._stopping.set()
        self._wake.set()
        for sup in self._supervisors:
            sup.stopping = True
            proc = sup.process
            if proc is not None and sup.job_id:
                proc.kill()  # the slot thread sees the loss and releases its job
        for t in self._threads:
            t.join(timeout=30)
        if self._lock_file is not None:
            self._lock_file.close()
            self._lock_file = None

    def health(self) -> tuple[bool, dict[str, Any]]:
        slots = sum(t.is_alive() for t in self._threads)
        processes = sum(1 for s in self._supervisors if s.process is not None and s.process.alive())
        busy = [s.job_id for s in self._supervisors if s.job_id]
        errors = [s.start_error for s in self._supervisors if s.start_error]
        # no worker process alive and the last start of each failed: every job would fail
        cannot_start = processes == 0 and bool(self._supervisors) and len(errors) == len(self._supervisors)
        ok = slots == self.settings.workers and not self._stopping.is_set() and not cannot_start
        info = {"backend": "local", "workers": self.settings.workers, "slots_alive": slots,
                "processes_alive": processes, "running": len(busy)}
        if errors:
            info["worker_error"] = errors[0]
        return ok, info


class CeleryQueue:
    """Enqueue to Celery on the configured broker; the workers run jobs (service.celery_app)."""

    backend = "celery"

    def __init__(self, store: JobStore, storage: Storage, settings: Settings):
        self.store, self.settings = store, settings
        from .celery_app import make_celery

        self.app = make_celery(settings)

    def start(self) -> None:
        # recovery is the workers' job here: they own running jobs (service.celery_app.on_worker_ready)
        pass

    def stop(self) -> None:
        self.app.close()

    def enqueue(self, job_id: str) -> None:
        self.app.send_task("voxelastic.run_job", args=[job_id])

    def health(self) -> tuple[bool, dict[str, Any]]:
        info: dict[str, Any] = {"backend": "celery", "broker": _redacted(self.settings.broker_url)}
        try:
            with self.app.connection_for_write() as conn:
                conn.ensure_connection(max_retries=1, interval_start=0, interval_step=0, timeout=2)
            info["broker_status"] = "ok"
            return True, info
        except Exception as exc:
            info["broker_status"] = f"unreachable: {type(exc).__name__}"
            return False, info


def _redacted(url: str) -> str:
    """The URL without its password."""
    from urllib.parse import urlsplit, urlunsplit

    parts = urlsplit(url)
    if parts.password:
        netloc = parts.netloc.replace(f":{parts.password}@", ":***@")
        return urlunsplit(parts._replace(netloc=netloc))
    return url


def make_queue(store: JobStore, storage: Storage, settings: Settings) -> Queue:
    return (CeleryQueue if settings.queue == "celery" else LocalQueue)(store, storage, settings)


__all__ = ["CeleryQueue", "DataDirLocked", "LocalQueue", "Queue", "make_queue"]
