"""p-multigrid preconditioned CG for block systems with hierarchical bases (DG at scale).

The fine space holds one dense block of s unknowns per element; the same subset of every block
spans a lower polynomial degree (DG's orthonormal bases are built degree by degree, so the first 4
of k = 2's 10 functions per component are exactly the k = 1 space, and the first of those the
constants). Prolongation is an injection, so each Galerkin coarse matrix P^T A P is read off the
blocks above it. The preconditioner is one symmetric V-cycle: on every level ``SMOOTHING_STEPS``
damped block-Jacobi steps (each element's own block inverted) before and after the correction
from the level below; the bottom level (k - 1, or below that the constants once the k - 1 level
passes the caller's ``coarse_direct`` unknowns) is factorised once by sparse Cholesky. Rigid modes a body keeps
free are bordered out of the bottom factor and projected out of every preconditioned residual.

Why (docs/benchmarks.md, "DG at scale"): the sparse Cholesky of the full k = 2 system fills
superlinearly (32^3 shell, 427k unknowns: 333 s and 14.5 GiB), while the k = 1 level has 0.4x the
unknowns and 0.16x the nonzeros, and with it factorised the iteration count does not grow with the
grid (23-24 from 12^3 to 32^3 to rtol 1e-8).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from .cg import PCG
from .direct import DirectSolver, NotPositiveDefinite
from .linear import SolveStats

SMOOTHING_STEPS = 2  # before and after the coarse solve: 28 iterations at 16^3 (1 step: 36, 3: 26, equal time)
DAMPING = 1.5  # x += DAMPING / lambda_max(D^-1 A) D^-1 r: inside the smoother's stability bound of 2
POWER_STEPS = 20  # power iteration for lambda_max(D^-1 A); it approaches from below, hence DAMPING < 2


class ArraySpace:
    """The vector algebra of :func:`engine.solvers.cg.pcg` on numpy arrays of length n."""

    def __init__(self, n: int) -> None:
        self.n = n

    def zeros(self) -> np.ndarray:
        return np.zeros(self.n)

    def dot(self, x: np.ndarray, y: np.ndarray) -> float:
        return float(x @ y)

    def axpy(self, alpha: float, x: np.ndarray, y: np.ndarray) -> None:
        y += alpha * x

    def xpby(self, x: np.ndarray, beta: float, y: np.ndarray) -> None:
        y *= beta
        y += x

    def copy(self, src: np.ndarray, dst: np.ndarray) -> None:
        dst[:] = src

    def finite(self, x: np.ndarray) -> bool:
        return bool(np.all(np.isfinite(x)))


class Level:
    """One level of the V-cycle: A [n, n] block-sparse with blocks [s, s], its block-Jacobi smoother,
    and below it the Galerkin level of ``chain[0]`` (the coarse unknowns' places within a block):
    another ``Level`` over ``chain[1:]`` where that level has more than ``coarse_direct`` unknowns and
    the chain goes on (None: never), else its sparse Cholesky (free ``modes`` [n, k] bordered out there)."""

    def __init__(self, A: sp.bsr_matrix, chain: list[np.ndarray], modes: np.ndarray | None,
                 coarse_direct: int | None = None) -> None:
        self.matrix = A
        self.n = A.shape[0]
        s = A.blocksize[0]
        E = self.n // s
        sub = np.asarray(chain[0])
        self.coarse = (np.arange(E)[:, None] * s + sub[None, :]).reshape(-1)
        self._inverse_blocks = _diagonal_inverses(A)
        self._scale = DAMPING / self._lambda_max()
        coarse = sp.bsr_matrix((A.data[:, sub][:, :, sub], A.indices, A.indptr), shape=(E * len(sub),) * 2)
        coarse_modes = None
        if modes is not None:
            # the modes wholly inside the coarse space (singular value 1 of their restriction) are the
            # coarse matrix's null space: all rigid motions for k = 2 over k = 1, translations over k = 0
            U, sigma, _ = np.linalg.svd(modes[self.coarse], full_matrices=False)
            coarse_modes = U[:, sigma > 1 - 1e-8] if np.any(sigma > 1 - 1e-8) else None
        if len(chain) > 1 and coarse_direct is not None and coarse.shape[0] > coarse_direct:
            self.below: Level | DirectSolver = Level(coarse, chain[1:], coarse_modes, coarse_direct)
        else:
            self.below = DirectSolver(coarse.tocsr(), coarse_modes)

    @property
    def sizes(self) -> list[int]:
        """Unknowns per level, this one first."""
        return [self.n] + (self.below.sizes if isinstance(self.below, Level) else [self.below.matrix.shape[0]])

    @property
    def bottom(self) -> DirectSolver:
        return self.below.bottom if isinstance(self.below, Level) else self.below

    def _jacobi(self, r: np.ndarray) -> np.ndarray:
        s = self.matrix.blocksize[0]
        return (self._inverse_blocks @ r.reshape(-1, s, 1)).reshape(-1)

    def _lambda_max(self) -> float:
        v = np.random.default_rng(0).standard_normal(self.n)
        lam = 1.0
        for _ in range(POWER_STEPS):
            w = self._jacobi(self.matrix @ v)
            lam = float(np.linalg.norm(w) / np.linalg.norm(v))
            v = w / np.linalg.norm(w)
        return lam

    def cycle(self, r: np.ndarray) -> np.ndarray:
        """One symmetric V-cycle on r [n] from zero: smooth, coarse correction, smooth."""
        w = self._scale
        x = w * self._jacobi(r)
        for _ in range(SMOOTHING_STEPS - 1):
            x += w * self._jacobi(r - self.matrix @ x)
        residual = (r - self.matrix @ x)[self.coarse]
        if isinstance(self.below, Level):
            x[self.coarse] += self.below.cycle(residual)
        else:
            x[self.coarse] += self.below.solve(residual)[0]
        for _ in range(SMOOTHING_STEPS):
            x += w * self._jacobi(r - self.matrix @ x)
        return x

    def free(self) -> None:
        self.below.free()


class PMultigrid:
    """A :class:`~engine.solvers.linear.LinearSolver` for A [n, n] (symmetric, block sparse with
    blocks [s, s]) by CG preconditioned with the p-multigrid V-cycle above.

    chain: per level below the fine one, the coarse unknowns' places within a block of the level above
    (the same in every block): for DG k = 2, the k = 1 functions among the 30, then the constants among
    those 12; a level below the first with more than ``coarse_direct`` unknowns is cycled in turn
    instead of factorised (None: the first coarse level is factorised). modes Q [n, k] (orthonormal
    columns): rigid motions no boundary holds; A need be positive definite only on their complement, b
    is taken without its part along them and the solution is orthogonal to them. Raises
    ``NotPositiveDefinite`` at construction when a diagonal block or the bottom matrix is not (then A is
    not either); CG raises ``SolverError`` with reason "indefinite" when it meets a direction of
    non-positive curvature.
    """

    def __init__(self, A: sp.spmatrix, block: int, chain: list[np.ndarray], modes: np.ndarray | None = None, *,
                 rtol: float = 1e-8, max_iterations: int = 5000, coarse_direct: int | None = None) -> None:
        t0 = time.perf_counter()
        self.matrix = A if sp.isspmatrix_bsr(A) and A.blocksize == (block, block) else sp.bsr_matrix(
            A, blocksize=(block, block))
        self.matrix.sort_indices()
        self.n = A.shape[0]
        self.modes = modes if modes is not None and modes.shape[1] else None
        self.top = Level(self.matrix, chain, self.modes, coarse_direct)
        self._pcg = PCG(ArraySpace(self.n), self._apply, self._precondition, rtol, max_iterations)
        self.setup_seconds = time.perf_counter() - t0

    @property
    def backend(self) -> str:
        """What solves: CG on the p-multigrid V-cycle (unknowns per level), its bottom level by Cholesky."""
        sizes = " > ".join(str(n) for n in self.top.sizes)
        return f"pmg-cg ({sizes} unknowns, {self.top.bottom.backend} at the bottom)"

    def _apply(self, x: np.ndarray, out: np.ndarray) -> None:
        out[:] = self.matrix @ x

    def _project(self, v: np.ndarray) -> np.ndarray:
        if self.modes is not None:
            v = v - self.modes @ (self.modes.T @ v)
        return v

    def _precondition(self, r: np.ndarray, out: np.ndarray) -> None:
        out[:] = self._project(self.top.cycle(r))

    def solve(self, b: np.ndarray, x: np.ndarray | None = None,
              on_iteration: Callable[[int, float], None] | None = None) -> tuple[np.ndarray, SolveStats]:
        """(x [n], stats) for b [n], from ``x`` (default zero); raises ``SolverError``."""
        b = self._project(np.asarray(b, dtype=np.float64))
        x = np.zeros(self.n) if x is None else self._project(np.array(x, dtype=np.float64))
        return self._pcg.solve(b, x, on_iteration)

    def apply_inverse(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b [n] by a solve (on the complement of the modes)."""
        return self.solve(b)[0]

    def free(self) -> None:
        """Release the bottom level's factor now (``DirectSolver.free``; idempotent)."""
        self.top.free()


def diagonal_blocks(A: sp.bsr_matrix) -> np.ndarray:
    """Places [<= E] in A.data of the stored diagonal blocks of a block-sparse A, in row order."""
    rows = np.repeat(np.arange(len(A.indptr) - 1), np.diff(A.indptr))
    return np.nonzero(A.indices == rows)[0]


def _diagonal_inverses(A: sp.bsr_matrix) -> np.ndarray:
    """Inverses [E, s, s] of the diagonal blocks of a block-sparse A; raises ``NotPositiveDefinite``
    when one is not positive definite (then A is not)."""
    E = A.shape[0] // A.blocksize[0]
    diagonal = diagonal_blocks(A)
    if len(diagonal) != E:
        raise NotPositiveDefinite(f"{E - len(diagonal)} element(s) have no diagonal block")
    blocks = A.data[diagonal]
    try:
        factor = np.linalg.cholesky(blocks)
    except np.linalg.LinAlgError:
        raise NotPositiveDefinite("a diagonal block is not positive definite") from None
    eye = np.broadcast_to(np.eye(blocks.shape[1]), blocks.shape)
    inverse_factor = np.linalg.solve(factor, eye)
    return inverse_factor.swapaxes(-1, -2) @ inverse_factor
