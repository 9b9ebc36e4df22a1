"""Sparse direct solves for symmetric systems: MKL PARDISO (pypardiso), SuperLU as the fallback.

PARDISO factorises the upper triangle as a symmetric positive definite matrix (mtype 2); a
zero or negative pivot means the matrix is not positive definite, which the DG method uses to
raise its penalty (Kaufmann et al. 2009 section 9.1). Bordered (indefinite) systems use
symmetric indefinite PARDISO (mtype -2). The choice of PARDISO over SuperLU and Taichi's
SparseSolver is measured in docs/benchmarks.md (benchmarks/dg.py --solvers).
"""

from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

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
