"""Three levels, every coarse operator P^T A P of the linear-across divergence-preserving
prolongation (prolongation.py); the first coarse level smoothed by Chebyshev steps on M^-1 A1 with M^-1
the engine's curl smoother of that level (its rediscretised weights, its surface terms replaced by
P^T S P of this prolongation), the second solved exactly. Inconclusive (README): that M^-1 does not
fit A1.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/three_levels.py 64 0.4999
"""
import sys
sys.path.insert(0, 'prototypes/div_preserving_prolongation')
import numpy as np
from harness import Cholesky, mg, operator_block
from harness import held_shell, pcg_iterations, lanczos_ritz
from prolongation import tr_prolongation
from engine.staggered import smoother_kernels

res, nu = int(sys.argv[1]), float(sys.argv[2])
problem = held_shell(res, nu)
m3 = mg.Multigrid(problem.level, max_levels=3)
f, c1, c2 = m3.levels
print(f"engine, 3 levels: {pcg_iterations(problem, m3.precondition)} iterations (before its level 1 is changed below)", flush=True)
comp, pos = np.nonzero(f.free)
keys = comp.astype(np.int64) * f.size + pos
A = operator_block(f, keys)
P1, k1 = tr_prolongation(f, c1, comp, pos)
assert np.all(c1.free[k1 // c1.size, k1 % c1.size])
A1 = (P1.T @ A @ P1).tocsr()
comp1, pos1 = k1 // c1.size, k1 % c1.size
P2, k2 = tr_prolongation(c1, c2, comp1, pos1)
A2 = (P2.T @ A1 @ P2).tocsr()
F2 = Cholesky(A2)
from engine.staggered.nitsche import SurfaceOperator
from engine.staggered.curls import CurlSmoother
import scipy.sparse as sp
sf = f.surface
Ps, ks = tr_prolongation(f, c1, sf.comp, sf.pos)
Ps = (sp.diags(f.free[sf.comp, sf.pos].astype(float)) @ Ps).tocsr(); pst = Ps.T.tocsr()
c1.set_surface(SurfaceOperator(ks // c1.size, ks % c1.size, (pst @ sf.mass @ Ps).tocsr(), (pst @ sf.flux).tocsr(), (sf.stress @ Ps).tocsr(), pst @ sf.rhs), f.hold)
sm = CurlSmoother(c1)
rd, zd = c1.zeros(), c1.zeros()
def minv(r):
    v = np.zeros((c1.dim, c1.size)); v[comp1, pos1] = r
    rd.from_numpy(v.astype(c1.dtype))
    sm.apply(smoother_kernels.APPLY, rd, zd, zd, 0.0, 1.0)
    return zd.to_numpy()[comp1, pos1]
# Lanczos bound of M^-1 A1
rng = np.random.default_rng(7)
r = rng.standard_normal(len(k1)); z = minv(r); p = z.copy(); rz = r @ z; al, be = [], []
for _ in range(12):
    q = A1 @ p; a = rz / (p @ q); r = r - a * q; z = minv(r); rz2 = r @ z; b = rz2 / rz
    al.append(a); be.append(b); p = z + b * p; rz = rz2
a, b = np.array(al), np.array(be)
T = np.diag(1 / a + np.concatenate([[0], b[:-1] / a[:-1]])) + np.diag(np.sqrt(b[:-1]) / a[:-1], 1) + np.diag(np.sqrt(b[:-1]) / a[:-1], -1)
bound = np.linalg.eigvalsh(T)[-1] * mg.MARGIN
coef = mg.chebyshev_coefficients(bound, mg.CURL_SPREAD, mg.CURL_DEGREE)
print('level-1 bound', bound, 'A1 entries/row', A1.nnz / A1.shape[0], flush=True)
def cheb(b, x, first):
    step = np.zeros_like(b)
    for i, (ca, cb) in enumerate(coef):
        if first and i == 0:
            step = cb * minv(b); x = step.copy()
        else:
            step = ca * step + cb * minv(b - A1 @ x); x = x + step
    return x
P2t = P2.T.tocsr()
def level1(b):
    x = cheb(b, np.zeros_like(b), True)
    x = x + P2 @ F2.solve(P2t @ (b - A1 @ x))
    return cheb(b, x, False)
P1t = P1.T.tocsr()
rf = f.zeros()
def cycle(b, x):
    m3._smooth(0, b, x, first=True)
    f.residual(x, b, rf)
    e = P1 @ level1(P1t @ rf.to_numpy()[comp, pos])
    xv = x.to_numpy(); xv[comp, pos] += e; x.from_numpy(xv.astype(f.dtype))
    m3._smooth(0, b, x, first=False)
for name, pre in (('tr-galerkin, 3 levels', cycle),):
    print(f"{name}: {pcg_iterations(problem, pre)} iterations", flush=True)
    try:
        ev = lanczos_ritz(problem, pre)
        print(f"  Ritz values of B A {ev[0]:.3f} ... {ev[-1]:.3f}, condition {ev[-1] / ev[0]:.2f}", flush=True)
    except np.linalg.LinAlgError:
        print("  B is not positive definite (a negative Lanczos coefficient)", flush=True)
