"""Sparse direct solves for symmetric systems: MKL PARDISO (pypardiso), SuperLU as the fallback.

PARDISO factorises the upper triangle as a symmetric positive definite matrix (mtype 2); a
zero or negative pivot means the matrix is not positive definite, which the DG method uses to
raise its penalty (Kaufmann et al. 2009 section 9.1). Bordered (indefinite) systems use
symmetric indefinite PARDISO (mtype -2). ``DirectSolver`` is the layer's solver
(``linear.LinearSolver``) on such a factorisation. The choice of PARDISO over SuperLU and Taichi's
SparseSolver is measured in docs/benchmarks.md (benchmarks/dg.py --solvers).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .linear import SolverError, SolveStats


def _point_pypardiso_at_mkl() -> None:
    """Tell pypardiso where the mkl wheel put its runtime library, unless the environment already
    does. Without it pypardiso's import (it builds a solver at import) and every later solver
    search for the library with ``find_library`` and a recursive glob of the environment: 0.22 s
    of the first direct solve in a fresh process, which small staggered jobs pay (docs/benchmarks.md,
    "Cold start"). The mkl wheel's own file list names the library; 0.02 s."""
    if "PYPARDISO_MKL_RT" in os.environ:
        return
    try:
        from importlib import metadata

        found = [f for f in metadata.files("mkl") or () if f.name.startswith(("libmkl_rt.so", "mkl_rt"))]
    except metadata.PackageNotFoundError:  # pragma: no cover - MKL from elsewhere (conda, system)
        return
    for f in found:
        path = Path(f.locate())
        if path.is_file():
            os.environ["PYPARDISO_MKL_RT"] = str(path.resolve())
            return


_point_pypardiso_at_mkl()
try:  # MKL wheels exist for x86-64 only; elsewhere SuperLU does the work
    import pypardiso
except (ImportError, OSError):  # pragma: no cover - exercised only where MKL is missing
    pypardiso = None


def _pardiso(mtype: int):
    """A pypardiso solver of matrix type ``mtype``. pypardiso looks for MKL's library at every
    construction (``find_library``, then a recursive glob of the environment: ~0.2 s, paid per
    factorisation, so per penalty doubling and per corotated fixed-point step); after the first
    solver of a process the path found is handed on through pypardiso's own PYPARDISO_MKL_RT."""
    solver = pypardiso.PyPardisoSolver(mtype=mtype)
    os.environ.setdefault("PYPARDISO_MKL_RT", solver.libmkl._name)
    return solver


class NotPositiveDefinite(Exception):
    """The matrix handed to :class:`Cholesky` is not positive definite."""


class Cholesky:
    """Factorisation of a symmetric CSR matrix A [n, n]; ``solve(b)`` for b [n] or [n, k].

    definite: A must be positive definite (raises NotPositiveDefinite when a pivot is not
    positive); otherwise a symmetric indefinite factorisation whose ``negatives`` counts the
    negative pivots (the inertia). ``backend`` names what ran.
    """

    def __init__(self, A: sp.spmatrix, *, definite: bool = True) -> None:
        self.n = A.shape[0]
        self.definite = definite
        self._freed = False
        if pypardiso is not None:
            self.backend = "pardiso"
            self._solver = _pardiso(2 if definite else -2)
            self._upper = sp.triu(A, format="csr")
            self._upper.sort_indices()
            try:
                self._solver.factorize(self._upper)
            except pypardiso.pardiso_wrapper.PyPardisoError as exc:
                if definite and "-4" in str(exc):
                    raise NotPositiveDefinite("zero or negative pivot") from None
                raise
            # inertia of an indefinite factorisation: pivots < 0 (iparm(23) in PARDISO's numbering)
            self.negatives = int(self._solver.iparm[22]) if not definite else 0
        else:  # pragma: no cover
            self.backend = "superlu"
            # symmetric mode, no pivoting off the diagonal: the pivots are those of L D L^T
            self._lu = spla.splu(sp.csc_matrix(A), diag_pivot_thresh=0.0, options={"SymmetricMode": True})
            diag = self._lu.U.diagonal()
            self.negatives = int(np.sum(diag < 0))
            if definite and np.any(diag <= 0):
                raise NotPositiveDefinite(f"{int(np.sum(diag <= 0))} non-positive pivots")

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._freed:  # PARDISO would read released memory (or refactorise silently)
            raise RuntimeError("this factorisation was freed")
        b = np.asarray(b, dtype=np.float64)
        if self.backend == "pardiso":
            return self._solver.solve(self._upper, b)
        return self._lu.solve(b)  # pragma: no cover

    def free(self) -> None:
        """Release the factor's memory now (idempotent).

        PARDISO keeps the factor in MKL's own memory, which Python's garbage collector does not
        see: a solver object that is merely dropped keeps it until the process exits. A corotated
        DG solve refactorises per fixed-point iteration, so without this every iteration's factor
        stayed resident (issue 18: +25 MB per iteration on a 10-cell torus, 19 GB after 100 at 20).
        """
        if getattr(self, "_freed", True):
            return
        self._freed = True
        if getattr(self, "backend", None) == "pardiso" and hasattr(self, "_solver"):
            self._solver.free_memory(everything=True)
        else:  # pragma: no cover - SuperLU's factor is ordinary Python-owned memory
            self.__dict__.pop("_lu", None)

    def __del__(self) -> None:
        # also reached for a factorisation whose __init__ raised (a pivot that was not positive):
        # its PARDISO handle holds memory too
        try:
            self.free()
        except Exception:  # never raise from a finaliser (interpreter shutdown, MKL already unloaded)
            pass


