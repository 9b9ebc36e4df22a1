"""All service configuration in one pydantic-settings class (environment prefix ``VOXELASTIC_``).

Every field can be set as ``VOXELASTIC_<NAME>`` (e.g. ``VOXELASTIC_DATA_DIR``,
``VOXELASTIC_WORKERS``, ``VOXELASTIC_TOKENS=alpha,beta``). Sizes are bytes, times seconds.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict


def _default_data_dir() -> Path:
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return Path(base) / "voxelastic"


def _default_cache_dir() -> Path:
    # the engine's own cache root, so CLI and service share the geometry and kernel caches
    from engine.geometry.cache import cache_root

    return cache_root()


def _physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


class Settings(BaseSettings):
    """The job service's settings; one instance per process (see :func:`get_settings`)."""

    model_config = SettingsConfigDict(env_prefix="VOXELASTIC_", extra="ignore")

    # --- storage --------------------------------------------------------------------------------
    data_dir: Path = Field(default_factory=_default_data_dir, description="Uploads, results and the SQLite job table.")
    cache_dir: Path = Field(default_factory=_default_cache_dir, description="Geometry and Taichi kernel caches.")
    geometry_cache: bool = Field(True, description="Reuse cut-cell geometry of a repeated mesh + grid.")
    database_url: str | None = Field(
        None, description="SQLAlchemy URL of the job table; default SQLite at <data_dir>/jobs.db."
    )

    # --- execution ------------------------------------------------------------------------------
    queue: Literal["local", "celery"] = Field("local", description="local worker processes, or Celery workers.")
    broker_url: str = Field("redis://localhost:6379/0", description="Celery broker (queue=celery).")
    workers: int = Field(default_factory=lambda: os.cpu_count() or 1, ge=1, le=256, description="Local pool size.")
    arch: Literal["cpu", "cuda", "auto"] = Field("auto", description="Taichi backend of the workers (jobs saying 'auto').")
    precision: Literal["f64", "f32"] = Field("f64", description="Precision workers start with.")
    worker_nice: int = Field(
        10, ge=0, le=19, description="Niceness of worker processes, so the API stays responsive while they compute."
    )
    api_nice: int = Field(
        -10, ge=-20, le=0, description="Niceness the API process raises itself to at start where permitted "
        "(CAP_SYS_NICE or RLIMIT_NICE), so status requests are answered while other processes hold every core; "
        "workers run worker_nice below it."
    )
    max_attempts: int = Field(3, ge=1, le=20, description="Runs of a job before a lost worker fails it.")

    # --- limits ---------------------------------------------------------------------------------
    max_upload_bytes: int = Field(64 * 2**20, ge=1, description="Largest request body of POST /jobs (413 above).")
    max_spec_bytes: int = Field(
        4 * 2**20, ge=1024, description="Largest job spec, as a text field or a file part (413 above). Every status "
        "poll returns the spec; the largest real specs (thousands of probes) are some hundred kB."
    )
    max_triangles: int = Field(5_000_000, ge=1, description="Largest mesh (facets) accepted.")
    max_cells: int = Field(2**28, ge=1, description="Largest background grid (cells) accepted.")
    max_job_memory_bytes: int | None = Field(
        None, ge=1, description="Largest memory estimate of a job accepted (422 above); default worker_memory_bytes."
    )
    worker_memory_bytes: int | None = Field(
        None, ge=1, description="Resident memory at which a worker process is stopped and its job failed; "
        "default: a fair share, 80 % of physical memory / workers."
    )
    job_time_limit: float = Field(3600.0, gt=0, description="Wall time of one job attempt [s].")
    max_queued: int = Field(1000, ge=1, description="Queued jobs at which POST /jobs answers 429.")
    max_inflated_bytes: int | None = Field(
        None, ge=1, description="Largest size a compressed or archived mesh may inflate to (413 above); "
        "default 4 x max_upload_bytes."
    )
    admission_memory_bytes: int = Field(
        3 * 2**30, ge=64 * 2**20, description="Address space the process checking a submission may add "
        "(it reads the spec and the mesh apart from the API process; 413 above)."
    )
    admission_time_limit: float = Field(120.0, gt=0, description="Wall time to check one submission [s] (422 above).")

    preview_renders: int = Field(1, ge=1, le=64, description="Preview pictures rendered at once (each a "
                                 "process importing VTK); further requests wait their turn.")
    preview_wait: float = Field(20.0, gt=0, description="How long a preview request waits for its turn "
                                "before 503 + Retry-After [s].")

    # --- access ---------------------------------------------------------------------------------
    tokens: Annotated[list[str], NoDecode] = Field(
        default_factory=list, repr=False, description="Bearer tokens (comma-separated); empty = no authentication."
    )
    admin_tokens: Annotated[list[str], NoDecode] = Field(
        default_factory=list, repr=False, description="Bearer tokens that see and manage every tenant's jobs "
        "(comma-separated; they also authenticate)."
    )

    # --- server ---------------------------------------------------------------------------------
    host: str = Field("127.0.0.1", description="voxelastic serve: bind address.")
    port: int = Field(8000, ge=0, le=65535, description="voxelastic serve: port.")

    @field_validator("tokens", "admin_tokens", mode="before")
    @classmethod
    def _split_tokens(cls, value: object) -> object:
        # a comma-separated environment variable; JSON lists would force quoting secrets in shells
        if isinstance(value, str):
            return [t.strip() for t in value.split(",") if t.strip()]
        return value

    @model_validator(mode="after")
    def _defaults(self) -> Settings:
        if self.worker_memory_bytes is None:
            self.worker_memory_bytes = int(0.8 * _physical_memory() / self.workers)
        if self.max_job_memory_bytes is None:
            self.max_job_memory_bytes = self.worker_memory_bytes
        if self.max_inflated_bytes is None:
            self.max_inflated_bytes = 4 * self.max_upload_bytes
        return self

    @property
    def auth_enabled(self) -> bool:
        """Whether requests need a bearer token (and jobs belong to the token that submitted them)."""
        return bool(self.tokens or self.admin_tokens)

    @property
    def db_url(self) -> str:
        """The job table's URL (SQLite in the data directory unless configured)."""
        return self.database_url or f"sqlite:///{(self.data_dir / 'jobs.db').resolve()}"

    @property
    def heartbeat_stale_after(self) -> float:
        """A running job whose supervisor has been silent this long is considered lost [s]."""
        return 60.0

    @property
    def visibility_timeout(self) -> int:
        """Celery/Redis redelivers an unacknowledged job after this long: above the longest job."""
        return int(self.job_time_limit + 600)


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings read from the environment (cached)."""
    return Settings()
