"""What runs inside a worker process: Taichi initialised once, then jobs one after another.

The process is started with the *spawn* method (never fork after a CUDA context exists) by
:class:`service.worker.WorkerProcess`; it talks to its parent over a pipe:

    child -> parent   ("ready", info) once, after ``engine.runtime.init``
                      ("progress", stage, fraction, info) while a job runs (throttled)
                      ("done", summary) | ("error", kind, message) when it ends
    parent -> child   Task to run, or None to exit

The child writes the result into the attempt's staging directory (``engine.output.write_result``
writes each file under a temporary name and renames it); publishing it and marking the job
succeeded is the parent's business. Only engine modules import Taichi.
"""

from __future__ import annotations

import importlib
import os
import shutil
import signal
import sys
import threading
import time
import traceback
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from .faults import ERROR_KIND, describe, is_storage_fault

# progress messages closer together than this are merged (the newest wins); stage changes always go
PROGRESS_INTERVAL = 0.1


@dataclass(frozen=True)
class Task:
    """One attempt of a job, as sent to a worker process (plain data: it crosses a pipe)."""

    job_id: str
    attempt: int
    spec: str  # canonical JSON of the validated spec
    mesh_path: str | None  # the stored upload (None for a 2D polygon)
    filename: str  # name with the upload's suffix: the engine reads the format from it
    staging_dir: str
    result_name: str
    arch: str  # what the worker was initialised with; replaces the spec's (see service.worker)
    geometry_cache: str | None
    max_cells: int
    max_memory_bytes: int
    max_triangles: int


def _watch_parent(parent: int) -> None:
    # A killed server must not leave orphans computing: exit as soon as the parent is gone.
    while True:
        if os.getppid() != parent:
            os._exit(3)
        time.sleep(0.5)


def _die_with_parent() -> None:
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            PR_SET_PDEATHSIG = 1
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        except OSError:
            pass  # the watcher thread still covers it
    threading.Thread(target=_watch_parent, args=(os.getppid(),), daemon=True, name="parent-watch").start()


def worker_main(conn: Connection, arch: str, precision: str, cache_dir: str, nice: int) -> None:
    """Entry point of a worker process: initialise Taichi once, then serve tasks until told to stop."""
    _die_with_parent()
    # Ctrl-C in a terminal reaches the whole process group; the server stops its workers itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if nice:
        try:
            os.nice(nice)
        except OSError:
            pass
    try:
        from engine.runtime import init, save_kernel_cache

        info = init(arch, precision, cache_dir=Path(cache_dir) / "gstaichi")
        preload()
    except BaseException as exc:  # an unusable backend: say so instead of dying silently
        conn.send(("init_error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", {"pid": os.getpid(), "arch": info.arch, "precision": info.precision}))
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        outcome = run_task(task, _Reporter(conn))
        save_kernel_cache()  # before the answer: a worker stopped after it keeps what it compiled
        conn.send(outcome)


def preload() -> None:
    """Import what every job imports (the pipeline with trimesh and scipy's spatial parts, both
    methods, the result writer) before the worker says it is ready: 0.6 s of a worker's start that
    its first job paid before (docs/benchmarks.md, "Cold start"). What stays for the first job is
    the first launch of each kernel it uses."""
    for module in ("engine.pipeline", "engine.output", "engine.peaks", "engine.staggered.elasticity", "engine.dg.elasticity"):
        importlib.import_module(module)


class _Reporter:
    """The engine's progress callback: forwards (stage, fraction, info) to the parent, throttled."""

    def __init__(self, conn: Connection):
        self.conn, self.stage, self.last = conn, None, 0.0

    def __call__(self, stage: str, fraction: float, info: dict) -> None:
        now = time.monotonic()
        if stage == self.stage and now - self.last < PROGRESS_INTERVAL:
            return
        self.stage, self.last = stage, now
        self.conn.send(("progress", stage, float(fraction), _plain(info)))


def _plain(info: dict) -> dict[str, Any]:
    """JSON-safe copy of a progress info dict (numpy scalars -> Python numbers)."""
    out: dict[str, Any] = {}
    for key, value in info.items():
        if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
            value = value.item()
        if isinstance(value, (bool, int, float, str)) or value is None:
            out[str(key)] = value
        elif isinstance(value, (list, tuple)):
            out[str(key)] = [v.item() if hasattr(v, "item") else v for v in value]
    return out


def run_task(task: Task, progress) -> tuple:
    """Run one attempt; returns ("done", summary) or ("error", kind, message)."""
    from engine.errors import VoxelasticError
    from engine.geometry.cache import GeometryCache
    from engine.output import outside_probes_warning, write_result
    from engine.peaks import peaks
    from engine.pipeline import Limits, run
    from schemas import SpecError, parse_job

    t0 = time.perf_counter()
    try:
        spec = parse_job(task.spec)
        # the worker's Taichi runtime is fixed; the job asked for it (see service.worker.runtime_key)
        spec = spec.model_copy(update={"solver": spec.solver.model_copy(update={"arch": task.arch})})
        mesh = Path(task.mesh_path).read_bytes() if task.mesh_path else None
        result = run(
            spec,
            mesh,
            filename=task.filename,
            progress=progress,
            cache=GeometryCache(task.geometry_cache),
            limits=Limits(max_cells=task.max_cells, max_memory_bytes=task.max_memory_bytes, max_triangles=task.max_triangles),
        )
        note = outside_probes_warning(result)
        if note and result.solver is not None:
            result.solver.warnings.append(note)
        staging = Path(task.staging_dir)
        t_write = time.perf_counter()
        try:
            staging.mkdir(parents=True, exist_ok=True)
            path = write_result(result, staging / task.result_name)
        except OSError as exc:
            # a full disk, a file-size limit, a quota, a permission: the same on every retry, and
            # the user's job is not at fault; say which (engine.output keeps HDF5 usable after it)
            shutil.rmtree(staging, ignore_errors=True)
            if not is_storage_fault(exc):
                raise
            return ("error", ERROR_KIND, describe(exc, "the result"))
        report = result.solver
        stage_times = dict(report.stage_times) if report else {}
        stage_times["write"] = time.perf_counter() - t_write
        summary = {
            "iterations": int(report.iterations) if report else None,
            "residual": float(report.residual) if report else None,
            "stage_times": stage_times,
            "warnings": list(report.warnings) if report else [],
            "result_bytes": path.stat().st_size,
            "seconds": time.perf_counter() - t0,
            "grid": list(result.grid.shape),
            "peak": {place: peak.as_dict() for place, peak in peaks(result).items()},
        }
        return ("done", summary)
    except SpecError as exc:
        return ("error", "input", "; ".join(exc.errors))
    except VoxelasticError as exc:  # bad input found while running, or a method not available yet
        return ("error", "input", str(exc))
    except MemoryError:
        return ("error", "limit", "the job ran out of memory in its worker process; use a coarser grid")
    except Exception as exc:  # a bug: keep the worker alive, tell the user plainly, log the trace
        if is_storage_fault(exc):  # a working file on the way (the geometry cache): the server's disk
            return ("error", ERROR_KIND, describe(exc, "a working file of the job (mesh copy, geometry cache)"))
        traceback.print_exc(file=sys.stderr)
        return ("error", "internal", f"internal error: {type(exc).__name__}: {exc}")
