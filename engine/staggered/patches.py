"""Exact solves on vertex patches in the band around held surfaces: the smoothing near
incompressibility that the curls cannot give there (``curls.py``).

Beside a held surface the lambda term does not weigh the plain divergence: a held cell weighs its
finite-volume divergence with the faces' apertures (``held.py``) and Nitsche's points tie the
samples around them, so the curls, divergence-free for the plain divergence, are stiff at lambda's
scale there and smooth nothing. The fields that keep those constraints are other local
combinations of faces. An exact solve on the faces around each vertex (the 2^(d-1) faces of each
normal that touch it: 12 in 3D, 4 in 2D; Schoeberl 1999's patches) finds whichever of them its
patch holds, so near the surface the smoothing is

    M^-1 = D^-1 + C Theta^-1 C^T + sum_p R_p^T A_p^-1 R_p   (p: the band's vertices),

additive and symmetric. The band is every vertex whose patch has a face within one index of a DOF
the surface terms touch; its inverses are summed into one sparse matrix over the band's DOFs,
applied as the surface terms are (a gather and a CSR pass). Held shell at nu 0.4999 (Galerkin
coarse holds, ``galerkin.py``), CG iterations 64^3 / 128^3: 51 / 81 without the patches, 32 / 46
with them (and the smoothing bound from Lanczos, ``multigrid._lanczos_largest``), 25 / 32 with the
wider interval that they allow (``multigrid.CURL_SPREAD``) (docs/design-notes.md, "Held bands: Galerkin coarse holds and vertex patches").
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp

from ..grid import axis_pairs
from .operator import Level
from .sampling import _unique_rows

CHUNK = 20_000  # patches inverted per batch (bounds the [patches, 12, 12] temporaries: 23 MB each)


def vertex_patches(level: Level) -> np.ndarray | None:
    """The band's patches: DOF keys a * size + position [patches, d 2^(d-1)], -1 where the face is
    not an unknown; None when the level has no surface terms or no patch has two unknowns."""
    sf = level.surface
    if sf is None or not len(sf.pos):
        return None
    return patches_near(level, sf.pos)


def patches_near(level: Level, seeds: np.ndarray) -> np.ndarray | None:
    """The patches of :func:`vertex_patches` around the flat positions ``seeds`` [k] instead of the
    surface terms' DOFs."""
    lay, d, size = level.layout, level.dim, level.size
    near = np.zeros(size, dtype=np.uint8)
    near[seeds] = 1
    dense = lay.dense(near)
    # vertex V's patch holds the faces V - {0, 1}^d (one step back across each other axis): a
    # surface DOF within one index of one lies in V + [-2, 1] per axis
    for a in range(d):
        dense = ndi.maximum_filter1d(dense, 4, axis=a, mode="constant")
    vertices = np.argwhere(dense > 0)
    columns = []
    for a in range(d):
        for o in itertools.product(*[(0,) if k == a else (-1, 0) for k in range(d)]):
            at = lay.positions(vertices + np.asarray(o))
            ok = at >= 0
            ok[ok] = level.free[a, at[ok]]
            columns.append(np.where(ok, a * size + at, -1))
    keys = np.stack(columns, axis=1)
    keys = keys[(keys >= 0).sum(axis=1) >= 2]
    return keys if len(keys) else None


def band_inverse(level: Level) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix] | None:
    """(comp [n], pos [n], Z [n, n]) with Z = sum_p R_p^T A_p^-1 R_p over the band's patches
    (``vertex_patches``), A the level's operator (bulk, shift, surface terms) on its unknowns;
    None when there is no band."""
    patches = vertex_patches(level)
    if patches is None:
        return None
    size = level.size
    dofs = np.unique(patches[patches >= 0])
    block = operator_block(level, dofs)
    block.sum_duplicates()  # canonical CSR: its (row, column) keys come sorted
    n = len(dofs)
    entry_keys = np.repeat(np.arange(n, dtype=np.int64) * n, np.diff(block.indptr)) + block.indices
    entry_vals = block.data
    local = np.where(patches >= 0, np.searchsorted(dofs, np.maximum(patches, 0)), -1)
    m = local.shape[1]
    # A_p and its inverse are symmetric: the upper triangles alone are looked up and summed
    iu, ju = np.triu_indices(m)
    rows, cols, vals = [], [], []
    for start in range(0, len(local), CHUNK):
        idx = local[start : start + CHUNK]
        on = idx >= 0
        both = on[:, iu] & on[:, ju]
        pair = np.maximum(idx, 0)[:, iu] * n + np.maximum(idx, 0)[:, ju]
        at = np.minimum(np.searchsorted(entry_keys, pair), len(entry_keys) - 1)
        upper = np.where((entry_keys[at] == pair) & both, entry_vals[at], 0.0)
        a = np.empty((len(idx), m, m))
        a[:, iu, ju] = upper
        a[:, ju, iu] = upper
        a[:, np.arange(m), np.arange(m)] += ~on  # a missing face: a unit pivot, dropped below
        inv = _spd_inverse(a)
        rows.append(idx[:, iu][both])
        cols.append(idx[:, ju][both])
        vals.append(inv[:, iu, ju][both])
    upper = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), (n, n))
    # patch-local order is not the global one: an upper-triangle entry may land below the diagonal,
    # so the full matrix is the sum with the transpose less the diagonal counted twice
    z = (upper + upper.T - sp.diags(upper.diagonal())).tocsr()
    return dofs // size, dofs % size, z


