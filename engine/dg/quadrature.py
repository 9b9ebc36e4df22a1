"""Volume quadrature on DG elements, exact for polynomials of degree <= 4 (callables: body forces,
errors against analytic fields).

Full cells use the tensor Gauss rule with 3 points per axis (exact to degree 5 per axis). A cut
element uses the 4^3 Gauss points of its cell with weights fitted to its own moments (moment
fitting: the minimum-norm weights that integrate every monomial of degree <= 4 exactly); the
points need not lie inside the piece, so integrands must be defined around the solid.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

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


@lru_cache(maxsize=None)
def _fitting() -> tuple[np.ndarray, np.ndarray]:
    """Points [64, 3] and the map W [64, m] from moments [m] (degree 4) to fitted weights."""
    pts, _ = _tensor_gauss(4)
    V = B.monomials(pts, DEGREE).T  # [m, 64]
    W = V.T @ np.linalg.inv(V @ V.T)
    return pts, W


def volume_rule(el: Elements) -> VolumeRule:
    """The rule on every element of ``el`` (units: h^3 scaled to m^3)."""
    h = el.grid.spacing
    m = len(monomial_exponents(3, DEGREE))
    full_pts, full_w = _tensor_gauss(3)
    fit_pts, W = _fitting()
    xi, wts, elem = [], [], []
    full = np.nonzero(el.full)[0]
    cut = np.nonzero(~el.full)[0]
    if len(full):
        xi.append(np.tile(full_pts, (len(full), 1)))
        wts.append(np.tile(full_w, len(full)))
        elem.append(np.repeat(full, len(full_w)))
    if len(cut):
        xi.append(np.tile(fit_pts, (len(cut), 1)))
        wts.append((el.moments[cut, :m] @ W.T).reshape(-1))
        elem.append(np.repeat(cut, len(fit_pts)))
    xi = np.concatenate(xi)
    element = np.concatenate(elem)
    return VolumeRule(points=el.centres[element] + h * xi, weights=np.concatenate(wts) * h**3, element=element, xi=xi)
