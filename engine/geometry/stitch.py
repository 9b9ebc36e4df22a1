"""Closing cracks: boundary vertices far closer together than the edges around them are one vertex
that an export wrote twice, rounded differently (an ASCII STL with four decimals, a float32 soup).

Only vertices on open edges (edges used by one face) are candidates, so a closed mesh and the
distinct shells of an assembly are never touched. Two of them are welded when their distance is
below ``CRACK`` times the shortest edge at either: a gap that small is no feature any grid or
element resolves, and a real slit is as wide as its own edges are long. Welded groups (chains
included) take the position of their lowest-numbered vertex, the others are dropped; faces that
collapse are dropped by the loader's next step.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .topology import edges

CRACK = 0.1
NEIGHBOURS = 8  # searched per open-edge vertex: a crack leaves a vertex one copy per face around it


def stitch_cracks(vertices: np.ndarray, faces: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) with each crack's vertices (of vertices [n, 3] [m], faces [k, 3]) made one,
    the others dropped (the order of those kept is the input's); a warning with the count and the
    widest gap closed when any was."""
    n = len(vertices)
    edge, counts, ends = edges(faces, n)
    rim = np.unique(ends[counts[edge] == 1])
    if len(rim) < 2:
        return vertices, faces
    length = np.linalg.norm(vertices[ends[:, 0]] - vertices[ends[:, 1]], axis=1)
    shortest = np.full(n, np.inf)
    np.minimum.at(shortest, ends[:, 0], length)
    np.minimum.at(shortest, ends[:, 1], length)  # an open edge is listed in one direction only
    reach = CRACK * shortest[rim]
    # each vertex's nearest few (a ball search would pair a crowd of near-coincident vertices
    # quadratically: 200k of them took 100 s, 4 s this way); a larger crowd is linked through
    # chains of nearest neighbours
    points = vertices[rim]
    _, index = cKDTree(points).query(points, k=NEIGHBOURS + 1, distance_upper_bound=float(reach.max()))
    pairs = np.stack([np.broadcast_to(np.arange(len(rim))[:, None], index.shape), index], axis=2).reshape(-1, 2)
    pairs = pairs[(index.reshape(-1) < len(rim)) & (pairs[:, 0] < pairs[:, 1])]  # found, each pair once
    if not len(pairs):
        return vertices, faces
    gap = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    close = gap < np.minimum(reach[pairs[:, 0]], reach[pairs[:, 1]])
    if not close.any():
        return vertices, faces
    pairs, gap = pairs[close], gap[close]
    m = len(rim)
    groups = connected_components(coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m)),
                                  directed=False)[1]
    first = np.full(groups.max() + 1, n)
    np.minimum.at(first, groups, rim)  # rim is sorted: the lowest vertex number of each group
    target = np.arange(n)
    target[rim] = first[groups]
    keep = target == np.arange(n)
    number = np.cumsum(keep) - 1
    warnings.append(
        f"closed cracks: welded {n - int(keep.sum())} open-edge vertices onto a neighbour within {gap.max():.3g} m "
        f"(under {CRACK:g} of the shortest edge at each); vertex numbering differs from the input"
    )
    return vertices[keep], number[target[faces]]
