"""Two levels, the coarse operator P^T A P only in a band of coarse cells around the hold and the
rediscretised energy elsewhere, mixed cell by cell (P: the linear-across divergence-preserving
prolongation of prolongation.py):

    A_c = P^T A_in P + Ac_out + P^T S P,

A_in the fine energy of the fine cells inside flagged coarse cells (and of their shear edges, each
by the share of flagged coarse cells around it), Ac_out the rediscretised energy of the other
coarse cells (their edges by the other share), S the fine surface terms. Both parts are energies of
the same coarse field, so their sum is a consistent operator at the band's edge (a row-wise mix is
not). Flags: the coarse cells within W coarse cells of a coarse cell holding a surface term's DOF
(``hold:W``), or of any cut coarse cell too (``cut:W``); ``all`` is the whole P^T A P and ``none``
the rediscretised one; ``scaleX:W`` the rediscretised energy alone, X times in the ``cut:W`` cells.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/band_galerkin.py RES NU SLOPES FLAGS...

SLOPES "face" takes the cycle's own prolongation (kernels.FACE) instead.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp

from engine.grid import axis_pairs

sys.path.insert(0, str(Path(__file__).parent))
from harness import TwoLevel, held_shell, operator_block, pcg_spectrum  # noqa: E402
from prolongation import tr_prolongation  # noqa: E402


def energy(level, keys: np.ndarray, cell_weight: np.ndarray, edge_weight: np.ndarray) -> sp.csr_matrix:
    """The level's bulk operator on ``keys`` with its cells' fractions times ``cell_weight`` [size]
    and its edges' times ``edge_weight`` [pairs, size] (no surface terms)."""
    vc, ve, surface = level.vc_host, level.ve_host, level.surface
    level.vc_host, level.ve_host, level.surface = vc * cell_weight[: len(vc)], ve * edge_weight[:, : ve.shape[1]], None
    try:
        return operator_block(level, keys)
    finally:
        level.vc_host, level.ve_host, level.surface = vc, ve, surface


def shares(level, flag_of_cell) -> tuple[np.ndarray, np.ndarray]:
    """(cell weight [size], edge weight [pairs, size]) on ``level``: flag_of_cell(index [k, d]) for
    each cell, and for each edge the mean over the 2^2 cells around it."""
    lay, d = level.layout, level.dim
    index = lay.indices()
    cells = np.zeros(level.size)
    cells[: len(index)] = flag_of_cell(index)
    eye = np.eye(d, dtype=np.int64)
    edges = np.zeros((len(axis_pairs(d)), level.size))
    for q, (a, b) in enumerate(axis_pairs(d)):
        edges[q, : len(index)] = np.mean([flag_of_cell(index - i * eye[a] - j * eye[b]) for i in (0, 1) for j in (0, 1)], axis=0)
    return cells, edges


def flagged(f, c, kind: str, rings: int) -> np.ndarray:
    """[coarse box] bool: the coarse cells ``kind`` names ("all", "none", "hold": those holding a
    surface term's DOF, "cut": those and every cut coarse cell) and ``rings`` rings around them."""
    box = np.asarray(c.layout.box)
    if kind in ("all", "none"):
        return np.full(tuple(box), kind == "all")
    seeds = np.zeros(tuple(box), dtype=bool)
    seeds[tuple(((f.layout.index_of(f.surface.pos).astype(np.int64) + 2) >> 1).T)] = True
    if kind == "cut":
        seeds |= c.layout.dense(((c.vc_host > 0) & (c.vc_host < 1)).astype(np.uint8))[tuple(slice(0, n) for n in box)] > 0
    if rings:
        seeds = ndi.binary_dilation(seeds, np.ones((3,) * f.dim, dtype=bool), iterations=rings)
    return seeds


def flag_shares(f, c, seeds: np.ndarray):
    """((cell, edge) weights on the fine level, the same on the coarse one) of the flagged coarse
    cells ``seeds`` (``shares``; fine cell I lies in coarse cell (I + 2) >> 1)."""
    box = np.asarray(seeds.shape)

    def flag(J):
        J = np.asarray(J, dtype=np.int64)
        ok = np.all((J >= 0) & (J < box), axis=1)
        out = np.zeros(len(J))
        out[ok] = seeds[tuple(J[ok].T)]
        return out

    return shares(f, lambda I: flag((np.asarray(I, dtype=np.int64) + 2) >> 1)), shares(c, flag)


def mixed_operator(f, c, fine_keys: np.ndarray, P: sp.csr_matrix, keys: np.ndarray, surface: sp.csr_matrix,
                   seeds: np.ndarray) -> sp.csr_matrix:
    """P^T A_in P + Ac_out + ``surface`` (P^T S P) with the coarse cells ``seeds`` flagged."""
    (fc, fe), (cc, ce) = flag_shares(f, c, seeds)
    return (P.T @ energy(f, fine_keys, fc, fe) @ P + energy(c, keys, 1.0 - cc, 1.0 - ce) + surface).tocsr()


def main(res: int, nu: float, slopes: str, flags: list[str]) -> None:
    problem = held_shell(res, nu)
    two = TwoLevel(problem)
    f, c = two.fine, two.coarse
    P, keys = two.own() if slopes == "face" else tr_prolongation(f, c, two.comp, two.pos, slopes)
    surface = (P.T @ two.S @ P).tocsr()
    print(f"two levels with the engine's prolongation: {pcg_spectrum(problem, two.mg.precondition)[0]} iterations", flush=True)
    for flag in flags:
        kind, _, width = flag.partition(":")
        if kind.startswith("scale"):  # scaleX:W: the rediscretised energy only, X times in the flagged cells
            scale = float(kind[5:])
            seeds = flagged(f, c, "cut", int(width))
            _, (cc, ce) = flag_shares(f, c, seeds)
            Ac = (energy(c, keys, 1.0 + (scale - 1.0) * cc, 1.0 + (scale - 1.0) * ce) + surface).tocsr()
        else:
            seeds = flagged(f, c, kind, int(width or 0))
            Ac = mixed_operator(f, c, two.keys, P, keys, surface, seeds)
        its, ev = pcg_spectrum(problem, two.cycle(P, Ac))
        print(f"{flag}: {int(seeds.sum())} coarse cells flagged, {Ac.nnz / Ac.shape[0]:.1f} entries per row; {its} iterations, "
              f"Ritz values {ev[0]:.3f} ... {ev[-1]:.3f}, condition {ev[-1] / ev[0]:.2f}", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), sys.argv[3], sys.argv[4:])
