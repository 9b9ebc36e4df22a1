"""Subdivision of surface facets (3D triangles [n, 3, 3], 2D segments [n, 2, 2]) into smaller pieces
that keep their orientation: for the surface quadrature (every edge below a length) and for
clipping to a region (pieces straddling its edge split until small).

Well-shaped triangles are quartered by their edge midpoints; slivers, which CAD booleans and STL
exports make in fans across flat faces, are cut along their length only, since quartering a sliver
of length L made (L / longest)^2 pieces of it (docs/benchmarks.md, "Slivers in the surface
quadrature").
"""

from __future__ import annotations

import numpy as np


def _quartered(facets: np.ndarray) -> np.ndarray:
    """Halve segments [n, 2, 2] / quarter triangles [n, 3, 3] by edge midpoints, keeping orientation."""
    if facets.shape[-1] == 2:
        a, b = facets[:, 0], facets[:, 1]
        m = 0.5 * (a + b)
        return np.stack([np.stack([a, m], 1), np.stack([m, b], 1)], axis=1).reshape(-1, 2, 2)
    a, b, c = facets[:, 0], facets[:, 1], facets[:, 2]
    ab, bc, ca = 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)
    return np.stack(
        [np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], axis=1
    ).reshape(-1, 3, 3)


ROUND = 0.5  # shape quality (``well_shaped``) above which a triangle is quartered; a right isosceles one: 0.87


def well_shaped(facets: np.ndarray) -> np.ndarray:
    """bool [n]: the triangles [n, 3, 3] whose quality 4 sqrt(3) area / sum of squared edges (1 when
    equilateral) is above ROUND; the rest are slivers."""
    edges = np.roll(facets, -1, axis=1) - facets
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    return 4 * np.sqrt(3) * area > ROUND * (edges**2).sum(axis=(1, 2))


