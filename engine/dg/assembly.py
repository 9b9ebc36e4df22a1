"""DG stiffness: element, interface and Nitsche blocks (Taichi kernels) into one sparse matrix.

The global matrix is block sparse with blocks [3 n, 3 n] per element pair (n basis functions
per component); unknowns of element e sit at e * 3 n + p * n + I. Full cells take one
reference element block and interfaces between full cells one reference block per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..solvers.pmultigrid import diagonal_blocks
from . import kernels
from .elements import Elements
from .integrals import Basis, PatchProjection, element_gradients, face_products, patch_products

FACE_CHUNK = 1024  # faces integrated at a time: their products (~20 MB at k = 2) stay below glibc's
# mmap threshold, so each chunk reuses the last one's memory; at 8192 every chunk's 80 MB came as fresh
# pages, faulted in anew (face integrals 0.74 -> 0.30 s on the 32^3 shell)


def touched(shape: tuple[int, ...]) -> np.ndarray:
    """A zeroed float64 array [shape] whose pages numpy has already faulted in: numpy's sequential fill
    faults them in at 2-3 GB/s on the development VM, while pages first touched inside a Taichi kernel
    (scattered, from two threads) came in at 0.4-0.7 GB/s, which was half of the DG assembly's time at
    32^3 (docs/benchmarks.md, "DG at scale")."""
    out = np.zeros(shape)
    out.fill(0.0)
    return out


@dataclass
class Group:
    """Blocks at (rows [K], cols [K]): block k is data[pick[k]] (data [U, s, s]; pick [K], None: data[k]),
    so blocks that full cells share are stored once. ``owner`` [K]: the element whose rotation warps
    each block (its stress side, Kaufmann et al. section 6.1), None for blocks that are never warped."""

    rows: np.ndarray
    cols: np.ndarray
    data: np.ndarray
    owner: np.ndarray | None = None
    pick: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.rows)

    def blocks(self, part: slice) -> np.ndarray:
        """The blocks [k, s, s] of ``part`` (a copy where they are shared)."""
        return self.data[part] if self.pick is None else self.data[self.pick[part]]


def element_blocks(el: Elements, basis: Basis, mu: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """int_K eps(v) : C : eps(u) for every element: (blocks [U, 3 n, 3 n] [N/m], pick [E]): element e's
    block is blocks[pick[e]]; full cells share the reference block 0."""
    D_ref, D_cut = element_gradients(el, basis)
    s = 3 * basis.size
    cut = ~el.full
    out = np.empty((1 + int(cut.sum()), s, s))
    kernels.element_blocks(np.ascontiguousarray(D_ref), mu, lam, out[:1])
    if len(D_cut):
        kernels.element_blocks(np.ascontiguousarray(D_cut), mu, lam, out[1:])
    pick = np.zeros(el.count, dtype=np.int64)
    pick[cut] = 1 + np.arange(int(cut.sum()))
    return out, pick


def face_penalty(el: Elements, eta: float) -> np.ndarray:
    """eta_f = eta area(f) (1 / vol(K-) + 1 / vol(K+)) [1/m] per interface (Kaufmann et al. eq. 20)."""
    return eta * el.area * (1.0 / el.volume[el.minus] + 1.0 / el.volume[el.plus])


def face_blocks(el: Elements, basis: Basis, mu: float, lam: float, eta: float, weights: tuple[float, float, float],
                rest: float = 1.0, volumetric: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Interface blocks (blocks [U, 3, 3 n, 3 n] of the side pairs (minus, minus), (plus, plus), (minus,
    plus); (plus, minus) is the last one's transpose), pick [F]): face f's blocks are blocks[pick[f]];
    faces between full cells share one reference block per axis. weights (penalty,
    consistency with the minus side's stress, with the plus side's): (1, 1, 1) is IP, (1, 0, 0) BZ.
    ``rest``: the penalty's weight on the part of the jump with zero mean over the face (its mean has
    weight 1). ``volumetric``: the volumetric penalty's eta over ``eta`` (its own coercivity threshold,
    DGElasticity._raise_penalty). Computed FACE_CHUNK faces at a time: the face integrals take half a
    block's memory each."""
    s = 3 * basis.size
    penalty = face_penalty(el, eta)
    ref = el.reference_faces
    # one reference face per axis, then every other face
    picks = [np.nonzero(ref & (el.axis == a))[0][:1] for a in range(3)]
    todo = np.concatenate(picks + [np.nonzero(~ref)[0]]).astype(np.int64)
    blocks = touched((len(todo), 3, s, s))
    for lo in range(0, len(todo), FACE_CHUNK):
        faces = todo[lo:lo + FACE_CHUNK]
        M, N, P = face_products(el, basis, faces, rest)
        kernels.face_blocks(np.ascontiguousarray(M), np.ascontiguousarray(volumetric * P), np.ascontiguousarray(N),
                            el.axis[faces].astype(np.int32), np.ascontiguousarray(penalty[faces]), mu, lam, *weights,
                            blocks[lo:lo + len(faces)])
    pick = np.empty(len(el.minus), dtype=np.int64)
    start = 0
    for a, first in enumerate(picks):
        if len(first):
            pick[ref & (el.axis == a)] = start
            start += 1
    pick[~ref] = start + np.arange(int((~ref).sum()))
    return blocks, pick


