"""Two levels whose coarse level is P^T A P of the linear-across divergence-preserving prolongation
(prolongation.py), solved inexactly by K steps of PCG preconditioned by a rediscretised cycle from
level 1 down (the engine's bulk, the surface terms P^T S P of the same prolongation, its transfers on
every deeper level: ``all_levels.HostTransfers``); the engine's fine smoothing; outer flexible CG.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/galerkin_inner.py RES NU [slopes=S] VARIANT...

Variants: ``exact`` (level 1 factorised), ``pcg:K`` (K inner PCG steps), ``ritz:K`` (the Ritz values of
the level-1 cycle times P^T A P after K PCG steps from a random vector: how well a rediscretised
hierarchy preconditions the Galerkin level). Each FCG run starts from a random right-hand side and
prints the iteration where the residual fell under rtol 1e-6 (45 if never).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from engine.runtime import device_array
from engine.solvers.direct import Cholesky

sys.path.insert(0, str(Path(__file__).parent))
from all_levels import HostTransfers  # noqa: E402
from harness import TwoLevel, held_shell, ritz  # noqa: E402
from prolongation import tr_prolongation  # noqa: E402


def fcg(problem, precondition, steps: int = 45, rtol: float = 1e-6, seed: int = 0) -> int:
    """FCG(1) (each direction A-orthogonal to the last; Notay 2000) from a random right-hand side."""
    lv, space = problem.level, problem.space
    b = device_array((np.random.default_rng(seed).standard_normal(lv.free.shape) * lv.free).astype(lv.dtype))
    x, r, z, q, p = (space.zeros() for _ in range(5))
    space.copy(b, r)
    bnorm = np.sqrt(space.dot(b, b))
    precondition(r, z)
    space.copy(z, p)
    for i in range(steps):
        lv.apply(p, q)
        pq = space.dot(p, q)
        alpha = space.dot(r, p) / pq
        space.axpy(alpha, p, x)
        space.axpy(-alpha, q, r)
        if np.sqrt(space.dot(r, r)) / bnorm < rtol:
            return i + 1
        precondition(r, z)
        space.xpby(z, -space.dot(z, q) / pq, p)
    return steps


def main(res: int, nu: float, variants: list[str]) -> None:
    slopes = variants.pop(0).split("=")[1] if variants[0].startswith("slopes=") else "central"
    problem = held_shell(res, nu)
    m = problem.multigrid
    f = m.levels[0]
    print("levels:", [lv.layout.box for lv in m.levels], flush=True)
    t = time.perf_counter()
    print(f"engine V-cycle: {fcg(problem, m.precondition)} FCG iterations ({time.perf_counter() - t:.1f} s)", flush=True)
    two = TwoLevel(problem)
    P, keys = tr_prolongation(f, two.coarse, two.comp, two.pos, slopes)
    P, Pt = P.tocsr(), P.T.tocsr()
    A1 = (Pt @ two.A @ P).tocsr()
    host = HostTransfers(f, slopes)
    c = host.levels[1]
    ck, cp = keys // c.size, keys % c.size
    print(f"P^T A P: {A1.shape[0]} rows, {A1.nnz / A1.shape[0]:.0f} entries per row", flush=True)
    bdev, xdev = c.zeros(), c.zeros()

    def cycle1(v: np.ndarray) -> np.ndarray:
        h = np.zeros((c.dim, c.size))
        h[ck, cp] = v
        bdev.from_numpy((h * c.free).astype(c.dtype))
        xdev.from_numpy(np.zeros((c.dim, c.size), c.dtype))
        host._cycle(1, bdev, xdev)
        return xdev.to_numpy()[ck, cp].astype(np.float64)

    def inner(b: np.ndarray, k: int, record: list | None = None) -> np.ndarray:
        x, r = np.zeros_like(b), b.copy()
        z = cycle1(r)
        p, rz = z.copy(), r @ z
        for i in range(k):
            q = A1 @ p
            alpha = rz / (p @ q)
            x += alpha * p
            r -= alpha * q
            if i == k - 1 and record is None:
                break
            z = cycle1(r)
            rz_next = r @ z
            if record is not None:
                record.append((alpha, rz_next / rz))
            p, rz = z + (rz_next / rz) * p, rz_next
        return x

    r = f.zeros()
    for v in variants:
        kind, _, k = v.partition(":")
        if kind == "ritz":
            steps: list = []
            inner(np.random.default_rng(3).standard_normal(A1.shape[0]), int(k), steps)
            ev = ritz(*map(list, zip(*steps)))
            print(f"{v}: Ritz values of the level-1 cycle times P^T A P {ev[0]:.3f} ... {ev[-1]:.2f}", flush=True)
            continue
        factor = Cholesky(A1) if kind == "exact" else None
        solve = factor.solve if factor else (lambda b, k=int(k): inner(b, k))

        def precondition(b, x) -> None:
            m._smooth(0, b, x, first=True)
            f.residual(x, b, r)
            xv = x.to_numpy()
            xv[two.comp, two.pos] += P @ solve(Pt @ r.to_numpy()[two.comp, two.pos])
            x.from_numpy(xv.astype(f.dtype))
            m._smooth(0, b, x, first=False)

        t = time.perf_counter()
        print(f"{v}: {fcg(problem, precondition)} FCG iterations ({time.perf_counter() - t:.1f} s)", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), sys.argv[3:])
