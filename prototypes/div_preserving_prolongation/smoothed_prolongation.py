"""Two levels of the engine's hierarchy with its coarse level solved exactly and a smoothed prolongation
S^k P (S = I - w M^-1 A, M^-1 the curl smoother of the fine level, w = WSCALE / its Lanczos bound; the
restriction P^T S^T, so the cycle stays symmetric): does lowering the prolonged fields' fine energy
bring the top of B A's spectrum down (twenty-third session)?

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/smoothed_prolongation.py RES NU K:WSCALE...
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from harness import TwoLevel, held_shell, pcg_spectrum  # noqa: E402
from engine.staggered import kernels, smoother_kernels  # noqa: E402
from engine.staggered import multigrid as mg  # noqa: E402


def smoothed_cycle(two, ksteps: int, wscale: float):
    """The two-level cycle's apply(b, x) with the prolongation smoothed ``ksteps`` times."""
    m, f, c = two.mg, two.fine, two.coarse
    sm = m.curls[0]
    lam = m.bounds[0] / mg.MARGIN
    w = wscale / lam
    d = f.dim
    r, t, u, e = f.zeros(), f.zeros(), f.zeros(), f.zeros()
    bc, xc = c.zeros(), c.zeros()

    def minv(src, dst):
        sm.apply(smoother_kernels.APPLY, src, dst, dst, 0.0, 1.0)

    def S(v):  # v <- v - w M^-1 A v
        for _ in range(ksteps):
            f.apply(v, t)
            minv(t, u)
            kernels.axpy(d, -w, u, v)

    def St(v):  # v <- v - w A M^-1 v
        for _ in range(ksteps):
            minv(v, u)
            f.apply(u, t)
            kernels.axpy(d, -w, t, v)

    def apply(b, x):
        m._smooth(0, b, x, first=True)
        f.residual(x, b, r)
        St(r)
        kernels.restrict(d, m.kind, c.coords, m.children[0], c.mask, r, bc)
        m.coarse.solve(bc, xc)
        kernels.copy(d, f.zeros(), e)
        kernels.prolong_add(d, m.kind, f.coords, m.parents[0], f.mask, xc, e)
        S(e)
        kernels.axpy(d, 1.0, e, x)
        m._smooth(0, b, x, first=False)
    return apply


if __name__ == "__main__":
    res, nu = int(sys.argv[1]), float(sys.argv[2])
    problem = held_shell(res, nu)
    two = TwoLevel.__new__(TwoLevel)  # the engine's two levels only: no assembled fine operator needed
    two.problem = problem
    two.mg = mg.Multigrid(problem.level, max_levels=2)
    two.fine, two.coarse = two.mg.levels
    print("curl smoothing bound", two.mg.bounds[0])
    for spec in sys.argv[3:]:
        k, w = spec.split(":")
        its, ev = pcg_spectrum(problem, smoothed_cycle(two, int(k), float(w)))
        print(f"k={k} w={w}: {its} iterations, Ritz {ev[0]:.3f} ... {ev[-1]:.3f}, condition {ev[-1]/ev[0]:.2f}", flush=True)
