"""Volume quadrature on DG elements, exact for polynomials of degree <= 4 (callables: body forces,
errors against analytic fields).

Full cells use the tensor Gauss rule with 3 points per axis (exact to degree 5 per axis). A cut
element places 4^3 Gauss points in the box of its inertia ellipsoid (centroid and principal axes
from its first and second moments, half-widths sqrt(3) sigma: the box itself for a box-shaped
piece) and fits the weights to its own moments (moment fitting: the minimum-norm weights that
integrate every monomial of degree <= 4 exactly). Points in the whole cell would do for
polynomials, but the basis of a small piece grows fast outside it, and a smooth integrand (a body
force, an error against an analytic field) then loses accuracy there (P2 on a sphere: errors of
pieces of 10% of a cell 2000x the interior's). Points may still lie slightly outside
a non-convex piece, so integrands must be defined around the solid.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from ..geometry.moments import monomial_exponents
from . import basis as B
from .elements import Elements

DEGREE = 4


@dataclass
class VolumeRule:
    """points [Q, 3] [m], weights [Q] [m^3], element [Q], xi [Q, 3] (element frame)."""

    points: np.ndarray
    weights: np.ndarray
    element: np.ndarray
    xi: np.ndarray


def _tensor_gauss(count: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(count)
    x, w = 0.5 * x, 0.5 * w  # on [-1/2, 1/2]
    g = np.stack(np.meshgrid(x, x, x, indexing="ij"), axis=-1).reshape(-1, 3)
    wt = np.einsum("i,j,k->ijk", w, w, w).reshape(-1)
    return g, wt


def _fitted(moments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points [C, 64, 3] (element frame) and fitted weights [C, 64] (xi units) for moments [C, m]."""
    g, _ = _tensor_gauss(4)
    g = 2.0 * g  # on [-1, 1]^3
    m0 = moments[:, 0]
    centroid = moments[:, 1:4] / m0[:, None]
    second = moments[:, B.hankel_index(1)[1:, 1:]] / m0[:, None, None]  # E[xi_a xi_b]
    cov = second - centroid[:, :, None] * centroid[:, None, :]
    var, axes = np.linalg.eigh(cov)
    half = np.sqrt(3.0 * np.maximum(var, 0.0))
    half = np.maximum(half, 1e-3 * half.max(axis=1, keepdims=True))  # a flat piece keeps some thickness
    pts = centroid[:, None, :] + np.einsum("cab,cb,qb->cqa", axes, half, g)
    V = B.monomials(pts, DEGREE).transpose(0, 2, 1)  # [C, m, 64]
    w = np.einsum("cqm,cm->cq", np.linalg.pinv(V, rcond=1e-13), moments)
    return pts, w


def volume_rule(el: Elements) -> VolumeRule:
    """The rule on every element of ``el`` (units: h^3 scaled to m^3)."""
    h = el.grid.spacing
    m = len(monomial_exponents(3, DEGREE))
    full_pts, full_w = _tensor_gauss(3)
    xi, wts, elem = [], [], []
    full = np.nonzero(el.full)[0]
    cut = np.nonzero(~el.full)[0]
    if len(full):
        xi.append(np.tile(full_pts, (len(full), 1)))
        wts.append(np.tile(full_w, len(full)))
        elem.append(np.repeat(full, len(full_w)))
    if len(cut):
        pts, w = _fitted(el.moments[cut, :m])
        xi.append(pts.reshape(-1, 3))
        wts.append(w.reshape(-1))
        elem.append(np.repeat(cut, pts.shape[1]))
    xi = np.concatenate(xi)
    element = np.concatenate(elem)
    return VolumeRule(points=el.centres[element] + h * xi, weights=np.concatenate(wts) * h**3, element=element, xi=xi)
