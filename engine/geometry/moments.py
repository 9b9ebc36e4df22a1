"""Exact polynomial moments of polyhedra and planar polygons given by triangles.

Moments are taken in scaled centred coordinates ``xi = (x - center) / scale``: for a solid V,
``M_alpha = int_V xi^alpha dV_xi`` with ``dV_xi = dV / scale^3``, for a planar set F,
``A_alpha = int_F xi^alpha dA_xi`` with ``dA_xi = dA / scale^2``. The monomials are those of
``monomial_exponents(3, degree)``.

Volume moments use the homogeneous form of the divergence theorem: ``div(xi xi^alpha) =
(3 + |alpha|) xi^alpha``, so ``M_alpha = 1/(3+|alpha|) sum_T (xi . n_T) int_T xi^alpha dA``, and
``xi . n_T`` is constant on a planar triangle. This is the cone decomposition of V from the
origin (each triangle with the origin spans a signed tetrahedron): no integration axis has to be
chosen per monomial, and the triangle integrals only need degree ``|alpha|`` instead of
``|alpha| + 1`` (Mirtich 1996 and Kaufmann et al. 2009, App. A, integrate along one axis and
need one degree more). The triangle integrals use rules exact for the degree (Radon's 7-point
rule up to degree 5, collapsed Gauss-Jacobi above), so the results are exact up to round-off.
Round-off grows with the distance of ``center`` from the solid (the cones cancel), so centre the
coordinates on the solid, as the DG pieces do with their cell centres.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ..errors import GeometryError

_CHUNK = 1 << 12  # triangles per vectorised block: keeps the temporaries near 10 MB


@lru_cache(maxsize=None)
def _exponents(dim: int, degree: int) -> np.ndarray:
    rows: list[tuple[int, ...]] = []

    def fill(prefix: tuple[int, ...], left: int, slots: int) -> None:
        # Decreasing lexicographic within a degree: x^2 before xy before xz before y^2 ...
        if slots == 1:
            rows.append(prefix + (left,))
            return
        for a in range(left, -1, -1):
            fill(prefix + (a,), left - a, slots - 1)

    for total in range(degree + 1):
        fill((), total, dim)
    out = np.array(rows, dtype=np.int64).reshape(-1, dim)
    out.setflags(write=False)
    return out


def monomial_exponents(dim: int, degree: int) -> np.ndarray:
    """Exponents [n, dim] of all monomials of total degree <= ``degree``.

    Order: graded (total degree 0, 1, ..., degree), within a degree decreasing lexicographic, i.e.
    for dim 3: 1, x, y, z, x^2, xy, xz, y^2, yz, z^2, x^3, ... (n = C(degree + dim, dim); 35 for
    dim 3, degree 4). The returned array is read-only and shared.
    """
    if dim not in (1, 2, 3):
        raise GeometryError(f"monomial_exponents: dim must be 1, 2 or 3, got {dim}")
    if not isinstance(degree, (int, np.integer)) or degree < 0:
        raise GeometryError(f"monomial_exponents: degree must be an integer >= 0, got {degree!r}")
    return _exponents(int(dim), int(degree))


@lru_cache(maxsize=None)
def triangle_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature on the reference triangle {u, v >= 0, u + v <= 1}, exact for total degree <= degree.

    Returns (points [Q, 2] as (u, v), weights [Q] summing to 1/2). Degree <= 1: the centroid;
    2: Strang-Fix interior three-point rule; 3..5: Radon's 7-point rule (closed form);
    higher: a collapsed Gauss rule (Gauss-Legendre in r times Gauss-Jacobi(1, 0) in s,
    u = (1 + r)(1 - s)/4, v = (1 + s)/2; the Jacobi weight absorbs the Duffy Jacobian).
    """
    if degree <= 1:
        bary, w = np.array([[1 / 3, 1 / 3, 1 / 3]]), np.array([1.0])
    elif degree == 2:
        bary = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
        w = np.full(3, 1 / 3)
    elif degree <= 5:
        r15 = math.sqrt(15.0)
        rows, weights = [[1 / 3, 1 / 3, 1 / 3]], [9 / 40]
        for a, wa in (((6 - r15) / 21, (155 - r15) / 1200), ((6 + r15) / 21, (155 + r15) / 1200)):
            b = 1 - 2 * a
            rows += [[b, a, a], [a, b, a], [a, a, b]]
            weights += [wa] * 3
        bary, w = np.array(rows), np.array(weights)
    else:
        from scipy.special import roots_jacobi, roots_legendre  # only here: workers start faster

        n = math.ceil((degree + 1) / 2)
        r, wr = roots_legendre(n)
        s, ws = roots_jacobi(n, 1.0, 0.0)
        rr, ss = np.meshgrid(r, s, indexing="ij")
        u, v = (0.25 * (1.0 + rr) * (1.0 - ss)).ravel(), (0.5 * (1.0 + ss)).ravel()
        bary, w = np.column_stack([1 - u - v, u, v]), np.outer(wr, ws).ravel() / 4.0
    points = np.ascontiguousarray(bary[:, 1:])
    weights = 0.5 * w  # w are fractions of the area (sum 1); the reference triangle's area is 1/2
    points.setflags(write=False)
    weights.setflags(write=False)
    return points, weights