def _spd_inverse(a: np.ndarray) -> np.ndarray:
    """Inverses [k, m, m] of the symmetric positive definite matrices a [k, m, m] (overwritten):
    Gauss-Jordan elimination without pivoting, one batched rank-one update per column (LAPACK's
    batched inverse took 1.0 s for the 43 k patches of the 128^3 shell, one call per matrix)."""
    m = a.shape[1]
    for j in range(m):
        pivot = 1.0 / a[:, j, j]
        col = a[:, :, j].copy()
        col[:, j] = 0.0
        row = a[:, j, :] * pivot[:, None]
        row[:, j] = pivot
        a -= col[:, :, None] * row[:, None, :]
        a[:, j, :] = row
        a[:, :, j] = -col * pivot[:, None]
        a[:, j, j] = pivot
    return a


def operator_block(level: Level, keys: np.ndarray) -> sp.csr_matrix:
    """A[keys][:, keys] [n, n] of the level's operator (keys a * size + position, sorted unknowns):
    the bulk energy's cells and edges that touch them (the weights the kernels read), the shift's
    mass and the surface terms."""
    lay, d, size, h = level.layout, level.dim, level.size, level.spacing
    comp, pos = keys // size, keys % size
    index = lay.index_of(pos).astype(np.int64)
    eye = np.eye(d, dtype=np.int64)
    n = len(keys)

    def column(a: int, at: np.ndarray) -> np.ndarray:
        """Compact column of component a's DOFs at indices ``at`` [k, d]; -1 outside ``keys``."""
        p = lay.positions(at)
        key = a * size + np.maximum(p, 0)
        j = np.minimum(np.searchsorted(keys, key), n - 1)
        return np.where((p >= 0) & (keys[j] == key), j, -1)

    def strains(taps: list[tuple[int, np.ndarray, float]], count: int) -> sp.csr_matrix:
        """[count, n]: one row per control volume, sum of coef u_a(at) over its taps within ``keys``."""
        r, c, v = [], [], []
        for a, at, coef in taps:
            j = column(a, at)
            on = j >= 0
            r.append(np.nonzero(on)[0])
            c.append(j[on])
            v.append(np.full(int(on.sum()), coef))
        return sp.csr_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), (count, n))

    # cells beside the DOFs: h eps_kk = u_k(C + e_k) - u_k(C)
    cells = _unique_rows(np.concatenate([index - eye[a] * (comp == a)[:, None] for a in range(d)] + [index]))[0]
    vc = _at(level.vc_host, lay, cells)
    moduli = level.mu * 2.0 * np.eye(d) + level.lam * np.ones((d, d))
    # every strain of the block stacked, K = h^d B^T W B in one product: W couples a cell's normal
    # strains through the moduli, an edge's shear strain is weighted alone
    blocks = [strains([(k, cells + eye[k], 1.0 / h), (k, cells, -1.0 / h)], len(cells)) for k in range(d)]
    weights = [sp.kron(moduli, sp.diags(vc))]
    # shear edges beside the DOFs: 2 h eps_ab = u_a(E) - u_a(E - e_b) + u_b(E) - u_b(E - e_a)
    for q, (a, b) in enumerate(axis_pairs(d)):
        near = np.concatenate([index[comp == a] + s * eye[b] for s in (0, 1)] + [index[comp == b] + s * eye[a] for s in (0, 1)])
        if not len(near):
            continue
        edges = _unique_rows(near)[0]
        blocks.append(strains([(a, edges, 0.5 / h), (a, edges - eye[b], -0.5 / h), (b, edges, 0.5 / h),
                               (b, edges - eye[a], -0.5 / h)], len(edges)))
        weights.append(sp.diags(4.0 * level.mu * _at(level.ve_host[q], lay, edges)))
    B = sp.vstack(blocks).tocsr()
    k_mat = h**d * (B.T @ (sp.block_diag(weights, format="csr") @ B))
    if level.shift != 0.0 and level.mass is not None:
        k_mat = k_mat + sp.diags(level.shift * level.mass.to_numpy()[comp, pos])
    sf = level.surface
    if sf is not None:
        skeys = sf.comp.astype(np.int64) * size + sf.pos
        j = np.minimum(np.searchsorted(keys, skeys), n - 1)
        on = keys[j] == skeys
        pick = sp.csr_matrix((np.ones(int(on.sum())), (j[on], np.nonzero(on)[0])), (n, len(skeys)))
        k_mat = k_mat + pick @ sf.matrix() @ pick.T
    return sp.csr_matrix(k_mat)


def _at(values: np.ndarray, lay, index: np.ndarray) -> np.ndarray:
    """values [size] at indices [k, d] (0 outside the kept tiles)."""
    p = lay.positions(index)
    return np.where(p >= 0, values[np.maximum(p, 0)], 0.0)
