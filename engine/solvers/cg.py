"""Preconditioned conjugate gradients on any vector space, with honest stopping.

The algorithm is kept apart from the operator: ``Space`` supplies the vector algebra (Taichi
kernels for the staggered method), ``apply`` and ``precondition`` the operator and its
approximate inverse. A solve either reaches the tolerance or raises ``SolverError`` naming why
(divergence, a non-finite value, loss of positive definiteness, stagnation, the iteration cap):
it never hands back a NaN field.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from ..errors import VoxelasticError


# The true residual may exceed the recursive one by round-off drift; beyond this factor it is a failure.
TRUE_RESIDUAL_SLACK = 10.0


class SolverError(VoxelasticError):
    """The linear solve did not converge; the message says why and what to change. ``reason``:
    "loads", "cap", "indefinite", "nonfinite", "stagnation" or "precision"."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class Space(Protocol):
    def zeros(self) -> Any: ...
    def dot(self, x: Any, y: Any) -> float: ...
    def axpy(self, alpha: float, x: Any, y: Any) -> None: ...  # y += alpha x
    def xpby(self, x: Any, beta: float, y: Any) -> None: ...  # y = x + beta y
    def copy(self, src: Any, dst: Any) -> None: ...
    def finite(self, x: Any) -> bool: ...


@dataclass
class SolveStats:
    """iterations: CG iterations; residual: final ||b - A x|| / ||b|| (recomputed, not recursed);
    history: relative residual after each iteration."""

    iterations: int
    residual: float
    history: list[float] = field(default_factory=list)


def pcg(
    space: Space,
    apply: Callable[[Any, Any], None],
    precondition: Callable[[Any, Any], None],
    b: Any,
    x: Any,
    *,
    rtol: float,
    max_iterations: int,
    stagnation: int = 200,
    on_iteration: Callable[[int, float], None] | None = None,
) -> SolveStats:
    """Solve A x = b to ||b - A x|| <= rtol ||b||, starting from (and overwriting) ``x``.

    apply(v, out): out = A v; precondition(r, out): out ~= A^-1 r (symmetric positive definite).
    stagnation: iterations without a new best residual after which the solve stops.
    """
    bnorm = math.sqrt(space.dot(b, b))
    if not math.isfinite(bnorm):
        raise SolverError("solver: the load vector is not finite (check loads and prescribed values)", "loads")
    if bnorm == 0.0:
        space.copy(space.zeros(), x)
        return SolveStats(0, 0.0)
    r, z, p, q = space.zeros(), space.zeros(), space.zeros(), space.zeros()
    apply(x, q)
    space.copy(b, r)
    space.axpy(-1.0, q, r)
    precondition(r, z)
    space.copy(z, p)
    rz = space.dot(r, z)
    history: list[float] = []
    best, best_at = math.inf, 0
    rel = math.sqrt(space.dot(r, r)) / bnorm
    it = 0
    while rel > rtol:
        if it >= max_iterations:
            raise SolverError(
                f"solver: relative residual {rel:.3g} after solver.max_iterations = {max_iterations} iterations, "
                f"short of solver.rtol = {rtol:g}; raise max_iterations or loosen rtol", "cap"
            )
        apply(p, q)
        pq = space.dot(p, q)
        if not (pq > 0.0) or not math.isfinite(pq):
            raise SolverError(
                f"solver: the operator lost positive definiteness at iteration {it} (p.Ap = {pq:.3g}); "
                "the problem is singular or too ill-conditioned for this precision", "indefinite"
            )
        alpha = rz / pq
        space.axpy(alpha, p, x)
        space.axpy(-alpha, q, r)
        it += 1
        rel = math.sqrt(space.dot(r, r)) / bnorm
        history.append(rel)
        if on_iteration is not None:
            on_iteration(it, rel)
        if not math.isfinite(rel):
            raise SolverError(f"solver: the residual became non-finite at iteration {it}", "nonfinite")
        if rel < best * 0.999:
            best, best_at = rel, it
        elif it - best_at >= stagnation:
            raise SolverError(
                f"solver: stagnated at relative residual {best:.3g} (no progress in {stagnation} iterations), "
                f"short of solver.rtol = {rtol:g}; the tolerance may be below what this precision resolves", "stagnation"
            )
        if rel <= rtol:
            break
        precondition(r, z)
        rz_new = space.dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        space.xpby(z, beta, p)
    # the recursive residual drifts from the true one in long solves: report the true one
    apply(x, q)
    space.copy(b, r)
    space.axpy(-1.0, q, r)
    true_rel = math.sqrt(space.dot(r, r)) / bnorm
    if not space.finite(x) or not math.isfinite(true_rel):
        raise SolverError("solver: the solution is not finite", "nonfinite")
    if true_rel > TRUE_RESIDUAL_SLACK * rtol:
        raise SolverError(
            f"solver: the recursive residual reached solver.rtol = {rtol:g} but the true relative residual is "
            f"{true_rel:.3g}; the tolerance is below what this precision resolves (use precision 'f64' or a larger rtol)", "precision"
        )
    return SolveStats(it, true_rel, history)
