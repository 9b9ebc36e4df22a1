"""Threads of their own for the reads that status polls, event streams and /health make.

Sync routes and sync dependencies all run on one shared thread pool (anyio's, 40 threads). A
burst of submissions waiting for an admission check holds those threads, and a status poll or a
health check queued behind them waited up to 77 s. The short reads of the job table that must
stay prompt run here instead, on pools no submission can take.
"""

from __future__ import annotations

import asyncio
import functools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")

# a status read takes milliseconds: 16 threads serve thousands of polls a second, and stay within
# the job table's connection pool (service.db: 16 + 16 overflow)
_READS = ThreadPoolExecutor(max_workers=16, thread_name_prefix="voxelastic-read")
# /health apart again: a probe must answer while polls queue up (a broker check may take 2 s)
_HEALTH = ThreadPoolExecutor(max_workers=4, thread_name_prefix="voxelastic-health")


async def read(fn: Callable[..., T], *args, **kwargs) -> T:
    """``fn(*args, **kwargs)`` on the read threads, awaited."""
    return await asyncio.get_running_loop().run_in_executor(_READS, functools.partial(fn, *args, **kwargs))


async def health_check(fn: Callable[..., T], *args) -> T:
    """``fn(*args)`` on the health threads, awaited."""
    return await asyncio.get_running_loop().run_in_executor(_HEALTH, functools.partial(fn, *args))
