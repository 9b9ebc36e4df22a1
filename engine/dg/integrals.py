"""Exact integrals of basis products over elements, interfaces and surface patches.

Each integral is a coefficient sandwich around a Hankel matrix of moments (``basis``); moments
come from the slicing (divergence theorem, exact up to round-off). Physical units: an element
integral of psi_I psi_J is h^3 delta_IJ, derivatives carry 1/h, surface integrals h^2.
Full cells and interfaces between two full cells share their reference values: they are
computed once and broadcast.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..geometry.moments import area_terms, cell_moments, monomial_exponents, triangle_rule
from . import basis as B
from .elements import Elements


_CHUNK = 2**16  # quadrature points per block in ``Basis.tested`` (bounded scratch memory)


@dataclass
class Basis:
    """Orthonormal bases of all elements: T [E, n, n] (rows = monomial coefficients), L = T^-1."""

    degree: int
    T: np.ndarray
    L: np.ndarray
    h: float

    @property
    def size(self) -> int:
        return B.size(self.degree)

    def values(self, element: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """psi_I at points xi [N, 3] (each in its element's frame) -> [N, n]."""
        return np.einsum("ns,nis->ni", B.monomials(xi, self.degree), self.T[element])

    def gradients(self, element: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """d psi_I / d x_a [1/m] at points xi [N, 3] -> [N, 3, n]."""
        mono = B.monomials(xi, self.degree)
        D = B.derivative(self.degree)  # [3, s, t]
        return np.einsum("nt,ast,nis->nai", mono, D, self.T[element]) / self.h

    def tested(self, count: int, element: np.ndarray, xi: np.ndarray, values: np.ndarray,
               gradient: bool = False) -> np.ndarray:
        """Per-element sums over quadrature points of values times the basis: [count, P, n] with
        out[e, p, I] = sum_q values[q, p] psi_I(xi_q) (values [Q, P], weights included) or, with
        ``gradient``, sum_q values[q, p, a] d_a psi_I(xi_q) (values [Q, P, 3]). Sums monomials per
        element first and applies T once per element: gathering T per point (``values``) costs
        n^2 per point and dominates surface-load assembly on fine meshes."""
        values = np.asarray(values, dtype=float)
        P, s = values.shape[1], self.size
        acc = np.zeros((count, P * s))
        if gradient:
            D = B.derivative(self.degree) / self.h  # [3, s, t]
        for q0 in range(0, len(element), _CHUNK):
            q = slice(q0, q0 + _CHUNK)
            mono = B.monomials(xi[q], self.degree)  # [Q, s]
            if gradient:  # d_a m_s = sum_t D[a, s, t] m_t
                test = np.einsum("qpa,ast,qt->qps", values[q], D, mono)
            else:
                test = values[q][:, :, None] * mono[:, None, :]
            rows = element[q]
            acc += sp.csr_matrix((np.ones(len(rows)), (rows, np.arange(len(rows)))),
                                 shape=(count, len(rows))) @ test.reshape(len(rows), P * s)
        return np.einsum("eis,eps->epi", self.T, acc.reshape(count, P, s))


def make_basis(el: Elements, degree: int) -> Basis:
    """Orthonormalise every element's monomials (full cells: one reference factorisation)."""
    n = B.size(degree)
    T = np.empty((el.count, n, n))
    L = np.empty((el.count, n, n))
    ref_T, ref_L = B.orthonormalise(cell_moments(2 * degree)[None, :], degree)
    T[el.full], L[el.full] = ref_T[0], ref_L[0]
    cut = ~el.full
    if np.any(cut):
        T[cut], L[cut] = B.orthonormalise(el.moments[cut], degree)
    return Basis(degree, T, L, el.grid.spacing)


def gradient_products(T: np.ndarray, H: np.ndarray, h: float, degree: int) -> np.ndarray:
    """D[b, a, c, I, J] = int d_a psi_I d_c psi_J dV [m] for rows T [B, n, n] and Hankel H [B, n, n]."""
    # batched matmul here and in face_products, not einsum: 8-20x faster on these tiny products
    G = T[:, None] @ B.derivative(degree)[None]  # [B, 3, n, n] gradient coefficients
    GH = G @ H[:, None]
    return h * (GH[:, :, None] @ G[:, None].swapaxes(-1, -2))


def element_gradients(el: Elements, basis: Basis) -> tuple[np.ndarray, np.ndarray]:
    """(D_ref [1, 3, 3, n, n] shared by full cells, D_cut [C, 3, 3, n, n] for the others (order of ~full))."""
    k = basis.degree
    ref = np.nonzero(el.full)[0][:1]
    H_ref = B.hankel(cell_moments(2 * k), k)[None]
    T_ref = basis.T[ref] if len(ref) else B.orthonormalise(cell_moments(2 * k)[None, :], k)[0]
    cut = ~el.full
    return (gradient_products(T_ref, H_ref, basis.h, k),
            gradient_products(basis.T[cut], B.hankel(el.moments[cut], k), basis.h, k))


def face_products(el: Elements, basis: Basis, faces: np.ndarray, rest: float = 1.0
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interface integrals of the faces ``faces`` [F']:

    M[f, X, Y, I, J] = int_f psi^X_I psi^Y_J dA [m^2], N[f, X, Y, a, I, J] = int_f psi^X_I d_a psi^Y_J dA [m]
    with sides X, Y in (minus, plus). ``rest`` < 1 weighs M's part orthogonal to constants on the face
    down: M = Mbar + rest (M - Mbar), Mbar = (int_f psi^X_I dA) (int_f psi^Y_J dA) / area(f), the
    product of the face means. P[f, X, Y, I, J] = int_f Pi psi^X_I Pi psi^Y_J dA [m^2] with Pi the L2
    projection onto polynomials of degree k - 1 on the face (``low_products``; k = 1: P = Mbar).
    """
    k, h = basis.degree, basis.h
    sides = (el.minus[faces], el.plus[faces])
    H = B.hankel(el.face_moments[faces], k)  # [F, n, n] in the face frame
    A = []
    for e in sides:
        offset = (el.face_cell[faces] - el.cell[e]).astype(np.float64)  # face frame - element frame [cells]
        # offsets are whole cells, a handful of distinct ones: one shift matrix each
        unique, inverse = np.unique(offset, axis=0, return_inverse=True)
        A.append(basis.T[e] @ B.shift(k, unique)[inverse.reshape(-1)])
    n, F = basis.size, len(faces)
    # both sides stacked (rows X n + I): one batched matmul per product instead of one per side pair,
    # 0.28 against 0.35 s for the 32^3 shell's cut faces in 1024-face chunks
    A2 = np.concatenate(A, axis=1)  # [F, 2 n, n]
    AH = A2 @ H
    M = h**2 * (AH @ A2.swapaxes(-1, -2))  # [F, (X, I), (Y, J)]
    if rest != 1.0:
        means = h**2 * AH[:, :, 0]  # H[:, s, 0] are the face moments of monomial s (monomial 0 is 1)
        mean = means[:, :, None] * means[:, None, :] / (h**2 * H[:, 0, 0])[:, None, None]
        M = mean + rest * (M - mean)
    M = M.reshape(F, 2, n, 2, n).transpose(0, 1, 3, 2, 4)
    dY = (A2[:, None] @ B.derivative(k)[None]).reshape(F, 6 * n, n)  # rows (a, Y, J)
    N = (h * (AH @ dY.swapaxes(-1, -2))).reshape(F, 2, n, 3, 2, n).transpose(0, 1, 4, 3, 2, 5)
    return M, N, low_products(A, H, el.axis[faces], k, h)


def low_products(A: list[np.ndarray], H: np.ndarray, axis: np.ndarray, degree: int, h: float) -> np.ndarray:
    """P[f, X, Y, I, J] = int_f Pi psi^X_I Pi psi^Y_J dA [m^2], Pi the L2 projection onto P_{k-1}(f).

    A[X] [F, n, n]: the sides' basis rows in the face frame's monomials, H [F, n, n] the face's Hankel
    matrix, axis [F] its normal. The face is planar with eta_axis constant on it, so P_{k-1}(f) is
    spanned by the monomials of degree < k without eta_axis; with C^X = A[X] H[:, S] (moments against
    them) and G = H[S, S], P = h^2 C^X G^+ C^Y^T.
    """
    exps = monomial_exponents(3, degree)
    low = exps.sum(axis=1) < degree
    n = len(exps)
    P = np.empty((len(axis), 2, 2, n, n))
    for a in range(3):
        on = np.nonzero(axis == a)[0]
        if len(on) == 0:
            continue
        S = np.nonzero(low & (exps[:, a] == 0))[0]
        W = pseudo_root(H[on][:, S[:, None], S[None, :]])
        R = [A[X][on] @ H[on][:, :, S] @ W for X in range(2)]
        for X in range(2):
            for Y in range(2):
                P[on, X, Y] = h**2 * (R[X] @ R[Y].swapaxes(-1, -2))
    return P


def pseudo_root(G: np.ndarray, cutoff: float = 1e-12) -> np.ndarray:
    """W [..., r, r] with W W^T = G^+ for Gram matrices G [..., r, r] of the degree < k polynomials on a
    face or patch. Jacobi-scaled, eigenvalues below ``cutoff`` of the largest dropped: on a sliver face
    the linear monomial across it nearly repeats the constant, on a flat patch the traces of 1, x, y, z
    are dependent; the projection onto their span stays bounded either way."""
    scale = 1.0 / np.sqrt(np.maximum(np.einsum("...ii->...i", G), 1e-300))
    w, V = np.linalg.eigh(G * scale[..., :, None] * scale[..., None, :])
    root = np.where(w > cutoff * w[..., -1:], 1.0 / np.sqrt(np.where(w > 0, w, 1.0)), 0.0)
    return scale[..., :, None] * V * root[..., None, :]


@dataclass
class SurfacePoints:
    """Quadrature on surface triangles: points [Q, 3] [m], weights [Q] [m^2], unit outward
    normals [Q, 3], element [Q], triangle [Q] (index into the triangles given)."""

    points: np.ndarray
    weights: np.ndarray
    normals: np.ndarray
    element: np.ndarray
    triangle: np.ndarray


def surface_points(triangles: np.ndarray, element: np.ndarray, degree: int) -> SurfacePoints:
    """A rule exact to ``degree`` on every triangle [T, 3, 3] [m] (owned by ``element`` [T])."""
    ref, w = triangle_rule(degree)
    tri = np.asarray(triangles, dtype=np.float64)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    twice = np.linalg.norm(cross, axis=1)
    normal = cross / np.where(twice > 0, twice, 1.0)[:, None]
    bary = np.column_stack([1 - ref[:, 0] - ref[:, 1], ref])  # [q, 3]
    pts = np.einsum("qk,tkd->tqd", bary, tri).reshape(-1, 3)
    q = len(w)
    return SurfacePoints(points=pts, weights=(twice[:, None] * w[None, :]).reshape(-1),
                         normals=np.repeat(normal, q, axis=0), element=np.repeat(element, q),
                         triangle=np.repeat(np.arange(len(tri)), q))


@dataclass
class PatchProjection:
    """The L2 projection Pi onto the traces of P_{k-1}(K) on each surface patch (basis psi_s, s < m):
    R[b, p, I, u] with int Pi(psi_I n_p) Pi(psi_J n_q) dA = sum_u R[b, p, I, u] R[b, q, J, u] [m^2], and
    W[b, s, u] [1/m] with G^+ = W W^T, G[s, t] = int psi_s psi_t dA; for data d on the patch,
    int Pi(d) Pi(psi_I n_p) = sum_{s, u} (int d psi_s) W[b, s, u] R[b, p, I, u]."""

    R: np.ndarray
    W: np.ndarray


def patch_products(el: Elements, basis: Basis, triangles: np.ndarray, element: np.ndarray,
                   patches: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, PatchProjection]:
    """Exact integrals over surface patches (triangles [T, 3, 3] [m] of ``element`` [T], grouped by
    ``patches`` [T] in 0..count-1, one element per patch):

    Mnn[b, a, c, I, J] = int psi_I psi_J n_a n_c dA [m^2], Nn[b, a, c, I, J] = int psi_I d_a psi_J n_c dA [m],
    area [b] [m^2], and the projection onto degree < k (``PatchProjection``).
    """
    k, h = basis.degree, basis.h
    tri = np.asarray(triangles, dtype=np.float64)
    corners = (tri - el.centres[element][:, None, :]) / h
    moments = area_terms(corners, 2 * k)  # [T, m] in element frames, h^2 units
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
    m1 = np.zeros((count, 3) + moments.shape[1:])
    m2 = np.zeros((count, 3, 3) + moments.shape[1:])
    np.add.at(m1, patches, normal[:, :, None] * moments[:, None, :])
    np.add.at(m2, patches, normal[:, :, None, None] * normal[:, None, :, None] * moments[:, None, None, :])
    m0 = np.zeros((count,) + moments.shape[1:])
    np.add.at(m0, patches, moments)
    area = np.zeros(count)
    np.add.at(area, patches, 0.5 * np.linalg.norm(cross, axis=1))
    owner = np.zeros(count, dtype=np.int64)
    owner[patches] = element
    T = basis.T[owner]
    H1, H2 = B.hankel(m1, k), B.hankel(m2, k)  # [b, c, n, n], [b, a, c, n, n]
    # batched matmuls, not einsum: these chains were 0.35 s of the 32^3 shell's assembly as einsums
    Tt = T.swapaxes(-1, -2)
    Mnn = h**2 * (T[:, None, None] @ H2 @ Tt[:, None, None])
    G = T[:, None] @ B.derivative(k)[None]  # [b, a, n, n] gradient coefficients
    TH1 = T[:, None] @ H1  # [b, c, n, n]
    Nn = h * (TH1[:, None] @ G[:, :, None].swapaxes(-1, -2))
    low = B.size(k - 1)
    W = pseudo_root(T[:, :low] @ B.hankel(m0, k) @ Tt[:, :, :low])
    R = h * (TH1 @ (Tt[:, :, :low] @ W)[:, None])
    return Mnn, Nn, area, PatchProjection(R, W / h)


def projected_load(basis: Basis, low: PatchProjection, owner: np.ndarray, mask: np.ndarray, points_xi: np.ndarray,
                   patch: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """out[e, p, I] = sum over patches b of element e of m_p int Pi(d) Pi(psi_I n_p) dA for patch data d
    given at quadrature points (``values`` [Q], weights included; ``patch`` [Q], ``points_xi`` [Q, 3] in
    the element frame): the load side of the projected volumetric penalty. owner [b], mask [b, 3]."""
    k = basis.degree
    m = low.W.shape[1]
    acc = np.zeros((len(owner), basis.size))
    np.add.at(acc, patch, values[:, None] * B.monomials(points_xi, k))
    moments = np.einsum("bis,bs->bi", basis.T[owner][:, :m], acc)  # int d psi_s dA, s < m
    coef = np.einsum("bs,bsu->bu", moments, low.W)
    out = np.zeros((count, 3, basis.size))
    np.add.at(out, owner, mask[:, :, None] * np.einsum("bu,bpiu->bpi", coef, low.R))
    return out
