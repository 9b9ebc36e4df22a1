"""Durability: ``kill -9`` of the server mid-job, then a restart, ends with the job succeeded; a
graceful stop hands the running job back without counting an attempt; no worker outlives its
server; a second server on the same data directory is refused."""

from __future__ import annotations

import signal
import subprocess
import sys

from service_helpers import ROOT, Server, cantilever, gone, shared_cache_dir, worker_pid


def _job() -> dict:
    # a few seconds, most of them solving: long enough to be caught mid-run
    return cantilever(72)


def test_server_kill_9_and_restart_recovers_the_job(tmp_path_factory):
    data = tmp_path_factory.mktemp("recovery") / "data"
    cache = shared_cache_dir(tmp_path_factory)
    first = Server(data, cache, workers=1).start()
    try:
        job_id = first.submit_ok(_job())
        pid = worker_pid(first.wait_running(job_id))
        assert first.stop(signal.SIGKILL) == -signal.SIGKILL
        assert gone(pid), "the worker process outlived its killed server"
    finally:
        first.close()

    second = Server(data, cache, workers=1)
    try:
        second.start()
        done = second.wait(job_id, timeout=180)
        assert done["status"] == "succeeded", done
        assert done["attempts"] == 2
        assert any("attempt 1 interrupted" in w for w in done["warnings"]), done["warnings"]
        assert second.client.get(f"/jobs/{job_id}/result").status_code == 200

        # a graceful stop (SIGTERM) releases the running job: it runs again, the attempt not counted
        job_id = second.submit_ok(_job())
        pid = worker_pid(second.wait_running(job_id))
        assert second.stop(signal.SIGTERM) in (0, -signal.SIGTERM)  # uvicorn re-raises the signal it handled
        assert gone(pid)
    finally:
        second.close()

    third = Server(data, cache, workers=1)
    try:
        third.start()
        # while it runs, a second server on the same data directory is refused with a clear message
        refused = subprocess.run([sys.executable, "-m", "engine.cli", "serve", "--port", "0"], cwd=ROOT,
                                 env=third.env(), capture_output=True, text=True, timeout=60)
        assert refused.returncode == 2 and "another voxelastic server" in refused.stderr
        done = third.wait(job_id, timeout=180)
        assert done["status"] == "succeeded", done
        assert done["attempts"] == 1
        assert any("interrupted by a server shutdown" in w for w in done["warnings"]), done["warnings"]
    finally:
        third.close()
