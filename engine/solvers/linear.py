"""The linear-solver layer the methods solve through: one protocol, one statistics record.

A solver is set up once per operator (a factorisation, a preconditioned iteration) and then
solves as often as its method needs; ``solve(b)`` returns the solution and a :class:`SolveStats`
with the same meaning for every solver: iterations (a direct solve counts one), the final true
relative residual ||b - A x|| / ||b|| (recomputed from x, not recursed) and the wall time [s]. The
staggered method solves through ``cg.PCG`` (matrix-free, Taichi vectors), DG through
``direct.DirectSolver`` (sparse Cholesky, numpy vectors).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from ..errors import VoxelasticError


class SolverError(VoxelasticError):
    """The linear solve did not converge; the message says why and what to change. ``reason``:
    "loads", "cap", "indefinite", "nonfinite", "stagnation", "precision" (the true residual
    stays above the tolerance however CG restarts: the storage precision or, in f64, the
    operator's conditioning) or "singular" (a direct solve met a singular matrix)."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass
class SolveStats:
    """iterations: iterations of an iterative solver (all restarts together), 1 for a direct
    solve; residual: final ||b - A x|| / ||b|| (recomputed, not recursed); history: relative
    residual after each iteration (CG: the recursive one, a restart starting again from the true
    one); restarts: how often CG restarted from the true residual; warnings: what the caller
    should report with the result (a true residual left above the tolerance, within
    cg.TRUE_RESIDUAL_SLACK of it); seconds: wall time of the solve [s]."""

    iterations: int
    residual: float
    history: list[float] = field(default_factory=list)
    restarts: int = 0
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0


class LinearSolver(Protocol):
    """A solver of A x = b for one operator A, set up once, solved as often as needed."""

    def solve(self, b: Any, x: Any | None = None,
              on_iteration: Callable[[int, float], None] | None = None) -> tuple[Any, SolveStats]:
        """(x, stats) with A x = b. ``x``: the starting guess of an iterative solver, overwritten
        with the solution (a direct solver ignores it); ``on_iteration(i, relative residual)``
        hears of each iteration."""
        ...