def triangle_integrals(corners: np.ndarray, degree: int) -> np.ndarray:
    """Reference-triangle integrals ``I[t, i] = int_ref xi^alpha_i(p(u, v)) du dv`` [T, n].

    corners: [T, 3, 3] triangle vertices already in xi coordinates. ``int_T xi^alpha dA_xi`` is
    ``|N_T| I[t]`` with N_T the (unnormalised) cross product of the edges. Vectorised in blocks:
    per triangle, the weighted x powers [degree+1, Q] times the yz products [Q, m] in one batched
    matmul, from which the n monomials are picked.
    """
    corners = np.asarray(corners, dtype=np.float64)
    exps = monomial_exponents(3, degree)
    points, weights = triangle_rule(degree)
    bary = np.column_stack([1.0 - points[:, 0] - points[:, 1], points])  # [Q, 3]
    yz_pairs = [(b, c) for b in range(degree + 1) for c in range(degree + 1 - b)]
    pick_a = exps[:, 0]
    pick_yz = np.array([yz_pairs.index((int(b), int(c))) for _, b, c in exps])
    out = np.empty((corners.shape[0], exps.shape[0]))
    for start in range(0, corners.shape[0], _CHUNK):
        c = corners[start : start + _CHUNK]
        p = np.matmul(c.transpose(2, 0, 1), bary.T)  # [3, t, Q] quadrature points
        pw = np.empty((3, degree + 1) + p.shape[1:])
        pw[:, 0] = 1.0
        for k in range(1, degree + 1):
            np.multiply(pw[:, k - 1], p, out=pw[:, k])
        xw = pw[0] * weights  # [degree+1, t, Q]
        yz = np.empty((len(yz_pairs),) + p.shape[1:])  # [m, t, Q]
        for i, (b, cc) in enumerate(yz_pairs):
            np.multiply(pw[1, b], pw[2, cc], out=yz[i])
        prod = np.matmul(xw.transpose(1, 0, 2), yz.transpose(1, 2, 0))  # [t, degree+1, m]
        out[start : start + _CHUNK] = prod[:, pick_a, pick_yz]
    return out


