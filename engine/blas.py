"""Batches of tiny dense problems on one OpenBLAS thread.

numpy's and scipy's OpenBLAS split even a 10 x 10 solve across their threads. Where the cores are
busy (a service running jobs side by side, CI, any other process) those threads wait on each
other, and a batch of small solves, factorisations or eigenvalue problems slows down by orders of
magnitude: 2,000 solves of 10 x 10 took 3 ms on one thread and 0.16 to 13.9 s on two with two other
jobs on this machine's 2 cores (docs/benchmarks.md, "Small dense batches on a busy machine"). The
engine's batched fits (surface stress, strain recovery, DG bases, the MLS embedding, barycentric
coordinates) run inside :func:`one_thread`. MKL, which PARDISO uses for large factorisations that
do use their threads, is left alone.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TypeVar

from threadpoolctl import ThreadpoolController

F = TypeVar("F", bound=Callable)


def one_thread():
    """Context manager: every OpenBLAS loaded in the process limited to one thread inside it."""
    return ThreadpoolController().select(internal_api="openblas").limit(limits=1)


def on_one_thread(function: F) -> F:
    """Decorator: ``function`` runs inside :func:`one_thread`."""

    @functools.wraps(function)
    def wrapped(*args, **kwargs):
        with one_thread():
            return function(*args, **kwargs)

    return wrapped  # type: ignore[return-value]
