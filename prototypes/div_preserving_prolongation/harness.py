"""Two-level spectra of the staggered V-cycle on the held shell of ``benchmarks.staggered``
(radii 1 and 0.6, held below z = -0.8, gravity), with the coarse correction swapped.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/harness.py RES NU VARIANT...

Variants: ``cycle`` (the engine's V-cycle, every level), ``cycle2`` (the engine's, two levels),
``own-galerkin`` (the cycle's own prolongation, kernels.FACE on the curl path and LINEAR below
lambda / mu = 4, with the coarse operator P^T A P), ``tr-galerkin[:slopes]`` (the
prolongation of prolongation.py, P^T A P), ``tr-rediscretised[:slopes]`` (that prolongation with
the engine's coarse level: rediscretised bulk plus P^T S P of the fine surface terms),
``check`` (fine-cell divergences of a prolonged random field against the coarse cells'),
``degree=N`` (the curl smoothing's Chebyshev degree for the variants after it),
``ratio`` (40 steps of power iteration on Ac^-1 P^T A P with the engine's two levels: how much more
fine energy a prolonged coarse mode has than its coarse level gives it, and where).
The two-level variants keep the engine's smoothing (the curl path's Chebyshev steps on the fine
level, run on the device) and solve the coarse level exactly on the host (PARDISO). Each prints
the PCG iteration at which the residual of a random right-hand side fell under rtol 1e-6 and the
extreme Ritz values of B A from the same run's 40 steps.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from benchmarks.staggered import job, shell_mesh
from engine import simulate
from engine.geometry.cache import GeometryCache
from engine.runtime import device_array
from engine.solvers.direct import Cholesky
from engine.staggered import elasticity, kernels
from engine.staggered import multigrid as mg
from engine.staggered.galerkin import prolongation_matrix
from engine.staggered.patches import operator_block

sys.path.insert(0, str(Path(__file__).parent))
from prolongation import tr_prolongation  # noqa: E402


def held_shell(res: int, nu: float):
    """The solved job's StaggeredElasticity (captured from its solve)."""
    captured = {}
    solve = elasticity.StaggeredElasticity.solve

    def grab(self, *args, **kwargs):
        captured["problem"] = self
        return solve(self, *args, **kwargs)

    elasticity.StaggeredElasticity.solve = grab
    try:
        with tempfile.TemporaryDirectory() as tmp:
            mesh = Path(tmp) / "shell.stl"
            shell_mesh(mesh)
            r = simulate(job(str(mesh), res, nu, 1e-6, "cpu"), mesh, cache=GeometryCache(None))
    finally:
        elasticity.StaggeredElasticity.solve = solve
    print(f"job: {r.solver.iterations} CG iterations", flush=True)
    return captured["problem"]


def pcg_spectrum(problem, precondition, steps: int = 40, rtol: float = 1e-6, seed: int = 0) -> tuple[int, np.ndarray]:
    """(the PCG iteration whose residual first fell under ``rtol``, or ``steps``; the Ritz values of
    B A from the Lanczos coefficients of all ``steps`` steps), from a random right-hand side."""
    lv, space = problem.level, problem.space
    rng = np.random.default_rng(seed)
    b = device_array((rng.standard_normal(lv.free.shape) * lv.free).astype(lv.dtype))
    x, r, z, q, p = (space.zeros() for _ in range(5))
    space.copy(b, r)
    bnorm = np.sqrt(space.dot(b, b))
    precondition(r, z)
    space.copy(z, p)
    rz = space.dot(r, z)
    alphas, betas, reached = [], [], steps
    for i in range(steps):
        lv.apply(p, q)
        alpha = rz / space.dot(p, q)
        space.axpy(alpha, p, x)
        space.axpy(-alpha, q, r)
        if reached == steps and np.sqrt(space.dot(r, r)) / bnorm < rtol:
            reached = i + 1
        precondition(r, z)
        rz_next = space.dot(r, z)
        alphas.append(alpha)
        betas.append(rz_next / rz)
        space.xpby(z, rz_next / rz, p)
        rz = rz_next
    return reached, ritz(alphas, betas)


def ritz(alphas: list[float], betas: list[float]) -> np.ndarray:
    """Eigenvalues of the Lanczos tridiagonal matrix of CG's step lengths and direction updates."""
    a, b = np.asarray(alphas), np.asarray(betas)
    diagonal = 1.0 / a + np.concatenate([[0.0], b[:-1] / a[:-1]])
    off = np.sqrt(b[:-1]) / a[:-1]
    return np.linalg.eigvalsh(np.diag(diagonal) + np.diag(off, 1) + np.diag(off, -1))


