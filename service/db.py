"""The job table (SQLAlchemy 2): SQLite in WAL mode by default, PostgreSQL for Celery scale-out.

The table is the source of truth for every job; status changes are compare-and-set UPDATEs
(see :mod:`service.store`), so concurrent API requests, pool threads and Celery workers never
overwrite each other's transitions.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import (
    JSON,
    inspect,
    text,
    Boolean,
    DateTime,
    Float,
    Integer,
    String,
    Text,
    UniqueConstraint,
    create_engine,
    event,
)
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError, OperationalError, ProgrammingError
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


class Base(DeclarativeBase):
    pass


class JobRow(Base):
    """One simulation job. Times are timezone-aware UTC."""

    __tablename__ = "voxelastic_jobs"
    __table_args__ = (UniqueConstraint("idempotency_key", name="uq_voxelastic_jobs_idempotency_key"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    status: Mapped[str] = mapped_column(String(16), index=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
    started_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    heartbeat_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    # the validated spec (canonical JSON) and the stored mesh's suffix (its format, e.g. ".stl")
    spec: Mapped[str] = mapped_column(Text)
    mesh_suffix: Mapped[str] = mapped_column(String(16))
    mesh_name: Mapped[str] = mapped_column(String(80), default="")  # for messages only
    mesh_bytes: Mapped[int] = mapped_column(Integer)
    precision: Mapped[str] = mapped_column(String(8))
    arch: Mapped[str] = mapped_column(String(8))
    idempotency_key: Mapped[str | None] = mapped_column(String(255))
    # the tenant: SHA-256 of the bearer token that submitted the job (never the token); NULL
    # without authentication
    owner: Mapped[str | None] = mapped_column(String(64), index=True)
    request_hash: Mapped[str] = mapped_column(String(64))
    # progress of the current attempt
    stage: Mapped[str | None] = mapped_column(String(32))
    fraction: Mapped[float] = mapped_column(Float, default=0.0)
    iterations: Mapped[int | None] = mapped_column(Integer)
    residual: Mapped[float | None] = mapped_column(Float)
    step: Mapped[int | None] = mapped_column(Integer)
    steps: Mapped[int | None] = mapped_column(Integer)
    # bumped on every change: server-sent events send a snapshot whenever it moves
    revision: Mapped[int] = mapped_column(Integer, default=0)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    worker: Mapped[str | None] = mapped_column(String(128))
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    warnings: Mapped[list] = mapped_column(JSON, default=list)
    stage_times: Mapped[dict] = mapped_column(JSON, default=dict)
    error: Mapped[str | None] = mapped_column(Text)
    error_kind: Mapped[str | None] = mapped_column(String(16))
    run_seconds: Mapped[float | None] = mapped_column(Float)
    result_bytes: Mapped[int | None] = mapped_column(Integer)
    summary: Mapped[dict] = mapped_column(JSON, default=dict)


class CounterRow(Base):
    """Monotonic counters for /metrics (jobs submitted, finished, duration histogram).

    Kept apart from the job rows so that deleting a job never makes a counter go down.
    """

    __tablename__ = "voxelastic_counters"

    key: Mapped[str] = mapped_column(String(96), primary_key=True)
    value: Mapped[float] = mapped_column(Float, default=0.0)


def _sqlite_pragmas(dbapi_connection, _record) -> None:
    # WAL: readers (status requests) never wait for the writers (progress updates); busy_timeout:
    # concurrent writers wait for each other instead of failing with "database is locked".
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.execute("PRAGMA busy_timeout=30000")
    cursor.close()


def make_engine(url: str) -> Engine:
    """An engine for ``url`` with the table created; SQLite gets WAL mode and a busy timeout."""
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30}, pool_size=16, max_overflow=16)
        event.listen(engine, "connect", _sqlite_pragmas)
    else:
        engine = create_engine(url, pool_pre_ping=True, pool_size=8, max_overflow=8)
    try:
        Base.metadata.create_all(engine)
    except (OperationalError, ProgrammingError, IntegrityError):
        # another process (API and workers start together) created the tables at the same moment
        Base.metadata.create_all(engine)
    _add_missing_columns(engine)
    return engine


# columns added after the first release: (name, SQL type); create_all does not alter a table
_ADDED_COLUMNS = [("owner", "VARCHAR(64)")]


def _add_missing_columns(engine: Engine) -> None:
    """Bring a job table made by an older version up to date (nullable columns only)."""
    present = {c["name"] for c in inspect(engine).get_columns(JobRow.__tablename__)}
    for name, sql_type in _ADDED_COLUMNS:
        if name in present:
            continue
        try:
            with engine.begin() as conn:
                conn.execute(text(f"ALTER TABLE {JobRow.__tablename__} ADD COLUMN {name} {sql_type}"))
        except (OperationalError, ProgrammingError):
            pass  # another process added it first