def split_facets(facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One refinement step of facets [n, d, d]: (children [m, d, d], each child's facet [m]). Segments
    and well-shaped triangles are cut by their edge midpoints (2 and 4 children); a sliver is halved
    at the midpoint of its longest edge, so that clipping a sliver at a region's edge keeps a few
    pieces straddling it at each step (quartering a plate face's fan slivers by a ball region made
    2.5 M pieces of 1,040 facets)."""
    n, d = facets.shape[0], facets.shape[-1]
    if d == 2:
        return _quartered(facets), np.repeat(np.arange(n), 2)
    good = well_shaped(facets)
    thin = np.nonzero(~good)[0]
    longest = np.linalg.norm(np.roll(facets[thin], -1, axis=1) - facets[thin], axis=2).argmax(axis=1)
    p, q, r = rolled(facets[thin], longest)
    halves = _halves(p, q, r, 0.5 * (p + q))
    quartered = np.nonzero(good)[0]
    return (np.concatenate([_quartered(facets[quartered]), halves]),
            np.concatenate([np.repeat(quartered, 4), np.repeat(thin, 2)]))


def _halves(p: np.ndarray, q: np.ndarray, r: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Triangles (p, q, r) [K, 3] each cut from ``at`` [K, 3] on its edge pq to r: [2 K, 3, 3], orientation kept."""
    return np.stack([np.stack([p, at, r], axis=1), np.stack([at, q, r], axis=1)], axis=1).reshape(-1, 3, 3)


def rolled(facets: np.ndarray, first: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The vertices [K, 3] of triangles [K, 3, 3] from vertex ``first`` [K] on, in their own cyclic
    order (the orientation kept): with ``first`` an edge's index (edge k runs from vertex k to k + 1),
    that edge runs from the first vertex to the second."""
    rows = np.arange(len(facets))
    return tuple(facets[rows, (first + k) % 3] for k in range(3))


def subdivided(facets: np.ndarray, longest: float) -> np.ndarray:
    """Facets [M, d, d] cut into pieces [K, d, d] whose edges are at most ``longest`` [m], as many as
    linear in a sliver's length. A well-shaped triangle (``well_shaped``) is quartered by its edge
    midpoints; a needle (its shortest edge at most ``longest``) is cut into a strip of slices
    parallel to that edge (``_strips``); any other sliver (a flat cap) is split at the foot of the
    altitude on its longest edge, into two needles.
    Quartering every triangle made a sliver of length L into (L / longest)^2 pieces: the 256 fan
    slivers of a holed plate's face (L ~ 0.7 m, longest 12.5 mm) 948 k pieces, 6.6 M quadrature
    points and 36 s of a 40 x 40 x 8 cell job's setup."""
    facets = np.asarray(facets, dtype=float).reshape(-1, facets.shape[-1], facets.shape[-1])
    done = []
    while len(facets):
        edges = np.linalg.norm(np.roll(facets, -1, axis=1) - facets, axis=2)  # edge k: vertex k to k + 1
        long = edges.max(axis=1) > longest
        done.append(facets[~long])
        facets, edges = facets[long], edges[long]
        if facets.shape[-1] == 2:
            facets = _quartered(facets)
            continue
        quarter = well_shaped(facets)
        needle = ~quarter & (edges.min(axis=1) <= longest)
        cap = ~quarter & ~needle
        # vertices rolled cyclically (the orientation kept): the needle's apex first, opposite its
        # shortest edge; the cap's longest edge from its first vertex to its second
        apex, b, c = rolled(facets[needle], edges[needle].argmin(axis=1) + 2)
        p, q, r = rolled(facets[cap], edges[cap].argmax(axis=1))
        t = np.einsum("ij,ij->i", r - p, q - p) / np.einsum("ij,ij->i", q - p, q - p)
        facets = np.concatenate([_quartered(facets[quarter]), _strips(apex, b, c, longest),
                                 _halves(p, q, r, p + t[:, None] * (q - p))])
    return np.concatenate(done) if done else facets


def _strips(apex: np.ndarray, b: np.ndarray, c: np.ndarray, longest: float) -> np.ndarray:
    """Triangles (apex, b, c) [K, 3] each whose edge bc is at most ``longest``, cut by n lines parallel to
    bc into 2 n - 1 triangles [sum(2 n - 1), 3, 3] (orientation kept) whose edges along ab and ac
    are at most longest - |bc|, so that their diagonals are at most ``longest`` (where |bc| is above
    longest / 2 the slices are longest / 2 long, and the diagonals up to 1.5 longest are cut again)."""
    side = np.maximum(np.linalg.norm(b - apex, axis=1), np.linalg.norm(c - apex, axis=1))
    step = np.maximum(longest - np.linalg.norm(c - b, axis=1), 0.5 * longest)
    n = np.maximum(np.ceil(side / step), 1).astype(np.int64)
    count = 2 * n - 1
    owner = np.repeat(np.arange(len(n)), count)
    j = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    i = (j + 1) // 2  # slice i holds (P_i, P_i+1, Q_i+1) at odd j (and j = 0) and (P_i, Q_i+1, Q_i) at even j > 0
    t0, t1 = (i / n[owner])[:, None], ((i + 1) / n[owner])[:, None]
    a0, ab, ac = apex[owner], b[owner] - apex[owner], c[owner] - apex[owner]
    p0, p1, q0, q1 = a0 + t0 * ab, a0 + t1 * ab, a0 + t0 * ac, a0 + t1 * ac
    outer = ((j % 2) == 1) | (j == 0)
    return np.stack([p0, np.where(outer[:, None], p1, q1), np.where(outer[:, None], q1, q0)], axis=1)


def lattice_pieces(facets: np.ndarray, origin: np.ndarray, step: float, parents: bool = False):
    """Facets [M, d, d] cut at every plane ``origin``_k + j ``step`` [m] of each axis k into pieces
    [K, d, d] that each lie in one box of that lattice, orientation kept (a piece through a vertex on
    a plane can have zero measure: the quadrature drops it). A weight that is polynomial in each box
    (a multilinear hat, or the staggered loads' hats times nearest-sample boxes, whose kinks and jumps
    lie on planes h/2 apart) is then integrated exactly by a rule exact for that degree. With
    ``parents`` also the facet each piece came from: (pieces, index [K] into facets)."""
    facets = np.asarray(facets, dtype=float)
    d = facets.shape[-1]
    origin = np.asarray(origin, dtype=float)
    f = (facets.reshape(-1, d, d) - origin) / step  # lattice units
    ids = np.arange(len(f))
    for axis in range(d):
        f, ids = _cut_along(f, ids, axis)
    return (f * step + origin, ids) if parents else f * step + origin


def _cut_along(f: np.ndarray, ids: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Pieces [M, d, d] (lattice units) cut at the integer planes along ``axis``, with the labels
    ``ids`` [M] each piece passes on to its parts: each pass cuts every piece that crosses one at the
    lowest plane it crosses, and keeps the part below it."""
    done, done_ids = [], []
    while len(f):
        c = f[:, :, axis]
        plane = np.floor(c.min(axis=1)) + 1.0
        cross = plane < c.max(axis=1)
        done.append(f[~cross])
        done_ids.append(ids[~cross])
        f, ids, plane = f[cross], ids[cross], plane[cross]
        if len(f):
            parts = _split(f, plane, axis)
            ids = np.tile(ids, len(parts) // len(f))  # _split returns its parts in blocks of the input's order
            f = parts
    return (np.concatenate(done), np.concatenate(done_ids)) if done else (f, ids)


def _split(f: np.ndarray, plane: np.ndarray, axis: int) -> np.ndarray:
    """Pieces [M, d, d] that cross ``plane`` [M] along ``axis``, split there (orientation kept):
    a segment into two, a triangle into the one on its lone vertex's side and two on the other."""
    s = f[:, :, axis] - plane[:, None]
    if f.shape[-1] == 2:
        p, q = f[:, 0], f[:, 1]
        a = p + (s[:, 0] / (s[:, 0] - s[:, 1]))[:, None] * (q - p)
        a[:, axis] = plane
        return np.concatenate([np.stack([p, a], axis=1), np.stack([a, q], axis=1)])
    above = s > 0
    lone = np.where(above.sum(axis=1) == 1, above.argmax(axis=1), (~above).argmax(axis=1))
    l, v1, v2 = rolled(f, lone)
    sl, s1, s2 = (np.take_along_axis(s, ((lone + k) % 3)[:, None], axis=1)[:, 0] for k in range(3))
    a = l + (sl / (sl - s1))[:, None] * (v1 - l)
    b = l + (sl / (sl - s2))[:, None] * (v2 - l)
    a[:, axis] = plane
    b[:, axis] = plane
    return np.concatenate([np.stack([l, a, b], axis=1), np.stack([a, v1, v2], axis=1), np.stack([a, v2, b], axis=1)])