def lanczos_bound(A: sp.csr_matrix, minv, steps: int = mg.LANCZOS_STEPS) -> float:
    """The Chebyshev bound as the engine takes it (``multigrid._lanczos_largest``) for a host level:
    MARGIN times the largest Ritz value of M^-1 A after ``steps`` CG steps from a random vector."""
    r = np.random.default_rng(7).standard_normal(A.shape[0])
    z = minv(r)
    p, rz, alphas, betas = z.copy(), r @ z, [], []
    for _ in range(steps):
        q = A @ p
        alphas.append(rz / (p @ q))
        r = r - alphas[-1] * q
        z = minv(r)
        betas.append((r @ z) / rz)
        p, rz = z + betas[-1] * p, r @ z
    return float(ritz(alphas, betas)[-1]) * mg.MARGIN


def host_chebyshev(A: sp.csr_matrix, minv, coefficients, b: np.ndarray, x: np.ndarray, first: bool) -> np.ndarray:
    """The engine's Chebyshev smoothing (``multigrid._curl_chebyshev``) of A x = b on the host."""
    step = np.zeros_like(b)
    for i, (c_step, c_new) in enumerate(coefficients):
        step = c_new * minv(b) if first and i == 0 else c_step * step + c_new * minv(b - A @ x)
        x = x + step
    return x


