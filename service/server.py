"""``voxelastic serve``: uvicorn with the API, the job table and (by default) the local worker pool."""

from __future__ import annotations

import fcntl
import logging
import os
import sys
from pathlib import Path

from . import faults
from .settings import Settings


def _data_dir_free(settings: Settings) -> str | None:
    """None if no other server holds the data directory's lock, else a message saying who does."""
    path = Path(settings.data_dir) / "server.lock"
    if not path.exists():
        return None
    with open(path, "a+") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            return (f"another voxelastic server (pid {f.read().strip() or '?'}) uses {settings.data_dir}; "
                    "stop it or set VOXELASTIC_DATA_DIR")
        fcntl.flock(f, fcntl.LOCK_UN)
    return None


def raise_priority(nice: int) -> str:
    """Raise this process to niceness ``nice`` (before any thread starts: threads, and the worker
    processes started from them, inherit it); returns what is in effect, in words.

    Worker niceness alone keeps the API ahead of its own jobs, not of other work on the machine:
    with 4 CPU-bound processes at the default priority beside 2 jobs, status requests at 200/s
    reached p99 ~1 s on 2 cores (issue 18; docs/benchmarks.md). Raising needs CAP_SYS_NICE (root)
    or an RLIMIT_NICE that allows it (e.g. ``docker run --ulimit nice=25``); without either the
    API stays at its niceness and says so.
    """
    current = os.getpriority(os.PRIO_PROCESS, 0)
    if nice >= current:
        return f"niceness {current}"
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except OSError as exc:
        return (f"niceness {current} (raising it to {nice} was refused: {exc.strerror}; allow it with CAP_SYS_NICE "
                "or RLIMIT_NICE, or set VOXELASTIC_API_NICE=0)")
    return f"niceness {os.getpriority(os.PRIO_PROCESS, 0)}"


def serve(host: str | None = None, port: int | None = None, log_level: str = "info") -> int:
    """Run the service in the foreground until SIGINT/SIGTERM; returns an exit code."""
    import uvicorn

    from .api.app import create_app

    settings = Settings()
    host = host or settings.host
    port = settings.port if port is None else port
    if settings.queue == "local":
        busy = _data_dir_free(settings)
        if busy:
            print(f"error: {busy}", file=sys.stderr)
            return 2
    logging.basicConfig(level=getattr(logging, log_level.upper(), logging.INFO),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    priority = raise_priority(settings.api_nice)
    print(f"voxelastic service on http://{host}:{port} (queue={settings.queue}, workers={settings.workers}, "
          f"data={settings.data_dir}, auth={'on' if settings.auth_enabled else 'off'}, API at {priority}, "
          f"workers {settings.worker_nice} below); API docs at /docs", file=sys.stderr, flush=True)
    # one uvicorn process: the local pool lives in it (more API processes would each start a pool)
    app = create_app(settings)
    faults.install(app)  # 507 naming the cause when an upload cannot be stored (issue 18)
    uvicorn.run(app, host=host, port=port, log_level=log_level, access_log=False,
                timeout_graceful_shutdown=10)
    return 0
