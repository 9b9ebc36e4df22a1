"""Per-element polynomial bases: monomial tables, orthonormalisation, evaluation.

Every element K has its own frame xi = (x - c_K) / h (c_K: the centre of the grid cell the
element lives in, h: the grid spacing). Its basis is the total-degree <= k monomials in xi,
orthonormalised with K's own moments: with the Hankel matrix H[s, t] = int_K xi^(a_s + a_t) dV_xi
and its Cholesky factor H = L L^T, the rows of T = L^-1 are the monomial coefficients of the
basis (psi_I = sum_s T[I, s] xi^a_s), so int_K psi_I psi_J dV = h^3 delta_IJ. A piece that is
small or thin keeps a unit-conditioned basis (its mass matrix is the identity), which is what
keeps cut elements from wrecking the system.

All integrals the method needs are bilinear in such coefficient rows around a Hankel matrix of
moments (element moments for volume terms, face or triangle moments for surface terms), and
the derivative and shift of a polynomial are linear maps of its coefficients:
``coefficients(d p / d xi_a) = c @ derivative(k)[a]``, ``coefficients(p(eta + d)) in eta = c @ shift(k, d)``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ..blas import on_one_thread
from ..errors import VoxelasticError
from ..geometry.moments import monomial_exponents


def size(degree: int) -> int:
    """Monomials of total degree <= degree in 3D: 4 for k = 1, 10 for k = 2."""
    return math.comb(degree + 3, 3)


@lru_cache(maxsize=None)
def _index(degree: int) -> dict[tuple[int, ...], int]:
    return {tuple(int(v) for v in e): i for i, e in enumerate(monomial_exponents(3, degree))}


@lru_cache(maxsize=None)
def hankel_index(degree: int) -> np.ndarray:
    """[n, n] index into ``monomial_exponents(3, 2 degree)`` of a_s + a_t (n = size(degree))."""
    exps = monomial_exponents(3, degree)
    table = _index(2 * degree)
    out = np.array([[table[tuple(int(v) for v in a + b)] for b in exps] for a in exps], dtype=np.int64)
    out.setflags(write=False)
    return out


def hankel(moments: np.ndarray, degree: int) -> np.ndarray:
    """Hankel matrices [..., n, n] from moments [..., m] over degree-2k monomials (m >= C(2k+3, 3))."""
    return np.asarray(moments)[..., hankel_index(degree)]


@lru_cache(maxsize=None)
def derivative(degree: int) -> np.ndarray:
    """[3, n, n]: ``c @ D[a]`` are the coefficients of d/dxi_a of the polynomial with coefficients c."""
    exps = monomial_exponents(3, degree)
    table = _index(degree)
    out = np.zeros((3, len(exps), len(exps)))
    for s, e in enumerate(exps):
        for a in range(3):
            if e[a] > 0:
                lower = tuple(int(v) - (1 if b == a else 0) for b, v in enumerate(e))
                out[a, s, table[lower]] = e[a]
    out.setflags(write=False)
    return out


def shift(degree: int, offsets: np.ndarray) -> np.ndarray:
    """[..., n, n]: ``c @ S`` re-expresses p(xi) in eta = xi - d (offsets d [..., 3], xi units).

    xi^a = (eta + d)^a = sum_{b <= a} C(a, b) d^(a - b) eta^b.
    """
    exps = monomial_exponents(3, degree)
    d = np.asarray(offsets, dtype=np.float64)
    le = np.all(exps[None, :, :] <= exps[:, None, :], axis=2)  # [s, t]: b_t <= a_s
    binom = np.array([[math.prod(math.comb(int(x), int(y)) for x, y in zip(a, b)) if le[i, j] else 0
                       for j, b in enumerate(exps)] for i, a in enumerate(exps)], dtype=np.float64)
    power = np.where(le[..., None], exps[:, None, :] - exps[None, :, :], 0)  # [s, t, 3]
    return binom * np.prod(d[..., None, None, :] ** power, axis=-1)


def monomials(xi: np.ndarray, degree: int) -> np.ndarray:
    """Monomials [..., n] of the points xi [..., 3] (element frame)."""
    exps = monomial_exponents(3, degree)
    xi = np.asarray(xi, dtype=np.float64)
    out = np.ones(xi.shape[:-1] + (len(exps),))
    for a in range(3):
        powers = xi[..., a, None] ** np.arange(degree + 1)
        out *= powers[..., exps[:, a]]
    return out


class BasisError(VoxelasticError):
    """An element's moments do not define a basis (degenerate or non-positive moments)."""


@on_one_thread
def orthonormalise(moments: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """(T [P, n, n], L [P, n, n]) with H = L L^T the Hankel matrices of moments [P, m].

    Rows of T are the basis coefficients (T = L^-1); rows of L express the monomials in the basis
    (xi^a_s = sum_I L[s, I] psi_I), e.g. the identity map x = c + h xi for stiffness warping and
    the rigid modes. Monomials are first scaled to unit norm (Jacobi scaling) so the factorisation
    sees the shape of the piece, not its size.
    """
    H = hankel(moments, degree)
    scale = 1.0 / np.sqrt(np.maximum(np.einsum("pii->pi", H), 1e-300))
    Hs = H * scale[:, :, None] * scale[:, None, :]
    try:
        Ls = np.linalg.cholesky(Hs)
    except np.linalg.LinAlgError:
        bad = [p for p in range(len(Hs)) if np.min(np.linalg.eigvalsh(Hs[p])) <= 0]
        raise BasisError(f"dg basis: the moments of {len(bad)} element(s) are not positive definite "
                         f"(first: element {bad[0] if bad else '?'}); the piece is degenerate") from None
    L = Ls / scale[:, :, None]
    eye = np.broadcast_to(np.eye(H.shape[-1]), H.shape)
    T = np.linalg.solve(L, eye)
    return T, L
