"""Celery scale-out against real servers: Redis as the broker, PostgreSQL for the job table (both
started by .ci/run, or privately here when their binaries exist), the API with
``VOXELASTIC_QUEUE=celery`` and a real ``celery -A service.celery_app worker`` process."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import time

import h5py
import pytest
from service_helpers import ROOT, Server, cantilever, gone, long_job, shared_cache_dir, start_backing, worker_pid


@pytest.fixture(scope="module")
def backing(tmp_path_factory):
    found = start_backing(tmp_path_factory.mktemp("backing"))
    if isinstance(found, str):
        pytest.skip(found)
    yield found
    found.close()


@pytest.fixture(scope="module")
def service(backing, tmp_path_factory):
    import redis
    from service.db import Base, make_engine

    engine = make_engine(backing.database_url)  # a clean job table in the test database
    Base.metadata.drop_all(engine)
    engine.dispose()
    redis.Redis.from_url(backing.broker_url).flushdb()

    shared = tmp_path_factory.mktemp("celery") / "shared"  # results on a directory both sides see
    api = Server(shared, shared_cache_dir(tmp_path_factory), queue="celery",
                 database_url=backing.database_url, broker_url=backing.broker_url)
    api.start()
    log = open(shared.parent / "celery-worker.log", "ab")
    worker = subprocess.Popen(
        [sys.executable, "-m", "celery", "-A", "service.celery_app", "worker", "--loglevel", "info",
         "--hostname", f"vx-test-{api.port}@%h"],
        cwd=ROOT, env=api.env(), stdout=log, stderr=subprocess.STDOUT,
    )
    api.worker_log = shared.parent / "celery-worker.log"
    yield api
    worker.send_signal(signal.SIGTERM)
    try:
        worker.wait(30)
    except subprocess.TimeoutExpired:
        worker.kill()
        worker.wait(10)
    api.close()


def _diagnose(api) -> str:
    return api.log()[-2000:] + "\n--- worker ---\n" + api.worker_log.read_text(errors="replace")[-4000:]


def test_health_checks_the_broker_and_the_database(service):
    health = service.client.get("/health").json()
    assert health["status"] == "ok" and health["database"] == "ok"
    assert health["queue"]["backend"] == "celery" and health["queue"]["broker_status"] == "ok"


def test_a_job_runs_on_a_celery_worker_with_the_table_in_postgresql(service, backing):
    from service.store import JobStore

    job_id = service.submit_ok(cantilever(16))
    done = service.wait(job_id, timeout=180)
    assert done["status"] == "succeeded", _diagnose(service)
    r = service.client.get(f"/jobs/{job_id}/result")
    assert r.status_code == 200 and int(r.headers["content-length"]) == done["result"]["bytes"]
    with h5py.File(io.BytesIO(r.content)) as f:
        assert -0.06 < f["probes/displacement"][0, 2] < -0.02
    # the row lives in PostgreSQL, the source of truth (not Celery's result backend)
    store = JobStore(backing.database_url)
    try:
        assert store.engine.dialect.name == "postgresql"
        assert store.get(job_id).status == "succeeded"
    finally:
        store.close()
    # the worker process runs on the Celery worker's machine, not in the API server
    assert worker_pid(done) not in {p.pid for p in service.children()}


def test_cancel_stops_the_job_process_on_the_celery_worker(service):
    job_id = service.submit_ok(long_job())
    pid = worker_pid(service.wait_running(job_id, stage=None, timeout=180))
    r = service.client.delete(f"/jobs/{job_id}")
    assert r.status_code in (200, 202)
    done = service.wait(job_id, timeout=30)
    assert done["status"] == "cancelled"
    assert gone(pid)


def test_kill_9_of_the_job_process_is_retried_by_the_worker(service):
    job_id = service.submit_ok(cantilever(72))
    pid = worker_pid(service.wait_running(job_id, timeout=180))
    os.kill(pid, signal.SIGKILL)
    done = service.wait(job_id, timeout=180)
    assert done["status"] == "succeeded", _diagnose(service)
    assert done["attempts"] == 2 and worker_pid(done) != pid
    assert any("was killed by SIGKILL" in w for w in done["warnings"])


def test_jobs_queue_up_behind_one_worker_and_all_finish(service):
    ids = [service.submit_ok(cantilever(16)) for _ in range(4)]
    t = time.monotonic()
    assert [service.wait(i, timeout=180)["status"] for i in ids] == ["succeeded"] * 4
    assert time.monotonic() - t < 120
