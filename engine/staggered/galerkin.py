"""Coarse surface terms as the Galerkin product of the finer level's: S_c = P^T S_f P.

Near incompressibility a held surface's terms carry lambda's scale (the finite-volume divergence
of held cells, ``held.py``; Nitsche's penalty elsewhere). Rediscretised on a coarse level they
hold a field the prolonged one does not meet on the fine level, and the mismatch is
lambda-weighted: the coarse correction then moves the held band wrongly and the V-cycle slows.
With the face transfers (``kernels.FACE``) the coarse level's volumetric term already is the
Galerkin product of the fine one (a prolonged field's divergence in every fine cell is its coarse
cell's); taking the surface terms as P^T S P too makes the coarse lambda energy of every coarse
field the fine energy of its prolongation. Held shell at nu 0.4999, CG iterations 64^3 / 128^3:
76 / 108 rediscretised, 51 / 81 Galerkin (docs/design-notes.md, "Held bands: Galerkin coarse
holds and vertex patches").

P is the cycle's own prolongation (``kernels.prolongation_weights``), built on the host for the
finer level's surface DOFs only; the product keeps S's factored form (mass, flux, stress).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import kernels
from .nitsche import SurfaceOperator
from .operator import Level


def prolongation_matrix(fine: Level, coarse: Level, comp: np.ndarray, pos: np.ndarray, kind: int
                        ) -> tuple[sp.csr_matrix, np.ndarray]:
    """Rows of the prolongation ``kind`` (LINEAR or FACE) at the fine DOFs (comp [n], pos [n]):
    (P [n, m] with unit-free weights, the coarse DOF keys a * coarse.size + position [m], sorted).
    Coarse DOFs that are not active are left out (the cycle's coarse vectors vanish there); the
    fine rows are not masked."""
    d = fine.dim
    comp = np.asarray(comp, dtype=np.int64)
    # the kernels' rule at fine index I + 2 (``prolongation_weights``)
    index = fine.layout.index_of(pos).astype(np.int64) + 2
    odd = index & 1
    along = comp[:, None] == np.arange(d)[None]
    rows, keys, vals = [], [], []
    for corner in range(2**d):
        second = np.array([(corner >> k) & 1 for k in range(d)])
        if kind == kernels.FACE:
            across_j = index >> 1
            across_w = np.broadcast_to(1.0 - second, index.shape)
        else:
            across_j = (index >> 1) + second * (2 * odd - 1)
            across_w = np.broadcast_to(0.75 - 0.5 * second, index.shape)
        j = np.where(along, (index >> 1) + second, across_j)
        w = np.where(along, np.where(odd == 0, 1.0 - second, 0.5), across_w).prod(axis=1)
        at = coarse.layout.positions(j)
        keep = (w != 0.0) & (at >= 0)
        keep[keep] = coarse.active[comp[keep], at[keep]]
        rows.append(np.nonzero(keep)[0])
        keys.append(comp[keep] * coarse.size + at[keep])
        vals.append(w[keep])
    keys_all = np.concatenate(keys)
    coarse_keys, column = np.unique(keys_all, return_inverse=True)
    p = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), column)), (len(comp), len(coarse_keys)))
    return p, coarse_keys


def galerkin_surface(fine: Level, coarse: Level, kind: int) -> SurfaceOperator:
    """P^T S P of ``fine.surface`` on ``coarse`` (P: the transfers ``kind``, masked by the fine
    level's unknowns as the cycle's prolongation is); its load is P^T of the fine load."""
    s = fine.surface
    p, keys = prolongation_matrix(fine, coarse, s.comp, s.pos, kind)
    p = (sp.diags(fine.free[s.comp, s.pos].astype(np.float64)) @ p).tocsr()
    pt = p.T.tocsr()
    return SurfaceOperator(keys // coarse.size, keys % coarse.size, (pt @ s.mass @ p).tocsr(), (pt @ s.flux).tocsr(),
                           (s.stress @ p).tocsr(), pt @ s.rhs)
