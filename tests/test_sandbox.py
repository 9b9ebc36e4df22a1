"""The admission sandbox on its own: a child process per call, stopped by its address-space and
wall-time limits, its answer or its exception handed back, the caller's memory untouched."""

from __future__ import annotations

import os
import time

import pytest

from service.admission import Rejected
from service.sandbox import SandboxCrashed, SandboxMemory, SandboxTimeout, run_limited


def _allocate(size: int) -> int:
    return len(bytearray(size))


def _sleep(seconds: float) -> str:
    time.sleep(seconds)
    return "woke"


def _reject() -> None:
    raise Rejected(422, [{"loc": ["body", "mesh"], "msg": "not a mesh", "type": "value_error"}])


def _abort() -> None:
    os.abort()


def _pid() -> int:
    return os.getpid()


def test_answers_and_exceptions_come_back():
    assert run_limited(_allocate, (50 * 2**20,), memory_bytes=200 * 2**20, time_limit=30) == 50 * 2**20
    assert run_limited(_pid, (), memory_bytes=200 * 2**20, time_limit=30) != os.getpid()
    with pytest.raises(Rejected) as info:
        run_limited(_reject, (), memory_bytes=200 * 2**20, time_limit=30)
    assert info.value.status_code == 422 and info.value.errors[0]["msg"] == "not a mesh"


def test_limits_stop_the_child_not_the_caller():
    with pytest.raises(SandboxMemory):
        run_limited(_allocate, (2**30,), memory_bytes=200 * 2**20, time_limit=30)
    t = time.monotonic()
    with pytest.raises(SandboxTimeout):
        run_limited(_sleep, (30,), memory_bytes=200 * 2**20, time_limit=1)
    assert time.monotonic() - t < 5
    with pytest.raises(SandboxCrashed, match="stopped by SIGABRT"):
        run_limited(_abort, (), memory_bytes=200 * 2**20, time_limit=30)
    # and the next call is served as usual
    assert run_limited(_sleep, (0,), memory_bytes=200 * 2**20, time_limit=30) == "woke"
