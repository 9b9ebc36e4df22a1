"""Prometheus text exposition of the service, computed from the job table at scrape time.

Gauges (jobs by status, queue length) come from the rows; counters (submitted, finished, the
duration histogram) from the monotonic counter table, so they survive restarts and deletions and
are right for every API replica and Celery worker alike.
"""

from __future__ import annotations

from typing import Any

from .store import DURATION_BUCKETS, TERMINAL, JobStatus, JobStore

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


def render(store: JobStore, queue_info: dict[str, Any], owner: str | None = None, everyone: bool = True) -> str:
    """The exposition; a tenant (not ``everyone``) gets its own jobs by status only: the counters,
    the queue and the workers are the whole server's, and would tell of the other tenants."""
    counts = store.counts(owner, everyone)
    out: list[str] = []

    def metric(name: str, kind: str, help_: str, samples: list[tuple[str, float]]) -> None:
        out.append(f"# HELP {name} {help_}")
        out.append(f"# TYPE {name} {kind}")
        out.extend(f"{name}{labels} {_num(value)}" for labels, value in samples)

    metric("voxelastic_jobs", "gauge", "Jobs in the job table by status" + ("." if everyone else " (this token's)."),
           [(f'{{status="{st.value}"}}', counts[st.value]) for st in JobStatus])
    if not everyone:
        return "\n".join(out) + "\n"
    counters = store.counters()
    metric("voxelastic_queue_length", "gauge", "Jobs waiting for a worker.", [("", counts["queued"])])
    metric("voxelastic_jobs_submitted_total", "counter", "Jobs accepted by POST /jobs.",
           [("", counters.get("submitted", 0.0))])
    metric("voxelastic_jobs_finished_total", "counter", "Jobs that reached a final status.",
           [(f'{{status="{st}"}}', counters.get(f"finished:{st}", 0.0)) for st in TERMINAL])
    samples = []
    for st in TERMINAL:
        for b in DURATION_BUCKETS:
            samples.append((f'_bucket{{status="{st}",le="{b:g}"}}', counters.get(f"duration_bucket:{st}:{b:g}", 0.0)))
        count = counters.get(f"duration_count:{st}", 0.0)
        samples.append((f'_bucket{{status="{st}",le="+Inf"}}', count))
        samples.append((f'_sum{{status="{st}"}}', counters.get(f"duration_sum:{st}", 0.0)))
        samples.append((f'_count{{status="{st}"}}', count))
    out.append("# HELP voxelastic_job_duration_seconds Wall time of a job's last attempt, by final status.")
    out.append("# TYPE voxelastic_job_duration_seconds histogram")
    out.extend(f"voxelastic_job_duration_seconds{suffix} {_num(v)}" for suffix, v in samples)
    if queue_info.get("backend") == "local":
        metric("voxelastic_workers", "gauge", "Local worker slots and their live processes.",
               [('{state="configured"}', queue_info.get("workers", 0)),
                ('{state="alive"}', queue_info.get("processes_alive", 0)),
                ('{state="busy"}', queue_info.get("running", 0))])
    return "\n".join(out) + "\n"


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else repr(float(v))
