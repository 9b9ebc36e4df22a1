"""Generalized winding number of an oriented surface: the inside test that tolerates holes.

For a closed, outward-oriented surface the winding number w(p) is 1 inside and 0 outside (an
integer count of how often the surface wraps around p). For an open surface, the same sum of
signed solid angles (3D) or signed angles (2D) varies smoothly across the holes, and w >= 1/2
is the natural inside test (Jacobson, Kavan & Sorkine-Hornung, "Robust inside-outside
segmentation using generalized winding numbers", SIGGRAPH 2013).

``winding_number`` sums each face's exact signed solid angle / angle:

    3D triangle (a, b, c) = corners - p:
        tan(Omega/2) = det[a b c] / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|)
        (Van Oosterom & Strackee 1983),  w = sum Omega / (4 pi)
    2D segment (a, b) = ends - p:
        theta = atan2(a x b, a . b),  w = sum theta / (2 pi)

The work is O(points x faces), vectorised over blocks of point-face pairs with a fixed
2 MiB of scratch memory. A point exactly on a face's interior (det = 0 with the face's corners
around it) gets that face's contribution 0 instead of +-2 pi (+-pi in 2D): the mean of the
two one-sided limits, so w = 1/2 there and ``inside`` counts surface points as inside.

``winding_number_fast`` (3D) is the hierarchical approximation of Barill, Dickson, Schmidt,
Levin & Jacobson ("Fast winding numbers for soups and clouds", SIGGRAPH 2018): a balanced
median-split tree over the triangles; a node whose ball (area-weighted centroid c, radius r)
is far from p, |c - p| > beta r, contributes the Taylor expansion of its solid angle about c
instead of its triangles' exact ones. To first order that is the dipole term

    Omega ~ R.N / |R|^3,   R = c - p,   N = sum_T N_T,   N_T = (b - a) x (c - a) / 2,

the small-triangle limit of the formula above (tan(Omega/2) ~ det / (4 |R|^3), det ~ 2 R.N_T);
the next two orders are added (see _far_coefficients). Leaves that are not far are summed
exactly with the kernel above. ``inside`` uses it for large point x face counts and
recomputes exactly the points whose fast w is not near an integer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Pairs per block. The arithmetic runs in place in 16 reused [points, faces] buffers, 2 MiB at
# this size: cache-sized blocks measured 28 M triangle-point pairs/s against 10 M/s for
# 100 MB blocks (one core, numpy 1.26).
_BLOCK_PAIRS = 2**14
_ON_SURFACE_TOL = 1e-12
# Fast path of ``inside``: taken above this many point x face pairs (3D only); below it the
# exact sum costs at most ~0.2 s and the tree would not pay for itself.
_FAST_MIN_PAIRS = 5_000_000
# Far-field acceptance |c - p| > beta r. The expansion's error per node falls like beta^-3
# (measured max |w error|: ~5e-3 at 2, ~1.5e-3 at 3, ~1.5e-4 at 4); 2 is the paper's choice
# and the fastest, and ``inside`` tolerates errors up to 0.4.
_BETA = 2.0
# Most triangles per leaf: leaves are summed exactly, so this trades exact pair work against
# tree levels (each level is a few numpy passes over the live (point, node) pairs).
_LEAF_FACES = 32
# A fast w farther than this from every integer is recomputed exactly by ``inside``. A fast w
# within it of an integer m decides like the exact w unless the two lie on either side of 1/2,
# i.e. unless the approximation error exceeds 1/2 - 0.1 = 0.4 (measured errors: < 1e-2, see
# winding_number_fast). Off a closed surface the exact w is an integer, so only points on the
# surface (w = 1/2) or near holes of an open one pay for the exact sum.
_AMBIGUOUS = 0.1
# Points per traversal chunk: bounds the live (point, node) pair arrays. Measured on an
# 81920-face icosphere: at most ~40 live pairs per point on a level (~110 far nodes and ~9
# leaves per point in all), so ~30 MB with the gathered far-field coefficients.
_POINT_CHUNK = 4096


def winding_number(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Generalized winding number of the surface at each point.

    vertices: [m, d] float, d = 2 or 3 [m]; faces: [k, d] int (triangles in 3D, segments with
    the solid on their left in 2D); points: [n, d] float [m]. Returns [n] float64: 1 inside
    and 0 outside a closed outward-oriented surface up to round-off, 1/2 on
    face interiors, fractional near holes of an open surface.
    """
    vertices, faces, points = _checked(vertices, faces, points)
    d = vertices.shape[1]
    n, k = len(points), len(faces)
    total = np.zeros(n, dtype=np.float64)
    if n == 0 or k == 0:
        return total
    # Corner coordinates as separate contiguous [k] arrays: component-wise arithmetic avoids
    # strided [..., d] temporaries.
    corners = [np.ascontiguousarray(vertices[faces[:, j], i]) for j in range(d) for i in range(d)]
    face_step = min(k, _BLOCK_PAIRS)
    point_step = max(1, _BLOCK_PAIRS // face_step)
    flat = np.empty((16, point_step * face_step))
    angle_sum = _solid_angle_sum if d == 3 else _angle_sum
    for p0 in range(0, n, point_step):
        p = points[p0 : p0 + point_step]
        for f0 in range(0, k, face_step):
            block = [c[f0 : f0 + face_step] for c in corners]
            shape = (len(p), len(block[0]))
            buf = [b[: shape[0] * shape[1]].reshape(shape) for b in flat]
            total[p0 : p0 + point_step] += angle_sum(block, p, buf)
    return total / (4.0 * np.pi if d == 3 else 2.0 * np.pi)


def winding_number_fast(
    vertices: np.ndarray,
    faces: np.ndarray,
    points: np.ndarray,
    beta: float = _BETA,
    leaf_faces: int = _LEAF_FACES,
) -> np.ndarray:
    """Hierarchical (Barill et al. 2018) approximation of ``winding_number`` in 3D.

    Shapes and units as in ``winding_number``; beta > 1 is the far-field acceptance ratio
    (distance to a node's centroid over its radius), leaf_faces >= 2 the most triangles per
    leaf. 2D input is passed to the exact ``winding_number``.

    Error behaviour: triangles in leaves near p (in particular every triangle p lies on or
    near) are summed exactly, so the contribution of the surface around p, and its jump across
    the surface, are exact. Each far node (|c - p| > beta r) is replaced by its Taylor
    expansion to second order about c, whose error is O((r / |c - p|)^3) times the node's
    unsigned solid angle; on a closed surface these errors partly cancel. Measured max
    |fast - exact| (tests/test_winding.py: points in the bounding box, on faces, on vertices
    and 1e-9 off the surface): beta = 2: 2.1e-3 on an icosphere (5120 faces), 5.4e-3 on a
    torus (2304 faces, worst at its centre, where it sees the inner ring's curved nodes from
    all sides), 2.7e-3 on 1200 points in the ball inside an 81920-face icosphere; beta = 3:
    4.6e-4 and 1.4e-3; beta = 4: 1.1e-4 and 1.3e-4. There is no hard bound: the error scales
    with the unsigned area of far nodes, so a dense soup of coherently oriented sheets folded
    into a small ball can raise it.
    Cost: O(k log k) to build the tree, then roughly O(log k) far nodes plus a few leaves'
    triangles per point instead of O(k) triangles.
    """
    vertices, faces, points = _checked(vertices, faces, points)
    if vertices.shape[1] != 3:
        return winding_number(vertices, faces, points)
    if not beta > 1.0:
        raise ValueError(f"beta must exceed 1 (the point must be outside a far node's ball), got {beta}")
    if leaf_faces < 2:
        raise ValueError(f"leaf_faces must be at least 2, got {leaf_faces}")
    total = np.zeros(len(points), dtype=np.float64)
    if len(points) == 0 or len(faces) == 0:
        return total
    tree = _build_tree(vertices, faces, leaf_faces)
    for p0 in range(0, len(points), _POINT_CHUNK):
        chunk = points[p0 : p0 + _POINT_CHUNK]
        total[p0 : p0 + _POINT_CHUNK] = _tree_solid_angle(tree, chunk, beta)
    return total / (4.0 * np.pi)


def inside(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Inside test by the generalized winding number: bool [n], True where w >= 1/2.

    Shapes as in ``winding_number``. Points on the surface count as inside: w is 1/2 there up
    to round-off, hence the threshold 1/2 - 1e-12. Above 5e6 point x face pairs in 3D, w comes
    from ``winding_number_fast`` and every point whose fast w is more than 0.1 from an integer
    (near the surface, on it, or near a hole of an open surface) is recomputed exactly; the
    decision then differs from the exact one only if the fast error exceeds 0.4.
    """
    vertices, faces, points = _checked(vertices, faces, points)
    if vertices.shape[1] != 3 or len(points) * len(faces) <= _FAST_MIN_PAIRS:
        return winding_number(vertices, faces, points) >= 0.5 - _ON_SURFACE_TOL
    w = winding_number_fast(vertices, faces, points)
    ambiguous = np.abs(w - np.round(w)) > _AMBIGUOUS
    if ambiguous.any():
        w[ambiguous] = winding_number(vertices, faces, points[ambiguous])
    return w >= 0.5 - _ON_SURFACE_TOL


def _checked(
    vertices: np.ndarray, faces: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inputs as float64 [m, d], int64 [k, d] and float64 [n, d] arrays; ValueError on bad shapes."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    points = np.asarray(points, dtype=np.float64)
    d = vertices.shape[1] if vertices.ndim == 2 else -1
    if d not in (2, 3):
        raise ValueError(f"vertices must have shape [m, 2] or [m, 3], got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != d:
        raise ValueError(f"faces must have shape [k, {d}] for {d}D vertices, got {faces.shape}")
    if points.ndim != 2 or points.shape[1] != d:
        raise ValueError(f"points must have shape [n, {d}], got {points.shape}")
    return vertices, faces, points


@dataclass(frozen=True)
class _FaceTree:
    """Complete binary tree over triangles in heap order: node i has children 2i+1, 2i+2, and
    level l holds nodes 2^l - 1 .. 2^(l+1) - 2; all leaves are on level ``depth``.

    centroid [nodes, 3] m: area-weighted centroid c of the node's triangles; radius [nodes] m:
    their corners' largest distance from c (exact at the leaves, an upper bound above);
    far [nodes, 23]: the far-field coefficients (see _far_coefficients); leaf_corners: 9 arrays
    [leaves, L] (x0, y0, z0, x1, ...) of the leaves' triangles, short leaves padded with a
    degenerate triangle (solid angle 0).
    """

    depth: int
    centroid: np.ndarray
    radius: np.ndarray
    far: np.ndarray
    leaf_corners: list[np.ndarray]


@dataclass
class _Moments:
    """Moments of some nodes' triangles T (area vector N_T [m^2], centroid x_T) about the nodes'
    centroids c, d = x - c over T's points x: area [b] m^2 (unsigned); centroid [b, 3] m;
    radius [b] m; first [b, 3] m^2: sum N_T (dipole); second [b, 3, 3] m^3:
    S_ij = sum_T N_T,i (x_T - c)_j; third [b, 3, 3, 3] m^4: T_ijk = sum_T N_T,i mean_T(d_j d_k).
    """

    area: np.ndarray
    centroid: np.ndarray
    radius: np.ndarray
    first: np.ndarray
    second: np.ndarray
    third: np.ndarray


def _level_bounds(k: int, level: int) -> np.ndarray:
    """Face-range boundaries [2^level + 1] of the nodes on a level (in tree order).

    floor(j k / 2^level): a node's two children split its range at its middle, which makes
    the split after sorting along an axis a median split.
    """
    return (np.arange(2**level + 1, dtype=np.int64) * k) >> level


def _build_tree(vertices: np.ndarray, faces: np.ndarray, leaf_faces: int) -> _FaceTree:
    """Median-split tree over the triangles with each node's far-field moments (see _FaceTree)."""
    k = len(faces)
    depth = 0
    while k > leaf_faces << depth:  # k / 2^depth <= leaf_faces, every leaf non-empty
        depth += 1
    tri = vertices[faces]  # [k, 3 corners, 3]
    tri = tri[_median_split_order(tri.mean(axis=1), depth)]
    leaf_tri = _padded_leaves(tri, _level_bounds(k, depth))
    # Moments at the leaves from the triangles, then level by level up the tree from the
    # children's: O(k) work in all instead of O(k) per level.
    levels = [_leaf_moments(leaf_tri)]
    for _ in range(depth):
        levels.append(_parent_moments(levels[-1]))
    levels.reverse()  # root level first, the heap order
    centroid = np.concatenate([m.centroid for m in levels])
    radius = np.concatenate([m.radius for m in levels])
    far = np.concatenate([_far_coefficients(m) for m in levels])
    # Corner coordinates as separate contiguous arrays, as in winding_number.
    leaf_corners = [np.ascontiguousarray(leaf_tri[:, :, j, i]) for j in range(3) for i in range(3)]
    return _FaceTree(depth, centroid, radius, far, leaf_corners)


def _median_split_order(centre: np.ndarray, depth: int) -> np.ndarray:
    """Permutation [k] of the triangles (centroids centre [k, 3]) into tree order: on each level,
    each node's range is sorted along the longest axis of its centroids' bounding box."""
    k = len(centre)
    order = np.arange(k)
    c = np.ascontiguousarray(centre.T)  # [3, k] in the current order: contiguous per axis
    for level in range(depth):
        bounds = _level_bounds(k, level)
        node = np.repeat(np.arange(2**level), np.diff(bounds))
        low = np.minimum.reduceat(c, bounds[:-1], axis=1)
        extent = np.maximum.reduceat(c, bounds[:-1], axis=1) - low  # [3, nodes]
        axis = np.argmax(extent, axis=0)
        nodes = np.arange(len(axis))
        width = extent[axis, nodes]
        scale = 1.0 / np.where(width > 0.0, 2.0 * width, 1.0)
        # One float sort key: the node number plus the position along its axis scaled into
        # [0, 1/2], which keeps each node's range in place (7x faster than np.lexsort). Ties
        # from rounding only reorder nearly equal centroids: still a median split.
        along = (c[axis[node], np.arange(k)] - low[axis, nodes][node]) * scale[node]
        perm = np.argsort(node + along)
        order, c = order[perm], c[:, perm]
    return order


def _padded_leaves(tri: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """The triangles tri[bounds[i]:bounds[i+1]] ([k, 3, 3] m) of each leaf as [leaves, L, 3, 3],
    L the most per leaf. A shorter leaf is padded with the triangle (q, q, q), q its own first
    corner: zero area, no effect on the leaf's radius, and solid angle exactly 0 from any
    point (det = 0, den = 4 |q - p|^3 >= 0, and atan2(0, 0) = 0 at p = q)."""
    slot = bounds[:-1, None] + np.arange(np.diff(bounds).max())  # [leaves, L]
    valid = slot < bounds[1:, None]
    padded = tri[np.where(valid, slot, bounds[:-1, None])]
    padded[~valid] = padded[~valid][:, :1, :]
    return padded


def _leaf_moments(tri: np.ndarray) -> _Moments:
    """Moments of the leaves with triangles tri [leaves, L, 3, 3] m (padded, see _padded_leaves)."""
    area_vec = 0.5 * np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])  # [b, L, 3]
    area = np.sqrt(np.einsum("nti,nti->nt", area_vec, area_vec))
    centre = tri.mean(axis=2)  # [b, L, 3]
    area_sum = area.sum(axis=1)
    # A node of degenerate triangles has no area to weight by; any centre works for it, as the
    # radius is measured from the same point (padding centres are the leaf's own corners).
    flat = area_sum == 0.0
    centroid = np.where(
        flat[:, None],
        centre.mean(axis=1),
        np.einsum("nt,nti->ni", area, centre) / np.where(flat, 1.0, area_sum)[:, None],
    )
    corner_offset = tri - centroid[:, None, None, :]
    radius = np.sqrt(np.einsum("ntki,ntki->ntk", corner_offset, corner_offset).max(axis=(1, 2)))
    offset = centre - centroid[:, None, :]  # [b, L, 3]
    spread = tri - centre[:, :, None, :]  # corners about the triangle's centroid [b, L, 3, 3]
    # mean_T(d d^T) = D D^T + (sum_k e_k e_k^T) / 12: the second moment of a uniform triangle
    # about its centroid is a twelfth of its corners' (e_k = corner k - x_T).
    second = np.einsum("nti,ntj->ntij", offset, offset)
    second += np.einsum("ntki,ntkj->ntij", spread, spread) / 12.0
    b = len(tri)
    return _Moments(
        area_sum,
        centroid,
        radius,
        area_vec.sum(axis=1),
        np.einsum("nti,ntj->nij", area_vec, offset),
        np.matmul(area_vec.transpose(0, 2, 1), second.reshape(b, -1, 9)).reshape(b, 3, 3, 3),
    )


def _parent_moments(child: _Moments) -> _Moments:
    """Moments of the nodes one level up from a level's (child nodes 2j, 2j+1 of parent j),
    shifted to the parent centroid: with delta = c_child - c_parent, d = d_child + delta, so
    S' = S + N (x) delta and T'_ijk = T_ijk + S_ij delta_k + delta_j S_ik + N_i delta_j delta_k.
    The radius is the bound max(|delta| + r_child): a larger radius only makes the far-field
    test stricter.
    """
    area = child.area[0::2] + child.area[1::2]
    weighted = child.area[:, None] * child.centroid
    centroid = np.where(
        (area == 0.0)[:, None],
        0.5 * (child.centroid[0::2] + child.centroid[1::2]),
        (weighted[0::2] + weighted[1::2]) / np.where(area == 0.0, 1.0, area)[:, None],
    )
    delta = child.centroid - np.repeat(centroid, 2, axis=0)  # [2b, 3]
    radius = child.radius + np.sqrt(np.einsum("ij,ij->i", delta, delta))
    first, second = child.first, child.second
    second_shifted = second + np.einsum("ni,nj->nij", first, delta)
    third_shifted = (
        child.third
        + np.einsum("nij,nk->nijk", second, delta)
        + np.einsum("nik,nj->nijk", second, delta)
        + np.einsum("ni,nj,nk->nijk", first, delta, delta)
    )
    return _Moments(
        area,
        centroid,
        np.maximum(radius[0::2], radius[1::2]),
        first[0::2] + first[1::2],
        second_shifted[0::2] + second_shifted[1::2],
        third_shifted[0::2] + third_shifted[1::2],
    )


# Index pairs i <= j and triples i <= j <= k: the distinct monomials r_i r_j and r_i r_j r_k.
_PAIRS = np.array([(i, j) for i in range(3) for j in range(i, 3)])
_TRIPLES = np.array([(i, j, k) for i in range(3) for j in range(i, 3) for k in range(j, 3)])
# r_i r_j r_k = (r_i r_j) r_k: the position of each triple's (i, j) in _PAIRS.
_TRIPLE_PAIR = np.array([np.flatnonzero((_PAIRS == t[:2]).all(axis=1))[0] for t in _TRIPLES])


def _symmetric_sum_matrix(index: np.ndarray) -> np.ndarray:
    """[3^q, len(index)] 0/1 matrix summing a flattened q-index tensor over all orderings of each
    sorted index tuple, so that t . (r x ... x r) = (flat t @ matrix) . monomials."""
    q = index.shape[1]
    matrix = np.zeros((3**q, len(index)))
    for flat, idx in enumerate(np.ndindex(*(3,) * q)):
        matrix[flat, np.flatnonzero((index == np.sort(idx)).all(axis=1))[0]] = 1.0
    return matrix


_SUM_PAIRS = _symmetric_sum_matrix(_PAIRS)
_SUM_TRIPLES = _symmetric_sum_matrix(_TRIPLES)


def _far_coefficients(m: _Moments) -> np.ndarray:
    """Far-field coefficients [b, 23] of nodes with moments m.

    Taylor-expanding r / |r|^3 (the integrand n . (x - p) / |x - p|^3 of the solid angle)
    about R = c - p to second order and integrating over the triangles gives

        Omega ~ [R.N + tr S - 3 R.S.R / |R|^2
                 + (-3 R.u + 15 T(R, R, R) / |R|^2) / (2 |R|^2)] / |R|^3

    with u_k = 2 T_iik + T_kjj. The terms of order 1 and 2 are both O(r^2 / |R|^2) relative to
    the dipole on a curved surface (the normal turns along the node), so neither is kept
    without the other. Columns: [tr S, N (3), -3/2 u (3), -3 S summed over index orders
    (6, _PAIRS), 15/2 T likewise (10, _TRIPLES)], the coefficients of _far_field's monomials.
    """
    b = len(m.area)
    trace = np.einsum("nii->n", m.second)
    u = 2.0 * np.einsum("niik->nk", m.third) + np.einsum("nkjj->nk", m.third)
    # The constant factors are folded in here, once per node rather than once per pair.
    return np.concatenate(
        [
            trace[:, None],
            m.first,
            -1.5 * u,
            -3.0 * (m.second.reshape(b, 9) @ _SUM_PAIRS),
            7.5 * (m.third.reshape(b, 27) @ _SUM_TRIPLES),
        ],
        axis=1,
    )


def _tree_solid_angle(tree: _FaceTree, points: np.ndarray, beta: float) -> np.ndarray:
    """Total signed solid angle [sr] of the tree's triangles at each point (points [n, 3]).

    Walks the tree level by level over all live (point, node) pairs at once: far pairs add
    their expansion, near pairs descend to both children, and near leaves are summed exactly.
    """
    n = len(points)
    point = np.arange(n)
    node = np.zeros(n, dtype=np.int64)
    parts = [np.zeros(n)]
    for level in range(tree.depth + 1):
        r = tree.centroid[node] - points[point]  # [pairs, 3]
        r2 = np.einsum("ij,ij->i", r, r)
        far = r2 > (beta * tree.radius[node]) ** 2
        parts.append(np.bincount(point[far], _far_field(tree, node[far], r[far], r2[far]), minlength=n))
        point, node = point[~far], node[~far]
        if level < tree.depth:
            point = np.repeat(point, 2)
            node = (2 * node[:, None] + np.array([1, 2])).ravel()
    leaf = node - (2**tree.depth - 1)
    parts.append(np.bincount(point, _leaf_solid_angles(tree, points, point, leaf), minlength=n))
    return np.sum(parts, axis=0)


def _far_field(tree: _FaceTree, node: np.ndarray, r: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Far-field solid angle [sr] [pairs] of nodes [pairs] seen at offsets r = centroid - point
    [pairs, 3] m, r2 = |r|^2: the coefficients (see _far_coefficients) dotted with the
    monomials [1, r, r / |r|^2, r_i r_j / |r|^2, r_i r_j r_k / |r|^4], over |r|^3."""
    inv2 = 1.0 / r2
    scaled = r * inv2[:, None]
    rr = scaled[:, _PAIRS[:, 0]] * r[:, _PAIRS[:, 1]]
    rrr = rr[:, _TRIPLE_PAIR] * scaled[:, _TRIPLES[:, 2]]
    coef = tree.far[node]  # [pairs, 23]
    # Row-wise dots per block measured 2x faster than one [pairs, 23] monomial matrix.
    total = coef[:, 0].copy()
    for lo, x in ((1, r), (4, scaled), (7, rr), (13, rrr)):
        total += np.einsum("ij,ij->i", coef[:, lo : lo + x.shape[1]], x)
    return total * inv2 * np.sqrt(inv2)


def _leaf_solid_angles(
    tree: _FaceTree, points: np.ndarray, point: np.ndarray, leaf: np.ndarray
) -> np.ndarray:
    """Exact solid angle [sr] [pairs] of leaf[i]'s triangles seen from points[point[i]]
    (points [n, 3] m; point, leaf [pairs] int)."""
    width = tree.leaf_corners[0].shape[1]
    step = max(1, _BLOCK_PAIRS // width)
    flat = np.empty((16, step * width))
    out = np.empty(len(point))
    for s in range(0, len(point), step):
        at = slice(s, s + step)
        block = [c[leaf[at]] for c in tree.leaf_corners]  # 9 x [b, width]
        shape = (len(block[0]), width)
        buf = [b[: shape[0] * shape[1]].reshape(shape) for b in flat]
        out[at] = _solid_angle_sum(block, points[point[at]], buf)
    return out


def _solid_angle_sum(corners: list[np.ndarray], p: np.ndarray, buf: list[np.ndarray]) -> np.ndarray:
    """Sum of the signed solid angles [sr] of a block of triangles seen from each point [b].

    corners: 9 arrays [f] (x0, y0, z0, x1, ...), or [b, f] for a different block of faces per
    point; p: [b, 3]; buf: 16 scratch arrays [b, f].
    """
    a, b, c = buf[0:3], buf[3:6], buf[6:9]
    la, lb, lc, det, den, t, u = buf[9:16]
    for j, e in enumerate((a, b, c)):
        for i in range(3):
            np.subtract(corners[3 * j + i], p[:, i : i + 1], out=e[i])
    for e, le in ((a, la), (b, lb), (c, lc)):
        _dot(e, e, le, t)
        np.sqrt(le, out=le)
    # det[a b c] = a . (b x c)
    det.fill(0.0)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        np.multiply(b[i1], c[i2], out=t)
        np.multiply(b[i2], c[i1], out=u)
        np.subtract(t, u, out=t)
        np.multiply(a[i], t, out=t)
        np.add(det, t, out=det)
    np.multiply(la, lb, out=den)
    np.multiply(den, lc, out=den)
    for e0, e1, l2 in ((a, b, lc), (b, c, la), (c, a, lb)):
        _dot(e0, e1, t, u)
        np.multiply(t, l2, out=t)
        np.add(den, t, out=den)
    omega = np.arctan2(det, den, out=t)
    # det == 0 and den < 0: p lies inside the triangle (in its plane); atan2 returns +-pi
    # by the sign of the zero. Zero is the mean of the one-sided limits (see module doc).
    _zero_on_face(omega, det, den)
    return 2.0 * omega.sum(axis=1)


def _angle_sum(corners: list[np.ndarray], p: np.ndarray, buf: list[np.ndarray]) -> np.ndarray:
    """Sum of the signed angles [rad] a block of segments subtends at each point [b].

    corners: 4 arrays [f] (x0, y0, x1, y1); p: [b, 2]; buf: >= 7 scratch arrays [b, f].
    """
    a, b = buf[0:2], buf[2:4]
    cross, dot, t = buf[4:7]
    for j, e in enumerate((a, b)):
        for i in range(2):
            np.subtract(corners[2 * j + i], p[:, i : i + 1], out=e[i])
    np.multiply(a[0], b[1], out=cross)
    np.multiply(a[1], b[0], out=t)
    np.subtract(cross, t, out=cross)
    _dot(a, b, dot, t)
    theta = np.arctan2(cross, dot, out=t)
    # p on the segment's interior: atan2 returns +-pi by the sign of the zero; the mean of
    # the one-sided limits is 0 (see module doc).
    _zero_on_face(theta, cross, dot)
    return theta.sum(axis=1)


def _dot(e0: list[np.ndarray], e1: list[np.ndarray], out: np.ndarray, tmp: np.ndarray) -> None:
    """out = sum_i e0[i] * e1[i] (component arrays of equal shape), using tmp as scratch."""
    np.multiply(e0[0], e1[0], out=out)
    for x, y in zip(e0[1:], e1[1:]):
        np.multiply(x, y, out=tmp)
        np.add(out, tmp, out=out)


def _zero_on_face(angle: np.ndarray, num: np.ndarray, den: np.ndarray) -> None:
    """Set angle = 0 in place where num == 0 and den < 0 (the point lies on the face)."""
    on_plane = num == 0.0
    if on_plane.any():
        angle[on_plane & (den < 0.0)] = 0.0
