"""The preview picture of a result: rendered once per job in a child process, few at a time.

Each render is a process importing VTK (2-3 s and some hundred MB for the bundled example), so
concurrent first requests must not each start one: at most ``preview_renders`` run at once, a
request waits up to ``preview_wait`` seconds for its turn, and a few waiters at most are held
(each holds one of the API's worker threads, which every other sync route needs too). The rest
get 503 with Retry-After.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

from fastapi import HTTPException, status

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


def _render(result: Path, picture: Path) -> None:
    """Render the picture once, beside the result (cached with it, deleted with it), in a child
    process: VTK's memory and time never land in the API process or a job's worker limits."""
    tmp = picture.with_name(f".{picture.stem}.{os.getpid()}.{threading.get_ident()}.tmp.png")  # PNG by its suffix
    try:
        out = subprocess.run([sys.executable, "-m", "engine.preview", str(result), str(tmp)], capture_output=True,
                             text=True, timeout=PREVIEW_SECONDS)
        if out.returncode != 0 or not tmp.is_file():
            reason = (out.stderr.strip().splitlines() or ["no output"])[-1]
            raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, detail=f"the picture could not be rendered: {reason}")
        os.replace(tmp, picture)
    except subprocess.TimeoutExpired:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE,
                            detail=f"the picture could not be rendered in {PREVIEW_SECONDS} s") from None
    finally:
        tmp.unlink(missing_ok=True)
