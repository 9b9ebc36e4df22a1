"""/health tells the truth about the workers (issue 18 item 10): a server whose worker processes
cannot start (in the Docker image it was Taichi's missing libX11.so.6) answers 503 and says why,
where it used to answer "ok" with 0 processes alive while every job failed."""

from __future__ import annotations

import subprocess
import sys
import time

import httpx
from service_helpers import ROOT, Server, cantilever


def test_health_is_503_with_the_reason_when_no_worker_process_can_start(tmp_path):
    # a real start failure: the Taichi kernel cache directory cannot be created (a file is in the way)
    blocked = tmp_path / "cache-is-a-file"
    blocked.write_text("not a directory\n")
    srv = Server(tmp_path / "data", str(blocked), workers=1)
    log = open(srv.log_path, "ab")
    srv.proc = subprocess.Popen([sys.executable, "-m", "engine.cli", "serve", "--host", "127.0.0.1", "--port",
                                 str(srv.port), "--log-level", "warning"], cwd=ROOT, env=srv.env(), stdout=log,
                                stderr=subprocess.STDOUT)
    try:
        deadline, body, status = time.monotonic() + 120, {}, None
        while time.monotonic() < deadline:
            try:
                r = httpx.get(srv.url + "/health", timeout=5)
                status, body = r.status_code, r.json()
                if body.get("queue", {}).get("worker_error"):
                    break
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        assert status == 503, (status, body, srv.log()[-2000:])
        assert body["status"] == "unavailable" and body["database"] == "ok"
        assert body["queue"]["processes_alive"] == 0
        reason = body["queue"]["worker_error"]
        assert "failed to start" in reason and "cache-is-a-file" in reason, reason
        # what a job gets meanwhile: failed, with the same reason
        job = srv.wait(srv.submit_ok(cantilever(16)))
        assert job["status"] == "failed" and "failed to start" in job["error"], job
    finally:
        srv.close()


PRELOAD = """
import sys
from service import runner
jobs_import = ("trimesh", "engine.pipeline", "engine.staggered.elasticity", "engine.dg.elasticity", "engine.output")
before = [m for m in jobs_import if m in sys.modules]
runner.preload()
print(before, [m for m in jobs_import if m not in sys.modules])
"""


def test_a_worker_imports_what_jobs_import_before_it_says_it_is_ready():
    """The first job of a worker used to import the pipeline, trimesh and the methods itself: 1.07-1.15 s
    against 0.14-0.17 s for the next ones (the bundled cantilever at 16 cells, the worker's seconds);
    with them imported at the worker's start 0.55-0.61 s (docs/benchmarks.md, "Cold start")."""
    out = subprocess.run([sys.executable, "-c", PRELOAD], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[] []", out.stdout  # none before, all after
