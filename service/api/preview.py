"""The preview picture of a result: rendered once per job in a child process, few at a time.

Each render is a process importing VTK (2-3 s and some hundred MB for the bundled example), so
concurrent first requests must not each start one: at most ``preview_renders`` run at once, a
request waits up to ``preview_wait`` seconds for its turn, and a few waiters at most are held
(each holds one of the API's worker threads, which every other sync route needs too). The rest
get 503 with Retry-After.
"""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

from fastapi import HTTPException, status

log = logging.getLogger("voxelastic.preview")

PREVIEW_SECONDS = 120  # rendering the bundled example takes 2-3 s; a huge surface may take longer
MAX_WAITING = 8
RETRY_AFTER = 5  # seconds: about two renders of a usual job


class RenderGate:
    """At most ``renders`` renders at once; a caller waits ``wait`` seconds for a turn."""

    def __init__(self, renders: int, wait: float):
        self.slots = threading.BoundedSemaphore(renders)
        self.wait = wait
        self._waiting = 0
        self._lock = threading.Lock()

    def render(self, result: Path, picture: Path) -> None:
        """Render ``picture`` unless it exists (another request may have made it while this one
        waited); HTTP 503 + Retry-After when no turn comes in time."""
        with self._lock:
            full = self._waiting >= MAX_WAITING
            if not full:
                self._waiting += 1
        got = False
        if not full:
            try:
                got = self.slots.acquire(timeout=self.wait)
            finally:
                with self._lock:
                    self._waiting -= 1
        if not got:
            raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, headers={"Retry-After": str(RETRY_AFTER)},
                                detail="other pictures are being rendered; retry in a few seconds "
                                       "(VOXELASTIC_PREVIEW_RENDERS at a time)")
        try:
            if not picture.is_file():
                _render(result, picture)
        finally:
            self.slots.release()


class RenderFailed(HTTPException):
    """503: the picture could not be rendered, the reason in words (no paths, no exception names)."""

    def __init__(self, reason: str):
        super().__init__(status.HTTP_503_SERVICE_UNAVAILABLE, detail=f"the picture could not be rendered: {reason}")


def _reason(code: int, stderr: str) -> str:
    """What the renderer said, when it said it in words: ``engine.preview`` exits 2 with one line
    "error: ..." for a result it cannot draw; anything else (a crash, a traceback) is logged and
    answered without its text, which names server paths and exception classes."""
    last = (stderr.strip().splitlines() or [""])[-1]
    if code == 2 and last.startswith("error: ") and not _PATHLIKE.search(last):
        return last.removeprefix("error: ")
    log.warning("preview renderer exited with status %s: %s", code, stderr.strip()[-2000:])
    return f"the renderer stopped (exit status {code}); the server log has the details"


_PATHLIKE = re.compile(r"(^|[\s'\"(=])/[^\s]")


def _render(result: Path, picture: Path) -> None:
    """Render the picture once, beside the result (cached with it, deleted with it), in a child
    process: VTK's memory and time never land in the API process or a job's worker limits."""
    tmp = picture.with_name(f".{picture.stem}.{os.getpid()}.{threading.get_ident()}.tmp.png")  # PNG by its suffix
    try:
        out = subprocess.run([sys.executable, "-m", "engine.preview", str(result), str(tmp)], capture_output=True,
                             text=True, timeout=PREVIEW_SECONDS)
        if out.returncode != 0 or not tmp.is_file():
            raise RenderFailed(_reason(out.returncode, out.stderr))
        os.replace(tmp, picture)
    except OSError as exc:  # the job's directory went away meanwhile (deleted), or the disk is full
        log.warning("preview of %s: %s", result.parent.parent.name, exc)
        raise RenderFailed("the picture could not be stored") from None
    except subprocess.TimeoutExpired:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE,
                            detail=f"the picture could not be rendered in {PREVIEW_SECONDS} s") from None
    finally:
        tmp.unlink(missing_ok=True)
