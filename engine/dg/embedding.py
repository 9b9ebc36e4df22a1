"""Smooth surface embedding of the discontinuous DG field (Kaufmann et al. 2009 section 7).

1. Stitching (eq. 30): every element evaluates its polynomial at the corners of its cell; at a
   grid node the values of the elements that meet there *and are joined through interfaces
   among themselves* are averaged into one sample. Elements that only share a node through empty
   space (two ears of a bunny in one cell) keep separate samples, so they are never glued.
2. Moving least squares (eq. 31): a surface vertex takes the affine fit of the samples around
   its element (the element, its face neighbours and their samples), weighted by a Gaussian of
   width h. The fit reproduces affine displacements exactly (rigid motions included), so the
   deformed surface has no gaps and an affine field is carried over to round-off.
3. Beyond the paper, the fit is of the samples' departure from the vertex's own element: a vertex
   takes u_e(x) + MLS(samples - u_e(sample points)). A field of the element's degree is then
   carried exactly, not only an affine one: the paper's fit of samples on one side of a curved wall
   read u_r 7% low on a Lame shell's inner wall at h = 0.1 where the element itself is within 2%
   (docs/benchmarks.md, "The surface embedding's own error"). Jumps between elements are still
   smoothed: an element's offset from its neighbours is in the departures, which the fit spreads.

The weights are linear in the samples, which are linear in the coefficients (eq. 32): they are
computed once and a field costs two sparse products.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..blas import on_one_thread

WIDTH = 1.0  # Gaussian width [h]


class SurfaceEmbedding:
    """Maps DG coefficients u [E, 3, n] to the displacement [V, 3] of the surface vertices."""

    @on_one_thread
    def __init__(self, method) -> None:
        el, basis, grid = method.elements, method.basis, method.elements.grid
        h = grid.spacing
        E = el.count
        corner = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        nodes = (el.cell[:, None, :] + corner[None, :, :]).reshape(-1, 3)  # [E*8, 3] node indices
        owner = np.repeat(np.arange(E), 8)
        node_shape = tuple(np.asarray(grid.shape) + 1)
        key = np.ravel_multi_index(tuple(nodes.T), node_shape)
        # (node, element) pairs joined when the two elements share an interface touching that node
        pair_of = {(int(k), int(e)): i for i, (k, e) in enumerate(zip(key, owner))}
        a_list, b_list = [], []
        face_corner = {a: np.array([c for c in corner if c[a] == 0]) for a in range(3)}
        for f in range(len(el.minus)):
            ax = int(el.axis[f])
            base = el.face_cell[f] + np.eye(3, dtype=int)[ax]
            for c in face_corner[ax]:
                k = int(np.ravel_multi_index(tuple(base + c), node_shape))
                i, j = pair_of.get((k, int(el.minus[f]))), pair_of.get((k, int(el.plus[f])))
                if i is not None and j is not None:
                    a_list.append(i)
                    b_list.append(j)
        P = len(key)
        graph = sp.coo_matrix((np.ones(len(a_list)), (a_list, b_list)), shape=(P, P))
        _, comp = connected_components(graph, directed=False)
        S = comp.max() + 1
        count = np.bincount(comp, minlength=S)
        positions = np.asarray(grid.origin) + h * nodes
        # stitched sample s = mean over its pairs of u_e(node): a sparse [S, E*3*n] map
        psi = basis.values(owner, (positions - el.centres[owner]) / h)  # [P, n]
        n = basis.size
        rows = np.repeat(comp, n)
        self._sample_pos = np.zeros((S, 3))
        self._sample_pos[comp] = positions
        self._stitch = (comp, owner, psi / count[comp][:, None])
        self.samples = S

        vertices = method.surface.vertices
        vert_elem = _vertex_elements(method, vertices)
        self.vertex_element = vert_elem  # [V]: the element whose piece holds each vertex
        # candidate samples per owner element: its own corners and those of its face neighbours
        nbr = sp.coo_matrix((np.ones(2 * len(el.minus)), (np.concatenate([el.minus, el.plus]),
                                                          np.concatenate([el.plus, el.minus]))), shape=(E, E)).tocsr()
        nbr = (nbr + sp.identity(E, format="csr")).tocsr()
        elem_samples = sp.csr_matrix((np.ones(P), (owner, comp)), shape=(E, S))
        reach = (nbr @ elem_samples).tocsr()  # [E, S] nonzero where a sample is in reach
        reach.data[:] = 1.0
        rows_v, cols_v, vals_v = [], [], []
        # per vertex: psi_e(vertex) - sum_s W_s psi_e(sample s), the owner's part of (3)
        self._own = np.zeros((len(vertices), basis.size))
        sigma = WIDTH * h
        for e in np.unique(vert_elem):
            vs = np.nonzero(vert_elem == e)[0]
            cand = reach.indices[reach.indptr[e]:reach.indptr[e + 1]]
            d = self._sample_pos[cand][None, :, :] - vertices[vs][:, None, :]  # [v, s, 3]
            w = np.exp(-np.einsum("vsa,vsa->vs", d, d) / sigma**2)
            p = np.concatenate([np.ones(d.shape[:2] + (1,)), d / h], axis=2)  # [v, s, 4]
            A = np.einsum("vs,vsi,vsj->vij", w, p, p)
            # affine fit evaluated at the vertex (p = (1, 0, 0, 0)): weight_s = w_s (A^-1 p_s)_0
            coef = np.linalg.solve(A, np.broadcast_to(np.eye(4)[0], (len(vs), 4))[..., None])[..., 0]
            W = w * np.einsum("vi,vsi->vs", coef, p)
            owner_e = np.full(len(vs), e)
            at_samples = basis.values(np.full(len(cand), e), (self._sample_pos[cand] - el.centres[e]) / h)  # [s, n]
            self._own[vs] = basis.values(owner_e, (vertices[vs] - el.centres[e]) / h) - W @ at_samples
            rows_v.append(np.repeat(vs, len(cand)))
            cols_v.append(np.tile(cand, len(vs)))
            vals_v.append(W.reshape(-1))
        self._mls = sp.csr_matrix((np.concatenate(vals_v), (np.concatenate(rows_v), np.concatenate(cols_v))),
                                  shape=(len(vertices), S))
        del rows

    def samples_of(self, u: np.ndarray) -> np.ndarray:
        """Stitched node samples [S, 3] of coefficients u [E, 3, n]."""
        comp, owner, psi = self._stitch
        vals = np.einsum("qpi,qi->qp", u[owner], psi)
        out = np.zeros((self.samples, 3))
        np.add.at(out, comp, vals)
        return out

    def displacement(self, u: np.ndarray) -> np.ndarray:
        """Displacement [V, 3] [m] of the surface vertices."""
        own = np.einsum("vpi,vi->vp", u[self.vertex_element], self._own)
        return self._mls @ self.samples_of(u) + own


def _vertex_elements(method, vertices: np.ndarray) -> np.ndarray:
    """The element [V] whose piece's surface holds each vertex; a vertex outside the grid's pieces
    takes the element with the nearest centre."""
    out = method.owners(vertices)
    missing = np.nonzero(out < 0)[0]
    if len(missing):
        from scipy.spatial import cKDTree

        out[missing] = cKDTree(method.elements.centres).query(vertices[missing])[1]
    return out
