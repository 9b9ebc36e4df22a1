"""Run an untrusted-input check in a short-lived child process with an address-space limit.

Reading a submission is where hostile bytes get to allocate: a 785-byte bzip2 inflates to a
gigabyte, a JSON spec of 60 MB of numbers becomes a gigabyte of Python objects, a loader may
build arrays from sizes a header merely declares. Done in the API process, any of these grows it
for good (CPython keeps most of the freed memory). Done here, it grows a child that the kernel
stops at ``memory_bytes`` above its starting size (``RLIMIT_AS``: allocations fail with
MemoryError instead of swapping the machine) and that exits when the check is done.

Children are forked from a *forkserver* that imported the engine once (about a second), so
each check starts in milliseconds and from a process that never ran a request: no lock held by
another thread of the API process can be inherited. At most ``os.cpu_count()`` (at least 2)
checks run at once; further requests wait for a slot (at most ``MAX_WAITING`` of them, for at most
``WAIT`` seconds: then :class:`SandboxBusy`, a 503 with Retry-After). As with every multiprocessing start method
but fork, a child imports the parent's ``__main__`` module again (as ``__mp_main__``): a program
that starts the service must keep its start-up under ``if __name__ == "__main__"`` (``voxelastic
serve``, ``python -m engine.cli serve`` and uvicorn's own entry point do).
"""

from __future__ import annotations

import logging
import math
import multiprocessing as mp
import os
import pickle
import resource
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

log = logging.getLogger("voxelastic.sandbox")

_CTX = mp.get_context("forkserver")
# imported once in the forkserver; every child starts with them loaded
_PRELOAD = ["numpy", "trimesh", "schemas", "engine.pipeline", "engine.geometry.loading", "service.admission"]
_SLOTS = threading.BoundedSemaphore(max(2, os.cpu_count() or 1))
# Each waiting check holds one of the API's 40 threads (the ones that serve the other sync routes
# too): a burst of slow submissions must neither hold them all nor wait without end. Past
# MAX_WAITING waiters, or after WAIT seconds, the check is refused with SandboxBusy (503); 24 lets
# a burst of 20 small submissions through and leaves a dozen threads to everything else.
MAX_WAITING = 24
WAIT = 30.0
_waiting = 0
_waiting_lock = threading.Lock()
_mean_seconds = 1.0  # running mean of a check's duration, for Retry-After
_CTX.set_forkserver_preload(_PRELOAD)  # before the forkserver starts, whoever starts it


class SandboxTimeout(Exception):
    """The check ran past its wall-time limit and was killed."""


class SandboxMemory(Exception):
    """The check needed more memory than its limit."""


class SandboxBusy(Exception):
    """Every check slot stayed busy: ``retry_after`` [s] is a guess of when one frees up."""

    def __init__(self, retry_after: int, waited: float):
        super().__init__(f"no admission slot free after {waited:g} s")
        self.retry_after, self.waited = retry_after, waited


class SandboxCrashed(Exception):
    """The child died without an answer (a signal from native code, typically)."""

    def __init__(self, detail: str):
        super().__init__(detail)
        self.detail = detail


def start() -> None:
    """Start the forkserver and import the engine in it, so that the first check is fast too."""
    from multiprocessing import forkserver

    forkserver.ensure_running()


