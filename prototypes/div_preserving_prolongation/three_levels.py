"""Three levels, every coarse operator P^T A P of the linear-across divergence-preserving
prolongation (prolongation.py); the first coarse level smoothed by Chebyshev steps on M^-1 A1 with M^-1
the engine's curl smoother of that level (its rediscretised weights, its surface terms replaced by
P^T S P of this prolongation), the second solved exactly. Inconclusive (README): that M^-1 does not
fit A1.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/three_levels.py 64 0.4999
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from engine.staggered import galerkin, smoother_kernels
from engine.staggered.curls import CurlSmoother

sys.path.insert(0, str(Path(__file__).parent))
from harness import Cholesky, held_shell, host_chebyshev, lanczos_bound, mg, operator_block, pcg_spectrum  # noqa: E402
from prolongation import tr_prolongation  # noqa: E402


def say(name: str, its: int, ev: np.ndarray) -> None:
    print(f"{name}: {its} iterations, Ritz values of B A {ev[0]:.3f} ... {ev[-1]:.3f}, "
          f"condition {ev[-1] / ev[0]:.2f}", flush=True)


def main(res: int, nu: float) -> None:
    problem = held_shell(res, nu)
    m3 = mg.Multigrid(problem.level, max_levels=3)
    f, c1, c2 = m3.levels
    say("engine, 3 levels", *pcg_spectrum(problem, m3.precondition))  # before level 1 changes below

    comp, pos = np.nonzero(f.free)
    A = operator_block(f, comp.astype(np.int64) * f.size + pos)
    P1, k1 = tr_prolongation(f, c1, comp, pos)
    A1 = (P1.T @ A @ P1).tocsr()
    comp1, pos1 = k1 // c1.size, k1 % c1.size
    P2, _ = tr_prolongation(c1, c2, comp1, pos1)
    F2 = Cholesky((P2.T @ A1 @ P2).tocsr())
    P1t, P2t = P1.T.tocsr(), P2.T.tocsr()

    # level 1's smoother: the engine's, its surface terms P^T S P of this prolongation
    # (galerkin_surface with the prolongation swapped in)
    own = galerkin.prolongation_matrix
    galerkin.prolongation_matrix = lambda fine, coarse, c, p, kind: tr_prolongation(fine, coarse, c, p)
    try:
        c1.set_surface(galerkin.galerkin_surface(f, c1, m3.kind), f.hold)
    finally:
        galerkin.prolongation_matrix = own
    smoother = CurlSmoother(c1)
    rd, zd = c1.zeros(), c1.zeros()

    def minv(r: np.ndarray) -> np.ndarray:
        v = np.zeros((c1.dim, c1.size))
        v[comp1, pos1] = r
        rd.from_numpy(v.astype(c1.dtype))
        smoother.apply(smoother_kernels.APPLY, rd, zd, zd, 0.0, 1.0)
        return zd.to_numpy()[comp1, pos1]

    bound = lanczos_bound(A1, minv, 12)
    coefficients = mg.chebyshev_coefficients(bound, mg.CURL_SPREAD, mg.CURL_DEGREE)
    print(f"level 1: Chebyshev bound {bound:.1f}, P^T A P {A1.nnz / A1.shape[0]:.1f} entries per row", flush=True)

    def smooth(b: np.ndarray, x: np.ndarray, first: bool) -> np.ndarray:
        return host_chebyshev(A1, minv, coefficients, b, x, first)

    def level1(b: np.ndarray) -> np.ndarray:
        x = smooth(b, np.zeros_like(b), True)
        x = x + P2 @ F2.solve(P2t @ (b - A1 @ x))
        return smooth(b, x, False)

    rf = f.zeros()

    def cycle(b, x) -> None:
        m3._smooth(0, b, x, first=True)
        f.residual(x, b, rf)
        xv = x.to_numpy()
        xv[comp, pos] += P1 @ level1(P1t @ rf.to_numpy()[comp, pos])
        x.from_numpy(xv.astype(f.dtype))
        m3._smooth(0, b, x, first=False)

    say("divergence-preserving P, P^T A P, 3 levels", *pcg_spectrum(problem, cycle))


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]))
