"""Edge bookkeeping of triangle surfaces: which faces share an edge, and which edges are unbalanced.

A surface bounds a solid (closed, in the sense the divergence theorem and the scan conversion
need) when every directed edge a->b is matched by as many b->a. Unbalanced edges form the rims of
its holes; loading reports them, the winding-number fallback caps them.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def edges(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges of triangles [k, 3]: (edge id per face corner [3k], faces per edge [e],
    directed ends per corner [3k, 2]); corner 3 f + j is the edge leaving vertex j of face f."""
    ends = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.minimum(ends[:, 0], ends[:, 1]) * n_vertices + np.maximum(ends[:, 0], ends[:, 1])
    _, edge, counts = np.unique(key, return_inverse=True, return_counts=True)
    return edge.reshape(-1), counts, ends


def edge_balance(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pairs [e, 2] as (low, high) vertex ids, faces per edge [e], net [e]): net is the number of
    traversals low->high minus high->low, zero for every edge of a closed surface."""
    edge, counts, ends = edges(faces, n_vertices)
    direction = np.where(ends[:, 0] < ends[:, 1], 1, -1)
    net = np.bincount(edge, weights=direction, minlength=len(counts)).astype(np.int64)
    first = np.zeros(len(counts), dtype=np.int64)
    first[edge[::-1]] = np.arange(len(edge))[::-1]
    pairs = np.sort(ends[first], axis=1)
    return pairs, counts, net


def rim_edges(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """The holes' rims: unbalanced edges oriented along their net direction [E, 2] and their net
    multiplicity [E] > 0 (the boundary chain of the surface)."""
    pairs, _, net = edge_balance(faces, n_vertices)
    keep = net != 0
    pairs, net = pairs[keep], net[keep]
    return np.where((net > 0)[:, None], pairs, pairs[:, ::-1]), np.abs(net)


def manifold_adjacency(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face pairs across edges used by exactly two faces: (face a [p], face b [p], same
    direction [p] bool: both traverse the edge the same way, so one must be reversed)."""
    edge, counts, ends = edges(faces, n_vertices)
    corner = np.argsort(edge, kind="stable")
    two = np.concatenate([[0], np.cumsum(counts)[:-1]])[counts == 2]
    c0, c1 = corner[two], corner[two + 1]
    return c0 // 3, c1 // 3, ends[c0, 0] == ends[c1, 0]


def shells(faces: np.ndarray, n_vertices: int) -> tuple[int, np.ndarray, tuple]:
    """(number of shells, shell label per face [k], the adjacency): faces connected across edges that
    exactly two faces share (a non-manifold edge where two bodies meet joins nothing)."""
    fa, fb, same = manifold_adjacency(faces, n_vertices)
    graph = coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(len(faces), len(faces)))
    n, label = connected_components(graph, directed=False)
    return n, label, (fa, fb, same)