class TwoLevel:
    """The engine's two-level hierarchy of the problem, its fine operator assembled."""

    def __init__(self, problem) -> None:
        self.problem = problem
        self.mg = mg.Multigrid(problem.level, max_levels=2)
        self.fine, self.coarse = self.mg.levels
        f = self.fine
        self.comp, self.pos = np.nonzero(f.free)
        self.keys = self.comp.astype(np.int64) * f.size + self.pos
        self.A = operator_block(f, self.keys)
        sf = f.surface
        j = np.searchsorted(self.keys, sf.comp.astype(np.int64) * f.size + sf.pos)
        pick = sp.csr_matrix((np.ones(len(j)), (j, np.arange(len(j)))), (len(self.keys), len(j)))
        self.S = (pick @ sf.matrix() @ pick.T).tocsr()  # the fine surface terms on the fine DOFs

    def own(self) -> tuple[sp.csr_matrix, np.ndarray]:
        return prolongation_matrix(self.fine, self.coarse, self.comp, self.pos, self.mg.kind)

    def tr(self, slopes: str) -> tuple[sp.csr_matrix, np.ndarray]:
        return tr_prolongation(self.fine, self.coarse, self.comp, self.pos, slopes)

    def rediscretised(self, P: sp.csr_matrix, keys: np.ndarray) -> sp.csr_matrix:
        """The coarse level's own bulk operator on ``keys`` plus P^T S P."""
        c = self.coarse
        surface, c.surface = c.surface, None
        try:
            bulk = operator_block(c, keys)
        finally:
            c.surface = surface
        return (bulk + P.T @ self.S @ P).tocsr()

    def cycle(self, P: sp.csr_matrix, Ac: sp.csr_matrix):
        """Pre-smoothing, the exact coarse correction P Ac^-1 P^T, post-smoothing."""
        factor, Pt, f, m = Cholesky(Ac), P.T.tocsr(), self.fine, self.mg
        r = f.zeros()
        comp, pos = self.comp, self.pos

        def apply(b, x) -> None:
            m._smooth(0, b, x, first=True)
            f.residual(x, b, r)
            e = P @ factor.solve(Pt @ r.to_numpy()[comp, pos])
            xv = x.to_numpy()
            xv[comp, pos] += e
            x.from_numpy(xv.astype(f.dtype))
            m._smooth(0, b, x, first=False)

        return apply

    def energy_ratio(self, steps: int = 40) -> str:
        """The largest (P v)^T A (P v) / v^T Ac v of the engine's two levels (Ac: its coarse level,
        applied matrix-free; P: the cycle's own prolongation) by power iteration on Ac^-1 P^T A P,
        and how the top mode's x (A x) per fine DOF changes sign from one z-layer to the next."""
        f, c, m, d = self.fine, self.coarse, self.mg, self.fine.dim

        def galerkin(v):
            x, y, out = f.zeros(), f.zeros(), c.zeros()
            kernels.prolong_add(d, m.kind, f.coords, m.parents[0], f.mask, v, x)
            f.apply(x, y)
            kernels.restrict(d, m.kind, c.coords, m.children[0], c.mask, y, out)
            return out, x, y

        v = device_array((np.random.default_rng(1).standard_normal(c.free.shape) * c.free).astype(c.dtype))
        for _ in range(steps):
            z = c.zeros()
            m.coarse.solve(galerkin(v)[0], z)
            az = c.zeros()
            c.apply(z, az)
            quotient = kernels.dot(d, z, galerkin(z)[0]) / kernels.dot(d, z, az)
            v = device_array((z.to_numpy() / np.sqrt(kernels.dot(d, z, az))).astype(c.dtype))
        _, x, y = galerkin(v)
        energy = (x.to_numpy() * y.to_numpy())[:, : f.layout.count * f.layout.tile_size]
        layers = np.bincount(f.layout.indices()[:, 2], weights=energy.sum(axis=0))
        layers = layers[np.abs(layers) > 1e-3 * np.abs(layers).max()]
        flips = int((np.sign(layers[1:]) != np.sign(layers[:-1])).sum())
        return (f"largest ratio {quotient:.2f} after {steps} steps; its energy changes sign between "
                f"{flips} of {len(layers) - 1} successive z-layers")

    def divergence_check(self, P: sp.csr_matrix, keys: np.ndarray) -> float:
        """max |div_fine(P v) - div_coarse(v)| / max |div_coarse(v)| over full fine cells in full
        coarse cells, v random."""
        f, c, d = self.fine, self.coarse, self.fine.dim
        v = np.random.default_rng(0).standard_normal(len(keys))
        uf, uc = np.zeros((d, f.size)), np.zeros((d, c.size))
        uf[self.comp, self.pos] = P @ v
        uc[keys // c.size, keys % c.size] = v

        def div(level, u):
            dense = [level.layout.dense(u[a]) for a in range(d)]
            return sum((np.roll(dense[a], -1, axis=a) - dense[a]) / level.spacing for a in range(d))

        df, dc = div(f, uf), div(c, uc)
        cells = np.argwhere(f.layout.dense(f.vc_host) > 0.999)
        parent = (cells + 2) >> 1
        ok = np.all(parent < np.array(dc.shape), axis=1)
        cells, parent = cells[ok], parent[ok]
        ok = c.layout.dense(c.vc_host)[tuple(parent.T)] > 0.999
        a, b = df[tuple(cells[ok].T)], dc[tuple(parent[ok].T)]
        return float(np.abs(a - b).max() / np.abs(b).max())


def main(argv: list[str]) -> None:
    res, nu, variants = int(argv[0]), float(argv[1]), argv[2:]
    problem = held_shell(res, nu)
    two = None

    def report(name, precondition) -> None:
        its, ev = pcg_spectrum(problem, precondition)
        print(f"{name}: {its} iterations, Ritz values of B A {ev[0]:.3f} ... {ev[-1]:.3f}, "
              f"condition {ev[-1] / ev[0]:.2f}", flush=True)

    for v in variants:
        if v.startswith("degree="):  # the curl smoothing's Chebyshev degree for the variants after it
            mg.CURL_DEGREE = int(v.split("=")[1])
            print(f"curl smoothing degree {mg.CURL_DEGREE}", flush=True)
            continue
        if v == "cycle":
            report(v, problem.multigrid.precondition)
            continue
        two = two or TwoLevel(problem)
        kind, _, slopes = v.partition(":")
        if v == "cycle2":
            report(v, two.mg.precondition)
        elif kind == "own-galerkin":
            P, _ = two.own()
            report(v, two.cycle(P, (P.T @ two.A @ P).tocsr()))
        elif kind == "tr-galerkin":
            P, _ = two.tr(slopes or "central")
            Ac = (P.T @ two.A @ P).tocsr()
            print(f"  coarse operator: {Ac.nnz / Ac.shape[0]:.1f} entries per row "
                  f"(fine {two.A.nnz / two.A.shape[0]:.1f})", flush=True)
            report(v, two.cycle(P, Ac))
        elif kind == "tr-rediscretised":
            P, keys = two.tr(slopes or "central")
            report(v, two.cycle(P, two.rediscretised(P, keys)))
        elif kind == "ratio":
            print(f"ratio: {two.energy_ratio()}", flush=True)
        elif kind == "check":
            P, keys = two.tr(slopes or "central")
            print(f"check: fine-cell divergence of P v against the coarse cell's: {two.divergence_check(P, keys):.1e} (relative)")
        else:
            raise SystemExit(f"unknown variant {v!r}")


if __name__ == "__main__":
    main(sys.argv[1:])
