"""Job store: every read and state transition of the job table.

Transitions are single compare-and-set UPDATEs guarded by the expected status and, for a running
job, by its attempt number: a worker that lost its job (cancelled, re-queued after a restart)
cannot overwrite what happened since. This is what makes the table safe to share between the
API, the local pool's threads and Celery workers on other machines.

    queued --claim--> running --finish--> succeeded | failed | cancelled
       |                 |--requeue (worker lost, attempts left)--> queued
       +--cancel--> cancelled
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, fields
from datetime import datetime, timedelta, timezone
from enum import Enum
from typing import Any

from sqlalchemy import case, delete, func, select, text, update
from sqlalchemy.engine import Engine
from sqlalchemy.exc import DisconnectionError, IntegrityError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeoutError
from sqlalchemy.orm import Session, defer

from .db import CounterRow, JobRow, make_engine


class JobStatus(str, Enum):
    """Where a job is in its life."""

    queued = "queued"  # accepted and stored; waiting for a worker
    running = "running"  # a worker process holds it (see ``attempts``, ``worker``)
    succeeded = "succeeded"  # the result files are published and downloadable
    failed = "failed"  # ``error`` says why: bad input found late, a limit, a lost worker, a bug
    cancelled = "cancelled"  # stopped on request; its worker process was stopped


# what SQLAlchemy raises when the database does not answer (down, restarting, SQLite locked past its
# busy timeout, no pooled connection free): the service's state, which passes, not a bug
DATABASE_DOWN = (OperationalError, InterfaceError, DisconnectionError, PoolTimeoutError)

TERMINAL = (JobStatus.succeeded.value, JobStatus.failed.value, JobStatus.cancelled.value)

# Upper bounds [s] of the job-duration histogram in /metrics.
DURATION_BUCKETS = (0.5, 1, 2, 5, 10, 30, 60, 120, 300, 600, 1800, 3600)


def utcnow() -> datetime:
    return datetime.now(timezone.utc)


def _aware(t: datetime | None) -> datetime | None:
    # SQLite hands datetimes back without a zone; everything we store is UTC
    return t.replace(tzinfo=timezone.utc) if t is not None and t.tzinfo is None else t


@dataclass
class Job:
    """A snapshot of one row, detached from any database session."""

    id: str
    status: str
    created_at: datetime
    spec: str | None  # canonical JSON; None when read without it (``with_spec=False``)
    mesh_suffix: str
    mesh_bytes: int
    precision: str
    arch: str
    request_hash: str
    mesh_name: str = ""
    started_at: datetime | None = None
    finished_at: datetime | None = None
    heartbeat_at: datetime | None = None
    idempotency_key: str | None = None
    owner: str | None = None
    stage: str | None = None
    fraction: float = 0.0
    iterations: int | None = None
    residual: float | None = None
    step: int | None = None
    steps: int | None = None
    revision: int = 0
    attempts: int = 0
    worker: str | None = None
    cancel_requested: bool = False
    warnings: list = field(default_factory=list)
    stage_times: dict = field(default_factory=dict)
    error: str | None = None
    error_kind: str | None = None
    run_seconds: float | None = None
    result_bytes: int | None = None
    summary: dict = field(default_factory=dict)

    @property
    def terminal(self) -> bool:
        return self.status in TERMINAL


_FIELDS = [f.name for f in fields(Job)]


def _snapshot(row: JobRow, with_spec: bool = True) -> Job:
    values = {name: getattr(row, name) for name in _FIELDS if with_spec or name != "spec"}
    values.setdefault("spec", None)
    for name in ("created_at", "started_at", "finished_at", "heartbeat_at"):
        values[name] = _aware(values[name])
    values["warnings"] = list(values["warnings"] or [])
    values["stage_times"] = dict(values["stage_times"] or {})
    values["summary"] = dict(values["summary"] or {})
    return Job(**values)


def request_hash(spec_text: str, mesh: bytes, suffix: str) -> str:
    """Fingerprint of a submission, to tell a repeated request from a reused Idempotency-Key."""
    h = hashlib.sha256()
    for part in (spec_text.encode(), suffix.encode(), mesh):
        h.update(hashlib.sha256(part).digest())
    return h.hexdigest()


def owner_of(token: str) -> str:
    """The tenant a bearer token stands for, as stored with its jobs: a hash, never the token."""
    return hashlib.sha256(b"voxelastic-owner\0" + token.encode()).hexdigest()


def scoped_key(key: str, owner: str | None) -> str:
    """An Idempotency-Key as stored: per tenant, so equal keys of two tenants never meet."""
    if owner is None:
        return key
    return "t:" + hashlib.sha256(f"{owner}\0{key}".encode()).hexdigest()


class IdempotencyConflict(Exception):
    """An Idempotency-Key already names a job submitted with different content."""


class JobStore:
    """The job table behind a SQLAlchemy engine (``url``: SQLite or PostgreSQL)."""

    def __init__(self, url: str):
        self.engine: Engine = make_engine(url)
        self._ensure_counters()

    # --- counters (monotonic, for /metrics) -----------------------------------------------------

    @staticmethod
    def counter_keys() -> list[str]:
        keys = ["submitted"]
        for st in TERMINAL:
            keys += [f"finished:{st}", f"duration_sum:{st}", f"duration_count:{st}"]
            keys += [f"duration_bucket:{st}:{b:g}" for b in DURATION_BUCKETS]
        return keys

    def _ensure_counters(self) -> None:
        with Session(self.engine) as s:
            present = set(s.scalars(select(CounterRow.key)).all())
        for key in self.counter_keys():
            if key not in present:
                try:
                    with Session(self.engine) as s, s.begin():
                        s.add(CounterRow(key=key, value=0.0))
                except IntegrityError:
                    pass  # another process added it first

    def counters(self) -> dict[str, float]:
        with Session(self.engine) as s:
            return {k: float(v) for k, v in s.execute(select(CounterRow.key, CounterRow.value)).all()}

    @staticmethod
    def _finish_increments(status: str, seconds: float | None) -> dict[str, float]:
        inc = {f"finished:{status}": 1.0}
        if seconds is not None:
            inc[f"duration_sum:{status}"] = seconds
            inc[f"duration_count:{status}"] = 1.0
            for b in DURATION_BUCKETS:
                if seconds <= b:
                    inc[f"duration_bucket:{status}:{b:g}"] = 1.0
        return inc

    @staticmethod
    def _bump(session: Session, increments: dict[str, float]) -> None:
        # one UPDATE for all keys; the rows exist (created at start), so no INSERT can race here
        session.execute(
            update(CounterRow)
            .where(CounterRow.key.in_(list(increments)))
            .values(value=CounterRow.value + case(increments, value=CounterRow.key, else_=0.0))
            .execution_options(synchronize_session=False)
        )

    def close(self) -> None:
        self.engine.dispose()

    # --- reads --------------------------------------------------------------------------------

    def ping(self) -> None:
        """Raise unless the database answers."""
        with self.engine.connect() as conn:
            conn.execute(text("SELECT 1"))

    def get(self, job_id: str, *, with_spec: bool = True) -> Job | None:
        """The job's row; ``with_spec=False`` leaves the spec column unread (``Job.spec`` None): it
        never changes and can be megabytes, while status polls and event streams run every 0.2 s."""
        with Session(self.engine) as s:
            if with_spec:
                row = s.get(JobRow, job_id)
            else:
                row = s.scalars(select(JobRow).options(defer(JobRow.spec, raiseload=True))
                                .where(JobRow.id == job_id)).first()
            return _snapshot(row, with_spec) if row is not None else None

    def spec_of(self, job_id: str) -> str | None:
        """The stored spec alone (canonical JSON), None if the job is gone."""
        with Session(self.engine) as s:
            return s.scalar(select(JobRow.spec).where(JobRow.id == job_id))

    def get_owned(self, job_id: str, owner: str | None, everyone: bool = False, *,
                  with_spec: bool = True) -> Job | None:
        """The job if ``owner`` submitted it (any job when ``everyone``); else None, as if absent."""
        job = self.get(job_id, with_spec=with_spec)
        if job is None or everyone or job.owner == owner:
            return job
        return None

    def list(self, *, limit: int, offset: int, status: str | None = None, owner: str | None = None,
             everyone: bool = True) -> tuple[list[Job], int]:
        """Jobs newest first and how many match in all; only ``owner``'s unless ``everyone``."""
        where = [JobRow.status == status] if status else []
        if not everyone:
            where.append(JobRow.owner == owner if owner is not None else JobRow.owner.is_(None))
        with Session(self.engine) as s:
            total = s.scalar(select(func.count()).select_from(JobRow).where(*where)) or 0
            rows = s.scalars(
                select(JobRow).where(*where).order_by(JobRow.created_at.desc(), JobRow.id).limit(limit).offset(offset)
            ).all()
            return [_snapshot(r) for r in rows], total

    def counts(self, owner: str | None = None, everyone: bool = True) -> dict[str, int]:
        """Number of jobs per status (every status present, zeros included); only ``owner``'s
        unless ``everyone``."""
        stmt = select(JobRow.status, func.count()).group_by(JobRow.status)
        if not everyone:
            stmt = stmt.where(JobRow.owner == owner if owner is not None else JobRow.owner.is_(None))
        with Session(self.engine) as s:
            found = dict(s.execute(stmt).all())
        return {st.value: int(found.get(st.value, 0)) for st in JobStatus}

    def queued_count(self) -> int:
        with Session(self.engine) as s:
            return s.scalar(select(func.count()).select_from(JobRow).where(JobRow.status == "queued")) or 0

    def mean_run_seconds(self, last: int = 50) -> float | None:
        """Mean run time of the most recent successful jobs (for Retry-After)."""
        with Session(self.engine) as s:
            recent = (
                select(JobRow.run_seconds)
                .where(JobRow.status == "succeeded", JobRow.run_seconds.is_not(None))
                .order_by(JobRow.finished_at.desc())
                .limit(last)
                .subquery()
            )
            value = s.scalar(select(func.avg(recent.c.run_seconds)))
        return float(value) if value is not None else None

    def is_cancel_requested(self, job_id: str) -> bool:
        with Session(self.engine) as s:
            return bool(s.scalar(select(JobRow.cancel_requested).where(JobRow.id == job_id)))

    def stale_running(self, older_than: timedelta) -> list[str]:
        cutoff = utcnow() - older_than
        with Session(self.engine) as s:
            return list(
                s.scalars(select(JobRow.id).where(JobRow.status == "running", JobRow.heartbeat_at < cutoff)).all()
            )

    def queued_before(self, older_than: timedelta) -> list[str]:
        cutoff = utcnow() - older_than
        with Session(self.engine) as s:
            return list(s.scalars(select(JobRow.id).where(JobRow.status == "queued", JobRow.created_at < cutoff)).all())

    # --- creation and deletion ----------------------------------------------------------------

    def create(self, job: Job, shown_key: str | None = None) -> tuple[Job, bool]:
        """Insert ``job`` (status queued); with an Idempotency-Key already used, the earlier job.

        Returns (job, created). Raises :class:`IdempotencyConflict` when the key was used for a
        different submission (``shown_key``: the key as the client sent it, for the message).
        """
        if job.idempotency_key is not None:
            existing = self._by_key(job.idempotency_key)
            if existing is not None:
                return self._same_request(existing, job, shown_key), False
        row = JobRow(**{name: getattr(job, name) for name in _FIELDS})
        try:
            with Session(self.engine) as s, s.begin():
                s.add(row)
                s.flush()
                self._bump(s, {"submitted": 1.0})
        except IntegrityError:
            # a concurrent request with the same key won the insert
            existing = self._by_key(job.idempotency_key) if job.idempotency_key else None
            if existing is None:
                raise
            return self._same_request(existing, job, shown_key), False
        return job, True

    def for_idempotency_key(self, key: str, fingerprint: str, shown_as: str | None = None) -> Job | None:
        """The job submitted earlier with ``key``, None if none; IdempotencyConflict on other content."""
        existing = self._by_key(key)
        if existing is not None and existing.request_hash != fingerprint:
            raise IdempotencyConflict(
                f"Idempotency-Key {shown_as or key!r} was used for job {existing.id} with a different spec or mesh"
            )
        return existing

    def _by_key(self, key: str) -> Job | None:
        with Session(self.engine) as s:
            row = s.scalars(select(JobRow).where(JobRow.idempotency_key == key)).first()
            return _snapshot(row) if row is not None else None

    @staticmethod
    def _same_request(existing: Job, job: Job, shown_key: str | None = None) -> Job:
        if existing.request_hash != job.request_hash:
            raise IdempotencyConflict(
                f"Idempotency-Key {shown_key or job.idempotency_key!r} was used for job {existing.id} "
                "with a different spec or mesh"
            )
        return existing

    def delete(self, job_id: str) -> bool:
        """Delete a finished job's row; False if it is not finished (or gone)."""
        with Session(self.engine) as s, s.begin():
            res = s.execute(delete(JobRow).where(JobRow.id == job_id, JobRow.status.in_(TERMINAL)))
        return res.rowcount == 1

    def fail_queued(self, job_id: str, error: str, kind: str) -> bool:
        """Fail a job that never ran (e.g. the broker refused it)."""
        return self._update(job_id, ("queued",), None, status="failed", error=error, error_kind=kind, finished_at=utcnow())

    # --- transitions --------------------------------------------------------------------------

    def _update(self, job_id: str, statuses: tuple[str, ...], attempt: int | None, **values: Any) -> bool:
        """Compare-and-set: apply ``values`` if the job has one of ``statuses`` (and ``attempt``).

        A terminal status also bumps the finished counters, in the same transaction.
        """
        where = [JobRow.id == job_id, JobRow.status.in_(statuses)]
        if attempt is not None:
            where.append(JobRow.attempts == attempt)
        stmt = update(JobRow).where(*where).values(revision=JobRow.revision + 1, **values)
        with Session(self.engine) as s, s.begin():
            res = s.execute(stmt.execution_options(synchronize_session=False))
            changed = res.rowcount == 1
            if changed and values.get("status") in TERMINAL:
                self._bump(s, self._finish_increments(values["status"], values.get("run_seconds")))
        return changed

    def claim(self, job_id: str) -> Job | None:
        """Take a queued job: status running, attempts + 1. None if it is not queued.

        ``worker`` is filled in by :meth:`assign_worker` once the attempt's process is known.
        """
        now = utcnow()
        ok = self._update(
            job_id,
            ("queued",),
            None,
            status="running",
            attempts=JobRow.attempts + 1,
            worker=None,
            started_at=now,
            heartbeat_at=now,
            stage=None,
            fraction=0.0,
            iterations=None,
            residual=None,
            step=None,
            steps=None,
        )
        return self.get(job_id) if ok else None

    def claim_next(self) -> Job | None:
        """Claim the oldest queued job (first in, first out); None when nothing is queued."""
        for _ in range(20):  # another claimer may win the race for a candidate; try the next
            with Session(self.engine) as s:
                job_id = s.scalar(
                    select(JobRow.id).where(JobRow.status == "queued").order_by(JobRow.created_at, JobRow.id).limit(1)
                )
            if job_id is None:
                return None
            job = self.claim(job_id)
            if job is not None:
                return job
        return None

    def take_over(self, job_id: str, stale_after: timedelta, max_attempts: int) -> Job | None:
        """Claim a job whose message came back after its worker died (Celery redelivery).

        Queued: claimed as usual. Running with a heartbeat older than ``stale_after``: its worker
        is gone; re-queued (or failed when its attempts are used up) and then claimed.
        """
        job = self.claim(job_id)
        if job is not None:
            return job
        current = self.get(job_id)
        if current is None or current.status != "running" or current.heartbeat_at is None:
            return None
        if utcnow() - current.heartbeat_at < stale_after:
            return None  # alive elsewhere: this is a duplicate delivery
        note = f"attempt {current.attempts} lost: its worker stopped reporting (last heartbeat {current.heartbeat_at:%H:%M:%S} UTC)"
        if self.requeue(job_id, current.attempts, note, max_attempts) != "queued":
            return None
        return self.claim(job_id)

    def progress(self, job_id: str, attempt: int, stage: str, fraction: float, info: dict[str, Any]) -> bool:
        """Record the progress of a running attempt (also its heartbeat)."""
        values: dict[str, Any] = {"stage": stage[:32], "fraction": _finite(fraction, 0.0), "heartbeat_at": utcnow()}
        for key in ("iterations", "step", "steps"):
            if isinstance(info.get(key), (int, float)) and math.isfinite(info[key]):
                values[key] = int(info[key])
        if isinstance(info.get("residual"), (int, float)):
            values["residual"] = _finite(info["residual"], None)
        return self._update(job_id, ("running",), attempt, **values)

    def assign_worker(self, job_id: str, attempt: int, worker: str) -> bool:
        """Record which process runs the attempt (``host:pid``, for operators and health)."""
        return self._update(job_id, ("running",), attempt, worker=worker[:128], heartbeat_at=utcnow())

    def heartbeat(self, job_id: str, attempt: int) -> bool:
        # no revision bump needed, but one UPDATE either way; events skip unchanged snapshots
        where = [JobRow.id == job_id, JobRow.status == "running", JobRow.attempts == attempt]
        with Session(self.engine) as s, s.begin():
            res = s.execute(update(JobRow).where(*where).values(heartbeat_at=utcnow()))
        return res.rowcount == 1

    def _elapsed(self, job_id: str) -> float | None:
        job = self.get(job_id)
        return (utcnow() - job.started_at).total_seconds() if job and job.started_at else None

    def succeed(self, job_id: str, attempt: int, *, result_bytes: int, summary: dict[str, Any], warnings: list[str]) -> bool:
        job = self.get(job_id)
        return self._update(
            job_id,
            ("running",),
            attempt,
            status="succeeded",
            finished_at=utcnow(),
            fraction=1.0,
            stage="done",
            run_seconds=self._elapsed(job_id),
            result_bytes=result_bytes,
            iterations=summary.get("iterations"),
            residual=_finite(summary.get("residual"), None),
            stage_times=summary.get("stage_times", {}),
            summary={**(job.summary if job else {}), **summary},
            warnings=(job.warnings if job else []) + list(warnings),
        )

    def fail(self, job_id: str, attempt: int, error: str, kind: str) -> bool:
        return self._update(job_id, ("running",), attempt, status="failed", finished_at=utcnow(),
                            run_seconds=self._elapsed(job_id), error=error, error_kind=kind)

    def finish_cancel(self, job_id: str, attempt: int) -> bool:
        """A running attempt was stopped on request."""
        return self._update(job_id, ("running",), attempt, status="cancelled", finished_at=utcnow(),
                            run_seconds=self._elapsed(job_id), error="cancelled on request", error_kind="cancelled")

    def request_cancel(self, job_id: str) -> Job | None:
        """Cancel a queued job at once; flag a running one for its supervisor to stop."""
        if self._update(job_id, ("queued",), None, status="cancelled", finished_at=utcnow(), cancel_requested=True,
                        error="cancelled on request", error_kind="cancelled"):
            return self.get(job_id)
        self._update(job_id, ("running",), None, cancel_requested=True)
        return self.get(job_id)

    def requeue(self, job_id: str, attempt: int, note: str, max_attempts: int) -> str | None:
        """A running attempt was lost: queue the job again, or fail it when attempts are used up.

        Returns the new status ("queued" / "failed"), or None if the job had moved on already.
        """
        job = self.get(job_id)
        if job is None or job.status != "running" or job.attempts != attempt:
            return None
        warnings = job.warnings + [note]
        if job.cancel_requested:
            ok = self._update(job_id, ("running",), attempt, status="cancelled", finished_at=utcnow(),
                              error="cancelled on request", error_kind="cancelled", warnings=warnings)
            return "cancelled" if ok else None
        if attempt >= max_attempts:
            ok = self._update(job_id, ("running",), attempt, status="failed", finished_at=utcnow(), warnings=warnings,
                              error=f"{note}; gave up after {attempt} attempts", error_kind="worker_lost")
            return "failed" if ok else None
        ok = self._update(job_id, ("running",), attempt, status="queued", worker=None, stage=None, fraction=0.0,
                          warnings=warnings)
        return "queued" if ok else None

    def release(self, job_id: str, attempt: int, note: str) -> str | None:
        """Give a running job back to the queue without counting the attempt (server shutdown)."""
        job = self.get(job_id)
        if job is None:
            return None
        if job.cancel_requested:
            ok = self._update(job_id, ("running",), attempt, status="cancelled", finished_at=utcnow(),
                              error="cancelled on request", error_kind="cancelled")
            return "cancelled" if ok else None
        ok = self._update(job_id, ("running",), attempt, status="queued", worker=None, stage=None, fraction=0.0,
                          attempts=JobRow.attempts - 1, warnings=job.warnings + [note])
        return "queued" if ok else None

    def recover(self, max_attempts: int, older_than: timedelta | None = None) -> dict[str, str]:
        """Re-queue (or fail) jobs left running by a dead server or worker.

        ``older_than=None``: every running job (the local server owns all of them, so at its
        start none can be alive); else only those whose heartbeat is older (Celery workers).
        """
        with Session(self.engine) as s:
            stmt = select(JobRow.id, JobRow.attempts).where(JobRow.status == "running")
            if older_than is not None:
                stmt = stmt.where(JobRow.heartbeat_at < utcnow() - older_than)
            running = s.execute(stmt).all()
        outcome = {}
        for job_id, attempt in running:
            note = f"attempt {attempt} interrupted: its server or worker stopped while it was running"
            status = self.requeue(job_id, attempt, note, max_attempts)
            if status is not None:
                outcome[job_id] = status
        return outcome


def _finite(value: Any, default: Any) -> Any:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return default
    return v if math.isfinite(v) else default
