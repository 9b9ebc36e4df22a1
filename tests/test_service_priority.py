"""CPU priority of the service's processes (issue 18 item 5): the API process raises itself to
VOXELASTIC_API_NICE where permitted and its worker processes run VOXELASTIC_WORKER_NICE below
it, so status requests are answered while jobs and other processes hold every core (the
latency figure under CPU hogs is in docs/benchmarks.md, from benchmarks/service.py --hog)."""

from __future__ import annotations

import os

import psutil
import pytest
from service_helpers import Server, shared_cache_dir


def _can_raise(nice: int) -> bool:
    pid = os.fork()
    if pid == 0:  # try in a child: a raised priority cannot be lowered back without privilege
        try:
            os.setpriority(os.PRIO_PROCESS, 0, nice)
            os._exit(0)
        except OSError:
            os._exit(1)
    return os.waitpid(pid, 0)[1] == 0


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = Server(tmp_path_factory.mktemp("priority") / "data", shared_cache_dir(tmp_path_factory), workers=2,
                 api_nice=-7, worker_nice=9)
    srv.start()
    yield srv
    srv.close()


def test_api_outranks_its_workers_and_other_work(server):
    api = psutil.Process(server.proc.pid)
    workers = [p for p in api.children() if "spawn_main" in " ".join(p.cmdline())]
    assert len(workers) == 2
    base = os.getpriority(os.PRIO_PROCESS, 0)  # what any other process started here gets
    if _can_raise(-7):
        assert api.nice() == -7 and api.nice() < base
        assert "API at niceness -7" in server.log()
    else:  # unprivileged: it stays and says why
        assert api.nice() == base
        assert "raising it to -7 was refused" in server.log()
    for worker in workers:
        assert worker.nice() == api.nice() + 9  # the computing thread; Taichi's threads inherit it