def _scaled_corners(vertices: np.ndarray, triangles: np.ndarray, center, scale: float) -> np.ndarray:
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise GeometryError(f"moments: vertices must have shape [m, 3], got {vertices.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise GeometryError(f"moments: triangles must have shape [k, 3], got {triangles.shape}")
    if not (np.isfinite(scale) and scale > 0):
        raise GeometryError(f"moments: scale must be a positive finite length, got {scale}")
    if triangles.size and (triangles.min() < 0 or triangles.max() >= vertices.shape[0]):
        raise GeometryError("moments: triangle vertex index out of range")
    return (vertices[triangles] - np.asarray(center, dtype=np.float64)) / scale


def volume_terms(corners: np.ndarray, degree: int) -> np.ndarray:
    """Per-triangle contributions [T, n] to the volume moments; their sum over a closed
    outward-oriented surface is ``int_V xi^alpha dV_xi`` (corners [T, 3, 3] in xi coordinates).

    Exposed so callers can sum many solids at once (``np.add.reduceat`` over a piece id).
    """
    exps = monomial_exponents(3, degree)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    cone = np.einsum("td,td->t", corners[:, 0], normal)  # 2 |T| (xi . n) = 6 x signed tet volume
    return triangle_integrals(corners, degree) * cone[:, None] / (3.0 + exps.sum(axis=1))[None, :]


def area_terms(corners: np.ndarray, degree: int) -> np.ndarray:
    """Per-triangle area moments [T, n]: ``int_T xi^alpha dA_xi`` (corners [T, 3, 3] in xi)."""
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return triangle_integrals(corners, degree) * np.linalg.norm(normal, axis=1)[:, None]


def volume_moments(vertices: np.ndarray, triangles: np.ndarray, degree: int, center, scale: float) -> np.ndarray:
    """``int_V xi^alpha dV_xi`` [n] for the solid bounded by a closed, outward-oriented triangle mesh.

    vertices [m, 3] [m], triangles [k, 3] vertex indices, center [3] [m], scale [m];
    xi = (x - center)/scale. Several shells are fine (inner shells of hollow solids face inward).
    The surface must be closed: an open one gives a result that depends on ``center``.
    """
    corners = _scaled_corners(vertices, triangles, center, scale)
    return volume_terms(corners, degree).sum(axis=0)


def area_moments(vertices: np.ndarray, triangles: np.ndarray, degree: int, center, scale: float) -> np.ndarray:
    """``int_F xi^alpha dA_xi`` [n] over the union F of the (non-overlapping) triangles.

    Same arguments as ``volume_moments``; orientation is irrelevant. 3D monomials, so for a face on
    the plane x_a = const the ``xi_a`` powers are that constant's powers.
    """
    corners = _scaled_corners(vertices, triangles, center, scale)
    return area_terms(corners, degree).sum(axis=0)


def interval_moments(lower: np.ndarray, upper: np.ndarray, degree: int) -> np.ndarray:
    """``int_lower^upper t^k dt`` for k = 0..degree, broadcast over ``lower``/``upper`` -> [..., degree+1]."""
    k = np.arange(degree + 1)
    lo = np.asarray(lower, dtype=np.float64)[..., None]
    hi = np.asarray(upper, dtype=np.float64)[..., None]
    return (hi ** (k + 1) - lo ** (k + 1)) / (k + 1)


def box_moments(lower, upper, degree: int) -> np.ndarray:
    """Closed form ``int_box xi^alpha dV_xi`` [n] for the axis-aligned box [lower, upper] (xi units)."""
    exps = monomial_exponents(3, degree)
    one_d = interval_moments(np.asarray(lower, float), np.asarray(upper, float), degree)  # [3, degree+1]
    return one_d[0, exps[:, 0]] * one_d[1, exps[:, 1]] * one_d[2, exps[:, 2]]


@lru_cache(maxsize=None)
def _cell_moments(degree: int) -> np.ndarray:
    out = box_moments([-0.5] * 3, [0.5] * 3, degree)
    out.setflags(write=False)
    return out


def cell_moments(degree: int) -> np.ndarray:
    """Moments [n] of the full cell ``xi in [-1/2, 1/2]^3``: prod_d m(alpha_d) with m(k) = 0 for odd
    k and (1/2)^k / (k + 1) for even k. Shared reference of every full cell (read-only)."""
    return _cell_moments(int(degree))


@lru_cache(maxsize=None)
def _cell_face_moments(degree: int) -> np.ndarray:
    exps = monomial_exponents(3, degree)
    half = interval_moments(-0.5, 0.5, degree)  # [degree+1]
    rows = []
    for a in range(3):
        b, c = [d for d in range(3) if d != a]
        rows.append(0.5 ** exps[:, a] * half[exps[:, b]] * half[exps[:, c]])
    out = np.array(rows)
    out.setflags(write=False)
    return out


def cell_face_moments(degree: int) -> np.ndarray:
    """Area moments [3, n] of the full high face ``xi_a = +1/2`` of the cell, for a = 0, 1, 2
    (about the cell's centre; the low face follows by ``(-1)^alpha_a``). Read-only."""
    return _cell_face_moments(int(degree))


@lru_cache(maxsize=None)
def _shift_terms(degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (i, j) with exponents beta_j <= alpha_i: i [K], j [K], C(alpha, beta) [K], alpha - beta [K, 3]."""
    exps = monomial_exponents(3, degree)
    le = np.all(exps[None, :, :] <= exps[:, None, :], axis=2)  # [n_alpha, n_beta]
    i, j = np.nonzero(le)
    diff = exps[i] - exps[j]
    binom = np.array([math.prod(math.comb(int(a), int(b)) for a, b in zip(exps[ii], exps[jj]))
                      for ii, jj in zip(i, j)], dtype=np.float64)
    return i, j, binom, diff


def shift_moments(moments: np.ndarray, degree: int, shift) -> np.ndarray:
    """Moments [..., n] re-centred from xi to xi' = xi - shift; shift [3] or [..., 3] (scaled units).

    (xi - d)^alpha = sum_{beta <= alpha} C(alpha, beta) (-d)^(alpha - beta) xi^beta, and every beta
    is in the same monomial set, so the conversion is exact (up to round-off).
    """
    moments = np.asarray(moments, dtype=np.float64)
    d = np.broadcast_to(np.asarray(shift, dtype=np.float64), moments.shape[:-1] + (3,))
    i, j, binom, diff = _shift_terms(int(degree))
    n = monomial_exponents(3, degree).shape[0]
    # Batches usually hold few distinct shifts (e.g. unit vectors): one matrix per distinct shift.
    flat_d, flat_m = d.reshape(-1, 3), moments.reshape(-1, n)
    unique, inverse = np.unique(flat_d, axis=0, return_inverse=True)
    out = np.empty_like(flat_m)
    for k, dk in enumerate(unique):
        matrix = np.zeros((n, n))
        np.add.at(matrix, (i, j), binom * np.prod((-dk) ** diff, axis=1))
        rows = np.flatnonzero(inverse.ravel() == k)
        out[rows] = flat_m[rows] @ matrix.T
    return out.reshape(moments.shape)


def rescale_moments(moments: np.ndarray, degree: int, factor: float, *, area: bool = False) -> np.ndarray:
    """Moments [..., n] for a new scale ``scale' = scale / factor`` (xi' = factor * xi).

    Volume moments pick up ``factor^(|alpha| + 3)``, area moments ``factor^(|alpha| + 2)``.
    """
    exps = monomial_exponents(3, degree)
    power = exps.sum(axis=1) + (2 if area else 3)
    return np.asarray(moments) * float(factor) ** power
