"""Three levels whose coarse operators are P^T A P of the linear-across divergence-preserving
prolongation (prolongation.py), the first coarse level smoothed by a smoother built from its own
operator A1 (three_levels.py built it from the rediscretised weights, which did not fit A1):

    M1^-1 = D1^-1 + C Theta1^-1 C^T + sum_p R_p^T (A1)_p^-1 R_p,   Theta1 = diag(C^T A1 C),

D1 = diag(A1), C the level's curls (``smoother_kernels.curl_taps``) on its unknowns, p the band's
vertex patches (``patches.vertex_patches`` of the level). Chebyshev on M1^-1 A1 with the engine's
Lanczos bound; the second coarse level P2^T A1 P2 solved exactly. The fine level keeps the engine's
smoothing (its degree ``D0``), level 1 takes degree ``D1`` on [bound / S, bound] (S: the engine's
CURL_SPREAD unless given as D0:D1:S).

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/galerkin_levels.py RES NU MODE D0:D1...

MODE "full": level 1 is P^T A P; "cut:K": P^T A P only in the cut coarse cells and K rings around
them, the rediscretised energy elsewhere (``band_galerkin.py``); either with "+cutpatches": level 1's
vertex patches around every cut cell too (``cut_band.py``).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from engine.staggered.patches import _spd_inverse, vertex_patches
from engine.staggered.smoother_kernels import PAIRS, curl_taps

sys.path.insert(0, str(Path(__file__).parent))
from harness import Cholesky, held_shell, host_chebyshev, lanczos_bound, mg, operator_block, pcg_spectrum  # noqa: E402
from prolongation import tr_prolongation  # noqa: E402


def curls(level, keys: np.ndarray) -> sp.csr_matrix:
    """C [len(keys), edges]: the level's curls on its unknowns ``keys`` (a * size + position, sorted),
    edges with at least two unknowns."""
    lay, d, size = level.layout, level.dim, level.size
    index = lay.indices()
    cols = []
    for q in range(len(PAIRS[d])):
        rows, vals = [], []
        for k, o, c in curl_taps(d, q):
            p = lay.positions(index + np.asarray(o))
            key = k * size + np.maximum(p, 0)
            j = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
            rows.append(np.where((p >= 0) & (keys[j] == key), j, -1))
            vals.append(c)
        rows = np.stack(rows, axis=1)
        keep = (rows >= 0).sum(axis=1) >= 2
        rows = rows[keep]
        e = np.repeat(np.arange(len(rows)), rows.shape[1]).reshape(rows.shape)
        v = np.broadcast_to(np.asarray(vals), rows.shape)
        on = rows >= 0
        cols.append(sp.csr_matrix((v[on], (rows[on], e[on])), (len(keys), len(rows))))
    return sp.hstack(cols).tocsr()


def band(level, keys: np.ndarray, A: sp.csr_matrix) -> sp.csr_matrix:
    """sum_p R_p^T A_p^-1 R_p over the level's band patches (``vertex_patches``) with A's blocks."""
    patches = vertex_patches(level)
    n = len(keys)
    if patches is None:
        return sp.csr_matrix((n, n))
    local = np.where(patches >= 0, np.searchsorted(keys, np.maximum(patches, 0)), -1)
    local = np.where((local >= 0) & (keys[np.minimum(local, n - 1)] == patches), local, -1)
    on = local >= 0
    m = local.shape[1]
    safe = np.maximum(local, 0)
    A = A.tocsr()
    blocks = np.zeros((len(local), m, m))
    for i in range(m):
        for j in range(m):
            blocks[:, i, j] = np.asarray(A[safe[:, i], safe[:, j]]).ravel()
    both = on[:, :, None] & on[:, None, :]
    blocks = np.where(both, blocks, 0.0)
    blocks[:, np.arange(m), np.arange(m)] += ~on
    inv = _spd_inverse(blocks)
    r = np.broadcast_to(local[:, :, None], both.shape)[both]
    c = np.broadcast_to(local[:, None, :], both.shape)[both]
    return sp.csr_matrix((inv[both], (r, c)), (n, n))


def mixed(m3, P1, k1, rings: int) -> sp.csr_matrix:
    """Level 1 as ``band_galerkin.py cut:RINGS`` mixes it: P^T A P in the coarse cells holding a
    surface term's DOF, the cut ones and ``rings`` rings around them, the rediscretised energy
    elsewhere, the surface terms P^T S P."""
    from band_galerkin import flagged, mixed_operator

    f, c = m3.levels[0], m3.levels[1]
    comp, pos = np.nonzero(f.free)
    keys = comp.astype(np.int64) * f.size + pos
    sf = f.surface
    j = np.searchsorted(keys, sf.comp.astype(np.int64) * f.size + sf.pos)
    pick = sp.csr_matrix((np.ones(len(j)), (j, np.arange(len(j)))), (len(keys), len(j)))
    surface = (P1.T @ (pick @ sf.matrix() @ pick.T) @ P1).tocsr()
    return mixed_operator(f, c, keys, P1, k1, surface, flagged(f, c, "cut", rings))


def main(res: int, nu: float, mode: str, degrees: list[str]) -> None:
    global vertex_patches
    if mode.endswith("+cutpatches"):  # level 1's patches around every cut cell too (cut_band.py)
        from cut_band import wide_patches

        vertex_patches, mode = wide_patches, mode[: -len("+cutpatches")]
    problem = held_shell(res, nu)
    m3 = mg.Multigrid(problem.level, max_levels=3)
    f, c1, c2 = m3.levels
    comp, pos = np.nonzero(f.free)
    t = time.perf_counter()
    A = operator_block(f, comp.astype(np.int64) * f.size + pos)
    P1, k1 = tr_prolongation(f, c1, comp, pos)
    A1 = (P1.T @ A @ P1).tocsr() if mode == "full" else mixed(m3, P1, k1, int(mode.split(":")[1]))
    comp1, pos1 = k1 // c1.size, k1 % c1.size
    P2, _ = tr_prolongation(c1, c2, comp1, pos1)
    F2 = Cholesky((P2.T @ A1 @ P2).tocsr())
    F1 = Cholesky(A1)
    P1t, P2t = P1.T.tocsr(), P2.T.tocsr()
    C = curls(c1, k1)
    theta = np.asarray((C.multiply(A1 @ C)).sum(axis=0)).ravel()
    C = C[:, theta > 0]
    theta_inv = 1.0 / theta[theta > 0]
    Z = band(c1, k1, A1)
    dinv = 1.0 / A1.diagonal()
    Ct = C.T.tocsr()
    print(f"level 1: {A1.shape[0]} unknowns, {A1.nnz / A1.shape[0]:.1f} entries per row, {C.shape[1]} curls, "
          f"band {Z.nnz} entries; setup {time.perf_counter() - t:.1f} s", flush=True)

    def minv(r: np.ndarray) -> np.ndarray:
        return dinv * r + C @ (theta_inv * (Ct @ r)) + Z @ r

    bound = lanczos_bound(A1, minv)
    print(f"level 1: Chebyshev bound {bound:.2f}", flush=True)
    rf = f.zeros()
    fine_degree = mg.CURL_DEGREE

    for pair in degrees:
        d0, d1, *spread = pair.split(":")
        d0, d1, spread = int(d0), int(d1), float(spread[0]) if spread else mg.CURL_SPREAD
        coefficients = mg.chebyshev_coefficients(bound, spread, d1) if d1 else []

        def smooth(b, x, first):
            return host_chebyshev(A1, minv, coefficients, b, x, first)

        def level1(b):
            if not d1:
                return F1.solve(b)
            x = smooth(b, np.zeros_like(b), True)
            x = x + P2 @ F2.solve(P2t @ (b - A1 @ x))
            return smooth(b, x, False)

        def cycle(b, x) -> None:
            m3._smooth(0, b, x, first=True)
            f.residual(x, b, rf)
            xv = x.to_numpy()
            xv[comp, pos] += P1 @ level1(P1t @ rf.to_numpy()[comp, pos])
            x.from_numpy(xv.astype(f.dtype))
            m3._smooth(0, b, x, first=False)

        mg.CURL_DEGREE = d0
        try:
            its, ev = pcg_spectrum(problem, cycle)
        finally:
            mg.CURL_DEGREE = fine_degree
        print(f"fine degree {d0}, level 1 degree {d1 or 'exact'} (spread {spread:g}): {its} iterations, Ritz values {ev[0]:.3f} ... "
              f"{ev[-1]:.3f}, condition {ev[-1] / ev[0]:.2f}", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), sys.argv[3], sys.argv[4:])