def nitsche_blocks(el: Elements, basis: Basis, mu: float, lam: float, eta: float, triangles: np.ndarray,
                   element: np.ndarray, patches: np.ndarray, mask: np.ndarray, weights: tuple[float, float] = (1.0, 1.0),
                   volumetric: float = 1.0) -> tuple[np.ndarray, np.ndarray, PatchProjection]:
    """Weak Dirichlet blocks [b, 3 n, 3 n] of surface patches (one element each; ``patches`` [T]
    groups the triangles, ``mask`` [b, 3] the prescribed components; weights: penalty, consistency),
    their penalties [b] [1/m]:
    eta_b = eta area(patch) / vol(K) (eq. 20 with the outside as an element of infinite volume),
    and the patches' projection onto degree k - 1 (the volumetric penalty's, for the load side);
    ``volumetric`` as in :func:`face_blocks`."""
    count = len(mask)
    Mnn, Nn, area, low = patch_products(el, basis, triangles, element, patches, count)
    Pnn = volumetric * np.einsum("bpiu,bqju->bpqij", low.R, low.R)
    owner = np.zeros(count, dtype=np.int64)
    owner[patches] = element
    penalty = eta * area / el.volume[owner]
    s = 3 * basis.size
    out = np.empty((count, s, s))
    kernels.nitsche_blocks(np.ascontiguousarray(Mnn), np.ascontiguousarray(Pnn), np.ascontiguousarray(Nn),
                           np.ascontiguousarray(mask, dtype=np.float64), penalty, mu, lam, *weights, out)
    return out, penalty, low


def to_matrix(groups: list[Group], count: int) -> sp.bsr_matrix:
    """Sum the groups' blocks (duplicates added, off-diagonal ones mirrored) into one block-sparse
    matrix [count s]^2 with blocks [s, s], sorted. Each group is added from its stored (shared) blocks
    into the matrix's own storage: concatenating the groups first held a copy of every block per pair
    (at 32^3, k = 2 about 1 GB of the 5.3 GB peak)."""
    s = groups[0].data.shape[-1]
    parts = []
    for g in groups:
        rows, cols = g.rows.astype(np.int64), g.cols.astype(np.int64)
        off = rows != cols
        parts += [rows * count + cols, cols[off] * count + rows[off]]
    keys = np.unique(np.concatenate(parts))
    del parts
    data = touched((len(keys), s, s))
    for g in groups:
        rows, cols = g.rows.astype(np.int64), g.cols.astype(np.int64)
        source = g.pick if g.pick is not None else np.arange(len(g))
        off = rows != cols
        blocks = np.ascontiguousarray(g.data)  # a copy only for a strided view
        for key, pick, transpose in ((rows * count + cols, source, 0), (cols[off] * count + rows[off], source[off], 1)):
            slots = np.searchsorted(keys, key)
            # rounds of distinct slots (an element's diagonal block comes from up to 3 faces of a group),
            # each added by one kernel call
            order = np.argsort(slots, kind="stable")
            sorted_slots = slots[order]
            first = np.concatenate([[True], sorted_slots[1:] != sorted_slots[:-1]]) if len(slots) else np.zeros(0, bool)
            run_start = np.maximum.accumulate(np.where(first, np.arange(len(slots)), 0))
            rank = np.empty(len(slots), dtype=np.int64)
            rank[order] = np.arange(len(slots)) - run_start
            for r in range(int(rank.max(initial=-1)) + 1):
                take = np.nonzero(rank == r)[0]
                kernels.add_blocks(data, slots[take], blocks, pick[take].astype(np.int64), transpose)
    indptr = np.zeros(count + 1, dtype=np.int64)
    np.add.at(indptr, keys // count + 1, 1)
    return sp.bsr_matrix((data, (keys % count).astype(np.int32), np.cumsum(indptr)), shape=(count * s, count * s))


def add_to_diagonal(A: sp.bsr_matrix, value: float) -> None:
    """A += value I in place (A from :func:`to_matrix`: every diagonal block stored)."""
    A.data[diagonal_blocks(A)] += value * np.eye(A.blocksize[0])
