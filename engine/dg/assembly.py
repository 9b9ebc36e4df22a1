"""DG stiffness: element, interface and Nitsche blocks (Taichi kernels) into one sparse matrix.

The global matrix is block sparse with blocks [3 n, 3 n] per element pair (n basis functions
per component); unknowns of element e sit at e * 3 n + p * n + I. Full cells take one
reference element block and interfaces between full cells one reference block per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import kernels
from .elements import Elements
from .integrals import Basis, PatchProjection, element_gradients, face_products, patch_products


@dataclass
class Group:
    """Blocks data [K, s, s] at (rows [K], cols [K]); ``owner`` [K]: the element whose rotation warps
    each block (its stress side, Kaufmann et al. section 6.1), None for blocks that are never warped."""

    rows: np.ndarray
    cols: np.ndarray
    data: np.ndarray
    owner: np.ndarray | None = None


@dataclass
class Blocks:
    """A block-sparse symmetric matrix in pieces: rows [K], cols [K], data [K, s, s] (duplicates summed
    on assembly; only one triangle of the off-diagonal pairs is listed, mirrored on assembly)."""

    rows: np.ndarray
    cols: np.ndarray
    data: np.ndarray


def element_blocks(el: Elements, basis: Basis, mu: float, lam: float) -> np.ndarray:
    """int_K eps(v) : C : eps(u) for every element -> [E, 3 n, 3 n] [N/m]."""
    D_ref, D_cut = element_gradients(el, basis)
    s = 3 * basis.size
    out = np.empty((el.count, s, s))
    ref = np.empty((1, s, s))
    kernels.element_blocks(np.ascontiguousarray(D_ref), mu, lam, ref)
    out[el.full] = ref[0]
    if len(D_cut):
        cut = np.empty((len(D_cut), s, s))
        kernels.element_blocks(np.ascontiguousarray(D_cut), mu, lam, cut)
        out[~el.full] = cut
    return out


def face_penalty(el: Elements, eta: float) -> np.ndarray:
    """eta_f = eta area(f) (1 / vol(K-) + 1 / vol(K+)) [1/m] per interface (Kaufmann et al. eq. 20)."""
    return eta * el.area * (1.0 / el.volume[el.minus] + 1.0 / el.volume[el.plus])


def face_blocks(el: Elements, basis: Basis, mu: float, lam: float, eta: float, weights: tuple[float, float, float],
                rest: float = 1.0) -> np.ndarray:
    """Interface blocks [F, 2, 2, 3 n, 3 n] (sides minus, plus); weights (penalty, consistency with the
    minus side's stress, with the plus side's): (1, 1, 1) is IP, (1, 0, 0) BZ. ``rest``: the penalty's
    weight on the part of the jump with zero mean over the face (its mean has weight 1)."""
    s = 3 * basis.size
    F = len(el.minus)
    out = np.empty((F, 2, 2, s, s))
    penalty = face_penalty(el, eta)
    ref = el.reference_faces
    # one reference face per axis, then every other face
    picks = [np.nonzero(ref & (el.axis == a))[0][:1] for a in range(3)]
    todo = np.concatenate(picks + [np.nonzero(~ref)[0]]).astype(np.int64)
    if len(todo) == 0:
        return out
    M, N, P = face_products(el, basis, todo, rest)
    blocks = np.empty((len(todo), 2, 2, s, s))
    kernels.face_blocks(np.ascontiguousarray(M), np.ascontiguousarray(P), np.ascontiguousarray(N),
                        el.axis[todo].astype(np.int32),
                        np.ascontiguousarray(penalty[todo]), mu, lam, *weights, blocks)
    start = 0
    for a, pick in enumerate(picks):
        if len(pick):
            out[ref & (el.axis == a)] = blocks[start]
            start += 1
    out[~ref] = blocks[start:]
    return out


def nitsche_blocks(el: Elements, basis: Basis, mu: float, lam: float, eta: float, triangles: np.ndarray,
                   element: np.ndarray, patches: np.ndarray, mask: np.ndarray, weights: tuple[float, float] = (1.0, 1.0)
                   ) -> tuple[np.ndarray, np.ndarray, PatchProjection]:
    """Weak Dirichlet blocks [b, 3 n, 3 n] of surface patches (one element each; ``patches`` [T]
    groups the triangles, ``mask`` [b, 3] the prescribed components; weights: penalty, consistency),
    their penalties [b] [1/m]:
    eta_b = eta area(patch) / vol(K) (eq. 20 with the outside as an element of infinite volume),
    and the patches' projection onto degree k - 1 (the volumetric penalty's, for the load side)."""
    count = len(mask)
    Mnn, Nn, area, low = patch_products(el, basis, triangles, element, patches, count)
    Pnn = np.einsum("bpiu,bqju->bpqij", low.R, low.R)
    owner = np.zeros(count, dtype=np.int64)
    owner[patches] = element
    penalty = eta * area / el.volume[owner]
    s = 3 * basis.size
    out = np.empty((count, s, s))
    kernels.nitsche_blocks(np.ascontiguousarray(Mnn), np.ascontiguousarray(Pnn), np.ascontiguousarray(Nn),
                           np.ascontiguousarray(mask, dtype=np.float64), penalty, mu, lam, *weights, out)
    return out, penalty, low


def to_matrix(blocks: Blocks, count: int) -> sp.csr_matrix:
    """Sum duplicate blocks, mirror the off-diagonal ones, and return the CSR matrix [count s]^2."""
    s = blocks.data.shape[1]
    off = blocks.rows != blocks.cols
    rows = np.concatenate([blocks.rows, blocks.cols[off]])
    cols = np.concatenate([blocks.cols, blocks.rows[off]])
    key = rows.astype(np.int64) * count + cols
    order = np.argsort(key, kind="stable")
    key = key[order]
    first = np.concatenate([[True], key[1:] != key[:-1]]) if len(key) else np.zeros(0, bool)
    starts = np.nonzero(first)[0]
    data = np.empty((len(starts), s, s))
    n_direct = len(blocks.rows)
    # sum in chunks so the mirrored copies are formed without a second full data array
    for lo in range(0, len(starts), 4096):
        hi = min(lo + 4096, len(starts))
        seg = order[starts[lo]:(starts[hi] if hi < len(starts) else len(order))]
        src = np.where(seg < n_direct, seg, 0)
        part = blocks.data[src]
        mirrored = seg >= n_direct
        if np.any(mirrored):
            part[mirrored] = blocks.data[np.nonzero(off)[0][seg[mirrored] - n_direct]].transpose(0, 2, 1)
        data[lo:hi] = np.add.reduceat(part, starts[lo:hi] - starts[lo], axis=0)
    urow, ucol = key[starts] // count, key[starts] % count
    indptr = np.zeros(count + 1, dtype=np.int64)
    np.add.at(indptr, urow + 1, 1)
    indptr = np.cumsum(indptr)
    bsr = sp.bsr_matrix((data, ucol, indptr), shape=(count * s, count * s))
    return bsr.tocsr()