class DirectSolver:
    """A :class:`~engine.solvers.linear.LinearSolver` by sparse Cholesky of A [n, n] (symmetric CSR).

    Without ``modes``, A must be positive definite. With modes Q [n, k] (orthonormal columns: the
    rigid motions no boundary holds), A need only be positive definite on their complement: the
    bordered system [[A, Q], [Q^T, 0]] is factorised instead, whose solution x is orthogonal to Q
    and whose inertia must show exactly k negative pivots. Either way a matrix that is not
    positive definite (there) raises ``NotPositiveDefinite`` at construction. ``residual`` in the
    statistics is ||A x - b|| / ||b|| with the part along Q removed (A x - b has none in exact
    arithmetic; ||r|| itself where b = 0).
    """

    def __init__(self, A: sp.csr_matrix, modes: np.ndarray | None = None) -> None:
        self.matrix = A
        self.modes = modes if modes is not None and modes.shape[1] else None
        if self.modes is None:
            self.factor = Cholesky(A)
            return
        Q = self.modes
        k = Q.shape[1]
        zero = sp.csr_matrix((np.zeros(k), (np.arange(k), np.arange(k))), shape=(k, k))  # stored: PARDISO needs the diagonal
        K = sp.bmat([[A, sp.csr_matrix(Q)], [sp.csr_matrix(Q.T), zero]], format="csr")
        self.factor = Cholesky(K, definite=False)
        # k negative pivots when A is positive definite on the complement of the modes, more when it is not
        if self.factor.negatives > k:
            negatives = self.factor.negatives
            self.factor.free()
            raise NotPositiveDefinite(f"{negatives - k} negative pivots beyond the rigid modes")

    @property
    def backend(self) -> str:
        """What factorised: "pardiso" or "superlu"."""
        return self.factor.backend

    def apply_inverse(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b [n] through the factor (without modes only: with them it is the bordered inverse)."""
        return self.factor.solve(b)

    def solve(self, b: np.ndarray, x: np.ndarray | None = None,
              on_iteration: Callable[[int, float], None] | None = None) -> tuple[np.ndarray, SolveStats]:
        """(x [n], stats) for b [n]; ``x`` is ignored (nothing to start from). Raises
        ``SolverError`` (reason "singular") when the solution is not finite."""
        t0 = time.perf_counter()
        n = self.matrix.shape[0]
        if self.modes is not None:
            x = self.factor.solve(np.concatenate([b, np.zeros(self.modes.shape[1])]))[:n]
        else:
            x = self.factor.solve(b)
        if not np.all(np.isfinite(x)):
            raise SolverError("solver: the direct solve produced non-finite values (singular system)", "singular")
        r = self.matrix @ x - b
        if self.modes is not None:
            r = r - self.modes @ (self.modes.T @ r)
        norm = np.linalg.norm(b)
        residual = float(np.linalg.norm(r) / norm) if norm > 0 else float(np.linalg.norm(r))
        if on_iteration is not None:
            on_iteration(1, residual)
        return x, SolveStats(1, residual, [residual], seconds=time.perf_counter() - t0)

    def free(self) -> None:
        """Release the factor's memory now (``Cholesky.free``; idempotent)."""
        self.factor.free()
