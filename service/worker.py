"""Parent side of a worker: a spawned process per slot, and the supervisor that runs jobs on it.

Why a process per slot, kept alive between jobs: ``ti.init`` happens once per process, kernels
compile once, so a small job runs in a fraction of a second; and a process can be stopped at any
moment, which is how cancellation and the limits work (a thread could not be).

Taichi's arch and precision are fixed per process (``engine.runtime.init`` refuses to switch), so
a worker process is started for a *runtime key* (arch, precision): the job's precision, and its
arch unless it says ``auto`` (then the server's ``VOXELASTIC_ARCH``). A job whose key differs from
its slot's current process gets a fresh process (about a second); the old one is stopped. First
in, first out is kept: a slot never skips a job to find one that matches its process.

The supervisor enforces per attempt: the wall-time limit (``VOXELASTIC_JOB_TIME_LIMIT``), the
memory limit on the process tree's resident memory (``VOXELASTIC_WORKER_MEMORY_BYTES``), and
cancellation (the job's ``cancel_requested`` flag) -- each by killing the process.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import signal
import socket
import time
from datetime import timedelta
from pathlib import Path

import psutil
from sqlalchemy.exc import SQLAlchemyError

from .faults import ERROR_KIND, describe, is_storage_fault
from .runner import Task, worker_main
from .settings import Settings
from .storage import Storage
from .store import Job, JobStore

log = logging.getLogger("voxelastic.worker")

_SPAWN = mp.get_context("spawn")
START_TIMEOUT = 180.0  # first start compiles nothing, but imports + ti.init on a loaded machine
POLL = 0.1  # seconds between checks of limits and cancellation while a job runs
CANCEL_CHECK = 0.25
HEARTBEAT = 5.0
PROGRESS_WRITE = 0.25  # at most this often per job is progress written to the table


class WorkerStartError(RuntimeError):
    """A worker process could not initialise its Taichi runtime."""


def runtime_key(job: Job, settings: Settings) -> tuple[str, str]:
    """(arch, precision) a job needs from its worker process."""
    return (job.arch if job.arch != "auto" else settings.arch, job.precision)


class WorkerProcess:
    """A spawned child running :func:`service.runner.worker_main` for one runtime key."""

    def __init__(self, key: tuple[str, str], settings: Settings):
        self.key = key
        self.conn, child = _SPAWN.Pipe(duplex=True)
        self.process = _SPAWN.Process(
            target=worker_main,
            args=(child, key[0], key[1], str(settings.cache_dir), settings.worker_nice),
            name=f"voxelastic-worker-{key[0]}-{key[1]}",
            daemon=True,
        )
        self.process.start()
        child.close()
        self.info: dict = {}
        if not self.conn.poll(START_TIMEOUT):
            self.kill()
            raise WorkerStartError(f"worker process for arch={key[0]}, precision={key[1]} did not start in {START_TIMEOUT:g} s")
        try:
            msg = self.conn.recv()
        except (EOFError, OSError):
            self.kill()
            raise WorkerStartError(f"worker process for arch={key[0]}, precision={key[1]} died while starting") from None
        if msg[0] != "ready":
            self.kill()
            raise WorkerStartError(f"worker process for arch={key[0]}, precision={key[1]} failed to start: {msg[1]}")
        self.info = msg[1]

    @property
    def pid(self) -> int:
        return self.process.pid

    @property
    def label(self) -> str:
        return f"{socket.gethostname()}:{self.pid}"

    def alive(self) -> bool:
        return self.process.is_alive()

    def send(self, task: Task) -> None:
        self.conn.send(task)

    def poll(self, timeout: float):
        """The next message, or None after ``timeout``; EOFError when the process is gone."""
        if self.conn.poll(timeout):
            return self.conn.recv()
        if not self.process.is_alive():
            raise EOFError
        return None

    def rss(self) -> int:
        """Resident memory of the process and its descendants [bytes]."""
        try:
            proc = psutil.Process(self.pid)
            total = proc.memory_info().rss
            for child in proc.children(recursive=True):
                try:
                    total += child.memory_info().rss
                except psutil.Error:
                    pass
            return total
        except psutil.Error:
            return 0

    def exit_description(self) -> str:
        self.process.join(timeout=2)
        code = self.process.exitcode
        if code is None:
            return "stopped responding"
        if code < 0:
            try:
                return f"was killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"was killed by signal {-code}"
        return f"exited with status {code}"

    def kill(self) -> None:
        """Stop the process (and anything it started) at once."""
        try:
            for child in psutil.Process(self.pid).children(recursive=True):
                child.kill()
        except psutil.Error:
            pass
        if self.process.is_alive():
            self.process.kill()
        self.process.join(timeout=10)
        # the pipe is left to the garbage collector: another thread may still be polling it

    def stop(self) -> None:
        """Ask the process to exit after its current task; kill it if it does not."""
        try:
            self.conn.send(None)
        except (OSError, ValueError):
            pass
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.kill()
        else:
            self.conn.close()


class Supervisor:
    """Runs claimed jobs one at a time on a worker process of the right runtime key."""

    def __init__(self, store: JobStore, storage: Storage, settings: Settings, name: str = "worker"):
        self.store, self.storage, self.settings, self.name = store, storage, settings, name
        self.process: WorkerProcess | None = None
        self.job_id: str | None = None  # the job running now (for health and shutdown)
        self.stopping = False  # set by a server shutdown: a lost job is released, not retried
        # why the last worker process could not start (None once one has): /health reports it, so
        # a server whose workers cannot run anything is not "ok" (issue 18: the image lacked libX11)
        self.start_error: str | None = None
        # exceptions that end an attempt through the caller's own handling (Celery's soft time limit)
        self.passthrough: tuple[type[BaseException], ...] = ()

    def ensure_process(self, key: tuple[str, str]) -> WorkerProcess:
        if self.process is not None and (self.process.key != key or not self.process.alive()):
            self.process.stop()
            self.process = None
        if self.process is None:
            try:
                self.process = WorkerProcess(key, self.settings)
            except WorkerStartError as exc:
                self.start_error = str(exc)
                raise
            self.start_error = None
            log.info("%s: worker process %s started (arch=%s, precision=%s)", self.name, self.process.pid, *key)
        return self.process

    def shutdown(self) -> None:
        """Stop the worker process: at once if it runs a job, else after it exits by itself."""
        if self.process is None:
            return
        if self.job_id:
            self.process.kill()
        else:
            self.process.stop()
        self.process = None

    def run(self, job: Job) -> str | None:
        """Run the claimed ``job`` (status running) to its end; returns the status it ends in.

        "queued" means its worker was lost and the job went back to the queue (attempts left).
        Whatever goes wrong while supervising (a write to the job table that fails: SQLite locked
        past its busy timeout, PostgreSQL restarted) stops the worker process and ends the attempt
        by :meth:`settle`; only when that cannot be recorded either does the exception leave here,
        and the caller records it later (``settle`` again).
        """
        attempt = job.attempts
        self.job_id = job.id
        try:
            return self._run(job, attempt)
        except self.passthrough:
            self.discard_process()
            raise
        except Exception as exc:
            self.discard_process()
            return self.settle(job, attempt, exc)
        finally:
            self.job_id = None

    def _run(self, job: Job, attempt: int) -> str | None:
        try:
            proc = self.ensure_process(runtime_key(job, self.settings))
        except WorkerStartError as exc:
            self.store.fail(job.id, attempt, str(exc), "internal")
            return "failed"
        self.store.assign_worker(job.id, attempt, proc.label)
        self.storage.clear_attempts(job.id)
        proc.send(self._task(job, proc))
        return self._supervise(job, attempt, proc)

    def discard_process(self) -> None:
        """Kill the worker process and forget it: one interrupted mid-job still has that job's
        messages ("done" included) in its pipe, which the next job would read as its own."""
        proc, self.process = self.process, None
        if proc is not None:
            proc.kill()

    def settle(self, job: Job, attempt: int, exc: BaseException) -> str | None:
        """End an attempt whose supervision raised ``exc`` (its process is gone): re-queued per
        the retry policy when the job table failed (a passing fault), failed otherwise (a bug that
        a retry would meet again). Raises when the table still cannot be written."""
        if self.stopping:
            return self.store.release(job.id, attempt, f"attempt {attempt} interrupted by a server shutdown")
        if isinstance(exc, SQLAlchemyError):
            log.warning("%s: job %s, attempt %d: the job table could not be written (%s); its worker process "
                        "was stopped", self.name, job.id, attempt, type(exc).__name__)
            note = (f"attempt {attempt}: the job table could not be written while the job ran (database "
                    "unavailable); its worker process was stopped")
            return self.store.requeue(job.id, attempt, note, self.settings.max_attempts)
        log.error("%s: supervising job %s failed", self.name, job.id, exc_info=exc)
        self.store.fail(job.id, attempt, "internal error while supervising the job; its worker process was stopped",
                        "internal")
        return "failed"

    def _task(self, job: Job, proc: WorkerProcess) -> Task:
        s = self.settings
        return Task(
            job_id=job.id,
            attempt=job.attempts,
            spec=job.spec,
            mesh_path=str(self.storage.mesh_path(job.id, job.mesh_suffix)) if job.mesh_bytes else None,
            filename=job.mesh_name or f"mesh{job.mesh_suffix}",
            staging_dir=str(self.storage.staging_dir(job.id, job.attempts)),
            result_name=f"{job.id}.h5",
            arch=proc.key[0],
            geometry_cache=str(Path(s.cache_dir) / "geometry") if s.geometry_cache else None,
            max_cells=s.max_cells,
            max_memory_bytes=int(s.max_job_memory_bytes),
            max_triangles=s.max_triangles,
        )

    def _supervise(self, job: Job, attempt: int, proc: WorkerProcess) -> str | None:
        s = self.settings
        deadline = time.monotonic() + s.job_time_limit
        next_cancel_check = next_write = 0.0
        last_write = time.monotonic()
        stage, pending = None, None
        while True:
            try:
                msg = proc.poll(POLL)
            except (EOFError, OSError):
                return self._lost(job, attempt, proc)
            now = time.monotonic()
            if msg is not None:
                kind = msg[0]
                if kind == "progress":
                    pending = msg[1:]
                elif kind == "done":
                    return self._succeeded(job, attempt, msg[1])
                elif kind == "error":
                    self.storage.clear_attempts(job.id)  # nothing of a failed attempt stays behind
                    self.store.fail(job.id, attempt, msg[2], msg[1])
                    return "failed"
            if pending is not None and (pending[0] != stage or now >= next_write):
                stage = pending[0]
                if not self.store.progress(job.id, attempt, *pending):
                    return self._abandon(job, attempt, proc)
                pending, last_write, next_write = None, now, now + PROGRESS_WRITE
            elif now - last_write > HEARTBEAT:
                self.store.heartbeat(job.id, attempt)
                last_write = now
            if now > deadline:
                proc.kill()
                self.process = None
                self.store.fail(
                    job.id,
                    attempt,
                    f"the job exceeded the wall-time limit of {s.job_time_limit:g} s (VOXELASTIC_JOB_TIME_LIMIT) "
                    f"and was stopped in stage '{stage or 'start'}'",
                    "limit",
                )
                return "failed"
            rss = proc.rss()
            if rss > s.worker_memory_bytes:
                proc.kill()
                self.process = None
                self.store.fail(
                    job.id,
                    attempt,
                    f"the job exceeded the worker memory limit of {_gib(s.worker_memory_bytes)} "
                    f"(VOXELASTIC_WORKER_MEMORY_BYTES): {_gib(rss)} resident in stage '{stage or 'start'}'; "
                    "it was stopped (a coarser grid needs less)",
                    "limit",
                )
                return "failed"
            if now >= next_cancel_check:
                next_cancel_check = now + CANCEL_CHECK
                if self.store.is_cancel_requested(job.id):
                    proc.kill()
                    self.process = None
                    self.store.finish_cancel(job.id, attempt)
                    return "cancelled"

    def _succeeded(self, job: Job, attempt: int, summary: dict) -> str | None:
        try:
            size = self.storage.publish(job.id, attempt)
        except OSError as exc:
            self.storage.clear_attempts(job.id)
            if is_storage_fault(exc):
                self.store.fail(job.id, attempt, describe(exc, "the result"), ERROR_KIND)
            else:
                self.store.fail(job.id, attempt, f"internal error: could not publish the result: {exc}", "internal")
            return "failed"
        if self.store.succeed(job.id, attempt, result_bytes=size, summary=summary, warnings=summary.get("warnings", [])):
            return "succeeded"
        # the row moved on while the last bytes were written (taken over after a lost heartbeat);
        # what we published is only served if the row says succeeded, and the next attempt clears it
        current = self.store.get(job.id)
        return current.status if current else None

    def _lost(self, job: Job, attempt: int, proc: WorkerProcess) -> str | None:
        if self.stopping:
            proc.kill()
            self.process = None
            return self.store.release(job.id, attempt, f"attempt {attempt} interrupted by a server shutdown")
        what = f"attempt {attempt}: worker process {proc.pid} {proc.exit_description()}"
        proc.kill()
        self.process = None
        log.warning("%s: %s (job %s)", self.name, what, job.id)
        return self.store.requeue(job.id, attempt, what, self.settings.max_attempts)

    def _abandon(self, job: Job, attempt: int, proc: WorkerProcess) -> str | None:
        # the row moved on without us (deleted, or re-queued by a recovery elsewhere)
        proc.kill()
        self.process = None
        current = self.store.get(job.id)
        return current.status if current else None


def _gib(n: float) -> str:
    return f"{n / 2**30:.2f} GiB"


def stale_after(settings: Settings) -> timedelta:
    return timedelta(seconds=settings.heartbeat_stale_after)
