"""Preconditioned conjugate gradients on any vector space, with honest stopping.

The algorithm is kept apart from the operator: ``Space`` supplies the vector algebra (Taichi
kernels for the staggered method), ``apply`` and ``precondition`` the operator and its
approximate inverse. A solve either reaches the tolerance or raises ``SolverError`` naming why
(divergence, a non-finite value, loss of positive definiteness, stagnation, the iteration cap,
the precision or conditioning floor): it never hands back a NaN field.

The tolerance is judged on the *true* residual b - A x. The recursive residual of CG drifts from
it by rounding errors that grow with the condition number (the staggered cantilever at nu =
0.4999, f64: recursive 9.2e-9, true 3.5e-8 after 1022 iterations), so when the recursion reports
convergence but the true residual is above the tolerance, CG restarts from the current iterate
with the true residual (iterative refinement with CG as the inner solver), as long as a restart
still gains and iterations remain.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from .linear import SolverError, SolveStats


# After the restarts, a true residual within this factor of rtol is returned with a warning;
# beyond it the solve is a failure.
TRUE_RESIDUAL_SLACK = 10.0
# Restarts stop when one no longer divides the true residual by at least this factor (the floor
# that the precision and the conditioning allow is reached), or after MAX_RESTARTS.
RESTART_GAIN = 2.0
MAX_RESTARTS = 10
# A single-precision floor above this (fewer than two digits) gets no looser rtol to suggest: the held
# shell of benchmarks.staggered at 48^3 floors at 1.6e-4 / 4.5e-4 / 1.9e-3 / 1.9e-2 / 0.22 at nu 0.3 /
# 0.45 / 0.49 / 0.499 / 0.4999
F32_USEFUL = 1e-2


class Space(Protocol):
    def zeros(self) -> Any: ...
    def dot(self, x: Any, y: Any) -> float: ...
    def axpy(self, alpha: float, x: Any, y: Any) -> None: ...  # y += alpha x
    def xpby(self, x: Any, beta: float, y: Any) -> None: ...  # y = x + beta y
    def copy(self, src: Any, dst: Any) -> None: ...
    def finite(self, x: Any) -> bool: ...


def vector_precision(x: Any) -> str:
    """"f32" when the vector ``x`` (a Taichi ndarray or a numpy array) stores single precision,
    else "f64" (what the messages suggest depends on it)."""
    name = str(getattr(x, "dtype", "")).lower()
    return "f32" if name in ("f32", "float32") else "f64"


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
    precision: str | None = None,
) -> SolveStats:
    """Solve A x = b to ||b - A x|| <= rtol ||b||, starting from (and overwriting) ``x``.

    apply(v, out): out = A v; precondition(r, out): out ~= A^-1 r (symmetric positive definite).
    stagnation: iterations without a new best residual after which the solve stops.
    precision: "f32" or "f64", the storage of the vectors (default: read from ``b``); it only
    changes what a failure message suggests.
    """
    precision = precision or vector_precision(b)
    bnorm = math.sqrt(space.dot(b, b))
    if not math.isfinite(bnorm):
        raise SolverError("solver: the load vector is not finite (check loads and prescribed values)", "loads")
    if bnorm == 0.0:
        space.copy(space.zeros(), x)
        return SolveStats(0, 0.0)
    r, p, q = space.zeros(), space.zeros(), space.zeros()
    # z (the preconditioned residual) shares q's storage: z is read only until p is updated, q only
    # from A p until r is, so their lives never overlap; one full vector less (10 bytes per unknown
    # on the staggered 256^3 shell)
    z = q

    def true_residual() -> float:
        """r = b - A x; returns ||r|| / ||b||."""
        apply(x, q)
        space.copy(b, r)
        space.axpy(-1.0, q, r)
        return math.sqrt(space.dot(r, r)) / bnorm

    history: list[float] = []
    rel = true_rel = true_residual()
    it = restarts = 0
    pq = 0.0
    before = math.inf  # the true residual when the current run started from it
    while True:
        # one CG run from x, r holding its true residual
        precondition(r, z)
        space.copy(z, p)
        rz = space.dot(r, z)
        best, best_at = math.inf, it
        stop = ""  # why the run ended before the recursive residual reached rtol
        while rel > rtol:
            if it >= max_iterations:
                stop = "cap"
                break
            apply(p, q)
            pq = space.dot(p, q)
            if not (pq > 0.0) or not math.isfinite(pq):
                stop = "indefinite"
                break
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
                stop = "stagnation"
                break
            if rel <= rtol:
                break
            precondition(r, z)
            rz_new = space.dot(r, z)
            beta = rz_new / rz
            rz = rz_new
            space.xpby(z, beta, p)
        if stop and not restarts:
            # the first run never converged, even recursively: the operator, the preconditioner or
            # the iteration budget is at fault, not the rounding of a converged recursion
            _fail(stop, it, rel, best, pq, rtol, max_iterations, stagnation)
        true_rel = true_residual()
        if not space.finite(x) or not math.isfinite(true_rel):
            raise SolverError("solver: the solution is not finite", "nonfinite")
        if true_rel <= rtol:
            return SolveStats(it, true_rel, history, restarts)
        # the recursion converged (or a restart ran out) with the true residual above rtol:
        # restart from it while that still gains and iterations remain
        if stop or it >= max_iterations or restarts >= MAX_RESTARTS or true_rel * RESTART_GAIN > before:
            break
        before = rel = true_rel
        restarts += 1
    message = _floor_message(true_rel, rtol, it, restarts, precision, capped=it >= max_iterations,
                             max_iterations=max_iterations)
    if true_rel > TRUE_RESIDUAL_SLACK * rtol:
        raise SolverError(message, "precision")
    return SolveStats(it, true_rel, history, restarts, warnings=[message])


@dataclass
class PCG:
    """:func:`pcg` as a :class:`~engine.solvers.linear.LinearSolver`: the operator ``apply``, the
    preconditioner and the stopping rule fixed at construction, b and the start x per solve.
    ``iterate``: the CG routine with :func:`pcg`'s signature (a caller hands its own reference so
    that a test can wrap it where the caller looks it up)."""

    space: Space
    apply: Callable[[Any, Any], None]
    precondition: Callable[[Any, Any], None]
    rtol: float
    max_iterations: int
    stagnation: int = 200
    iterate: Callable[..., SolveStats] = pcg

    def solve(self, b: Any, x: Any | None = None,
              on_iteration: Callable[[int, float], None] | None = None) -> tuple[Any, SolveStats]:
        """(x, stats): ``x`` (default zero) overwritten with the solution; raises ``SolverError``."""
        t0 = time.perf_counter()
        x = self.space.zeros() if x is None else x
        stats = self.iterate(self.space, self.apply, self.precondition, b, x, rtol=self.rtol,
                    max_iterations=self.max_iterations, stagnation=self.stagnation, on_iteration=on_iteration)
        stats.seconds = time.perf_counter() - t0
        return x, stats


def _fail(stop: str, it: int, rel: float, best: float, pq: float, rtol: float, max_iterations: int,
          stagnation: int) -> None:
    """Raise the SolverError of a first CG run that ended with ``stop`` before converging."""
    if stop == "cap":
        raise SolverError(
            f"solver: relative residual {rel:.3g} after solver.max_iterations = {max_iterations} iterations, "
            f"short of solver.rtol = {rtol:g}; raise max_iterations or loosen rtol", "cap"
        )
    if stop == "indefinite":
        raise SolverError(
            f"solver: the operator lost positive definiteness at iteration {it} (p.Ap = {pq:.3g}); "
            "the problem is singular or too ill-conditioned for this precision", "indefinite"
        )
    raise SolverError(
        f"solver: stagnated at relative residual {best:.3g} (no progress in {stagnation} iterations), "
        f"short of solver.rtol = {rtol:g}; the tolerance may be below what this precision resolves", "stagnation"
    )


def _floor_message(true_rel: float, rtol: float, it: int, restarts: int, precision: str, *, capped: bool,
                   max_iterations: int) -> str:
    """Why the true residual stays above rtol although the recursion reached it, and what to do,
    for the precision in use: f32 storage is the usual floor; in f64 it is the conditioning."""
    head = (f"solver: the recursive residual reached solver.rtol = {rtol:g} but the true relative residual is "
            f"{true_rel:.3g} after {it} iterations and {restarts} restart(s) from it")
    if capped:
        head += f" (solver.max_iterations = {max_iterations} reached)"
    looser = f"{10 ** math.ceil(math.log10(true_rel)):.0e}"
    if precision == "f32" and true_rel > F32_USEFUL:
        # a looser rtol would be no solve at all (the held shell at nu 0.4999: 0.22, "about 1e+00")
        return (f"{head}; single precision does not resolve this operator (a Poisson ratio near 0.5, sliver "
                "cut cells or very different stiffnesses amplify its rounding errors): use precision 'f64'")
    if precision == "f32":
        return (f"{head}; the tolerance is below what single precision resolves for this operator: use "
                f"precision 'f64' or a larger rtol (about {looser})")
    return (f"{head}; in double precision this is the operator's conditioning (a Poisson ratio near 0.5, "
            f"sliver cut cells or very different stiffnesses amplify rounding errors): loosen solver.rtol to about "
            f"{looser}" + (" or raise solver.max_iterations" if capped else ""))
