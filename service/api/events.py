"""Server-sent events of a job: a snapshot whenever it changes, until it ends.

Works the same for both queue backends because it follows the job table (the ``revision`` column
moves with every change), not an in-process channel: a Celery worker on another machine updates
the row, the API streams it. Event ids are revisions, so a client reconnecting with
``Last-Event-ID`` gets only what it has not seen.

    event: progress            (queued / running snapshots)
    id: 7
    data: {...GET /jobs/{id} as JSON, without "spec"...}

    event: end                 (the terminal snapshot; then the stream closes)

    event: error               (the job table unavailable for 30 s; then the stream closes)
"""

from __future__ import annotations

import asyncio
import json
import re
import time
from collections.abc import AsyncIterator

from .models import job_out, output_surface
from .reads import read
from ..store import DATABASE_DOWN, JobStore

POLL = 0.2  # seconds between looks at the row
KEEPALIVE = 15.0  # a comment line this often keeps proxies from closing an idle stream
DOWN_LIMIT = 30.0  # seconds of an unavailable job table after which a stream ends with an error event


def _snapshot(job, surface: bool | None = None) -> str:
    # the job as GET /jobs/{id} shows it, less the spec: that never changes and is the bulk of it
    return job_out(job, surface=surface).model_dump_json(exclude={"spec"})


def last_seen(header: str | None) -> int | None:
    """The revision a reconnecting client saw, from its Last-Event-ID; None (send everything) for
    anything that is not one of our ids: a client may send ``null`` or an id of another stream."""
    value = (header or "").strip()
    return int(value) if re.fullmatch(r"[0-9]{1,18}", value) else None


def format_event(event: str, data: str, event_id: int | None = None) -> str:
    lines = [f"event: {event}"]
    if event_id is not None:
        lines.append(f"id: {event_id}")
    lines += [f"data: {line}" for line in data.splitlines() or [""]]
    return "\n".join(lines) + "\n\n"


async def job_events(store: JobStore, job_id: str, last_seen: int | None = None) -> AsyncIterator[str]:
    """Yield SSE frames for ``job_id`` until it reaches a terminal status (or is deleted)."""
    last, quiet_since = last_seen, time.monotonic()
    down_since: float | None = None
    yield "retry: 1000\n\n"
    while True:
        # without the spec: it never changes, and reading a large one 5 times a second per stream
        # took the API's CPU (issue: 5 streams of a 28 MB spec, 89 %)
        try:
            job = await read(store.get, job_id, with_spec=False)
        except DATABASE_DOWN:
            # a database restart is a pause of the stream, not its end; a long outage ends it in words
            down_since = down_since or time.monotonic()
            if time.monotonic() - down_since > DOWN_LIMIT:
                yield format_event("error", json.dumps({"detail": "the job table is unavailable (the database "
                                                                  "does not answer); reconnect later"}))
                return
            await asyncio.sleep(1.0)
            continue
        down_since = None
        if job is None:
            yield format_event("deleted", json.dumps({"id": job_id}))
            return
        if job.terminal:
            surface = None
            if job.status == "succeeded":  # its result links depend on output.surface: read once
                surface = output_surface(await read(store.spec_of, job_id))
            yield format_event("end", _snapshot(job, surface), job.revision)
            return
        if job.revision != last:
            last, quiet_since = job.revision, time.monotonic()
            yield format_event("progress", _snapshot(job), job.revision)
        elif time.monotonic() - quiet_since > KEEPALIVE:
            quiet_since = time.monotonic()
            yield ": keep-alive\n\n"
        await asyncio.sleep(POLL)
