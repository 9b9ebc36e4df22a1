"""The engine's V-cycle with its coarse levels solved by two flexible-CG steps each (Notay &
Vassilevski's K-cycle), preconditioned by their own cycles: how close multilevel gets to two-level.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/kcycle.py RES NU [TOL...]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from engine.staggered import kernels

sys.path.insert(0, str(Path(__file__).parent))
from harness import held_shell, mg, pcg_spectrum  # noqa: E402


def install(m: mg.Multigrid, tol: float) -> None:
    """Replace ``m._cycle`` by the K-cycle (``tol``: the inner residual ratio that skips the second step)."""
    work = {k: [lv.zeros() for _ in range(5)] for k, lv in enumerate(m.levels[:-1]) if k}
    last = len(m.levels) - 1

    def solve(k, b, x):
        if k == last:
            m.coarse.solve(b, x)
            return
        lv, d = m.levels[k], m.levels[k].dim
        c1, v1, rr, c2, v2 = work[k]
        cycle(k, b, c1)
        lv.apply(c1, v1)
        rho1, a1 = kernels.dot(d, c1, v1), kernels.dot(d, c1, b)
        kernels.copy(d, b, rr)
        kernels.axpy(d, -a1 / rho1, v1, rr)
        kernels.copy(d, c1, x)
        if np.sqrt(kernels.dot(d, rr, rr)) <= tol * np.sqrt(kernels.dot(d, b, b)):
            kernels.axpy(d, a1 / rho1 - 1.0, c1, x)  # x = (a1 / rho1) c1
            return
        cycle(k, rr, c2)
        lv.apply(c2, v2)
        gamma, beta, a2 = kernels.dot(d, c2, v1), kernels.dot(d, c2, v2), kernels.dot(d, c2, rr)
        rho2 = beta - gamma * gamma / rho1
        kernels.axpy(d, a1 / rho1 - gamma * a2 / (rho1 * rho2) - 1.0, c1, x)
        kernels.axpy(d, a2 / rho2, c2, x)

    def cycle(k, b, x):
        lv = m.levels[k]
        r = m.work[k][0]
        down = m.levels[k + 1]
        m._smooth(k, b, x, first=True)
        lv.residual(x, b, r)
        bc, xc = m.work[k + 1][1:3]
        kernels.restrict(lv.dim, m.kind, down.coords, m.children[k], down.mask, r, bc)
        solve(k + 1, bc, xc)
        kernels.prolong_add(lv.dim, m.kind, lv.coords, m.parents[k], lv.mask, xc, x)
        m._smooth(k, b, x, first=False)

    m._cycle = lambda k, b, x: cycle(k, b, x)


def main(res: int, nu: float, tols: list[float]) -> None:
    problem = held_shell(res, nu)
    m = problem.multigrid
    print("levels:", [lv.layout.box for lv in m.levels], flush=True)
    t = time.perf_counter()
    its, ev = pcg_spectrum(problem, m.precondition)
    print(f"V-cycle: {its} iterations ({time.perf_counter() - t:.1f} s)", flush=True)
    for tol in tols or [0.25]:
        install(m, tol)
        t = time.perf_counter()
        its, ev = pcg_spectrum(problem, m.precondition)
        print(f"K-cycle tol {tol}: {its} iterations ({time.perf_counter() - t:.1f} s)", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), [float(a) for a in sys.argv[3:]])