def _virtual_size() -> int:
    """This process's address-space size [bytes] (VmSize), 0 if unknown."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _child(conn, fn: Callable[..., Any], args: tuple, memory_bytes: int) -> None:
    # the limit counts from where this process starts: the preloaded engine is already mapped
    limit = _virtual_size() + memory_bytes
    try:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ValueError, OSError):
        log.warning("could not limit the address space of the admission check to %d bytes", limit)
    try:
        outcome: tuple = ("ok", fn(*args))
    except MemoryError:
        outcome = ("memory", None)
    except BaseException as exc:  # noqa: BLE001 - every outcome goes back to the API process
        try:
            pickle.loads(pickle.dumps(exc))  # it must arrive as itself, or not at all
            outcome = ("raised", exc)
        except Exception:  # noqa: BLE001
            outcome = ("crashed", f"{type(exc).__name__} in the check")
        if outcome[0] == "crashed" or not getattr(exc, "expected", False):
            log.error("admission check failed", exc_info=exc)
    try:
        conn.send(outcome)
    except MemoryError:
        conn.send(("memory", None))
    except Exception as exc:  # noqa: BLE001 - an exception that cannot be pickled
        conn.send(("crashed", f"{type(exc).__name__} while returning the result"))
    conn.close()


def run_limited(fn: Callable[..., Any], args: tuple, *, memory_bytes: int, time_limit: float) -> Any:
    """``fn(*args)`` in a fresh child process; its return value, or its exception re-raised here.

    Raises :class:`SandboxTimeout`, :class:`SandboxMemory` or :class:`SandboxCrashed` for a child
    that ran too long, ran out of its memory limit or died, :class:`SandboxBusy` when no check
    slot came free in time. ``fn`` must be importable by name.
    """
    _acquire()
    started = time.monotonic()
    try:
        kind, value = _run_child(fn, args, memory_bytes, time_limit)
    finally:
        _SLOTS.release()
        _record(time.monotonic() - started)
    if kind == "ok":
        return value
    if kind == "memory":
        raise SandboxMemory(f"over {memory_bytes} bytes")
    if kind == "raised":
        # a local naming the exception would put this frame, the frames below it in the traceback
        # and their locals (the upload itself) in a reference cycle that only the collector frees
        try:
            raise value
        finally:
            del value
    raise SandboxCrashed(str(value))


def _acquire(wait: float | None = None) -> None:
    """Take a check slot, waiting at most ``wait`` seconds (``WAIT``) behind at most ``MAX_WAITING``
    others; SandboxBusy otherwise."""
    global _waiting
    wait = WAIT if wait is None else wait
    if _SLOTS.acquire(blocking=False):
        return
    with _waiting_lock:
        full = _waiting >= MAX_WAITING
        if not full:
            _waiting += 1
        ahead = _waiting
    if full:
        raise SandboxBusy(_retry_after(ahead), 0.0)
    try:
        if _SLOTS.acquire(timeout=wait):
            return
    finally:
        with _waiting_lock:
            _waiting -= 1
    raise SandboxBusy(_retry_after(ahead), wait)


def _record(seconds: float) -> None:
    global _mean_seconds
    _mean_seconds = 0.8 * _mean_seconds + 0.2 * seconds


def _retry_after(ahead: int) -> int:
    """Seconds until the checks ahead are likely done: their number x mean duration / slots."""
    slots = max(2, os.cpu_count() or 1)
    return int(min(120, max(1, math.ceil(_mean_seconds * (ahead + 1) / slots))))


def _run_child(fn: Callable[..., Any], args: tuple, memory_bytes: int, time_limit: float) -> tuple[str, Any]:
    receiver, sender = _CTX.Pipe(duplex=False)
    proc = _CTX.Process(target=_child, args=(sender, fn, args, memory_bytes), daemon=True)
    proc.start()
    sender.close()
    try:
        if not receiver.poll(time_limit):
            proc.kill()
            raise SandboxTimeout(f"no answer in {time_limit:g} s")
        try:
            kind, value = receiver.recv()
        except (EOFError, OSError, pickle.UnpicklingError):
            proc.join(5)
            code = proc.exitcode
            raise SandboxCrashed(_describe_exit(code)) from None
    finally:
        receiver.close()
        proc.join(5)
        if proc.is_alive():
            proc.kill()
            proc.join(5)
    return kind, value


def _describe_exit(code: int | None) -> str:
    if code is not None and code < 0:
        try:
            return f"stopped by {signal.Signals(-code).name}"
        except ValueError:
            return f"stopped by signal {-code}"
    return f"exited with status {code}"
