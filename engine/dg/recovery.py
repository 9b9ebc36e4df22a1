"""Strain where it is asked for: per element, a degree-k least-squares fit of the DG strain over
the element and its face neighbours (a patch recovery).

The strain of a degree-k DG solution is a degree k - 1 polynomial per element, discontinuous
across interfaces: taken as it is at a probe it is one order below the displacement, and at the
surface (where the element's polynomial is only weakly tied to the traction) it is noisier still.
Each element K here gets the polynomial p_K of degree k (one degree more than the data) that
minimises sum_J w_KJ int_J |p_K - eps_J|^2 dV (w_KK = OWN_WEIGHT, 1 for the neighbours) over the
patch J in {K, face neighbours of K}: the patch spans about 3 h along every axis, enough to pin a
degree-k polynomial, and a least-squares fit reproduces every strain field of degree <= k exactly,
so the recovered strain is one order above the element's own (the thick sphere's probe von Mises at
h = 1/8: 2.48e-2 -> 8.93e-3 with the element's own strain weighted OWN_WEIGHT; docs/benchmarks.md).
Larger patches (two rings of neighbours, the 27 cells around) were worse there: a quadratic does
not follow the r^-3 stress over 5 h.

Everything is exact polynomial algebra (no quadrature): the strain's monomial coefficients come
from the basis coefficients (``basis.T``), the patch integrals are Hankel matrices of the elements'
moments (``basis.hankel``) moved into K's frame by the shift of monomials (``basis.shift``: the
patch's elements sit whole cells away from K). An element whose patch does not determine a
degree-k fit (a lone element, a thin sliver with one neighbour) keeps its own strain, which is the
fit over itself alone.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..blas import on_one_thread
from . import basis as B
from .elements import Elements
from .integrals import Basis

# w_KK, the element's own strain against a neighbour's (w_KJ = 1). Equal weights flatten a stress
# concentration: the holed plates' hole-edge sigma_xx at h = 1/30 came out 4.6% / 6.1% low (the
# element's own strain: +0.07% / -1.05%); with 16 it is -0.8% / -1.4%, and the thick sphere's probes
# are no worse (8.9e-3 against 1.03e-2 at h = 1/8; docs/benchmarks.md, "Holed plates")
OWN_WEIGHT = 16.0
MIN_EIGENVALUE = 1e-9  # Jacobi-scaled patch matrix: below this a degree-k fit is not determined


def strain_polynomials(u: np.ndarray, basis: Basis, rotations: np.ndarray | None = None) -> np.ndarray:
    """Voigt strain (xx, yy, zz, yz, xz, xy; tensor strain) of coefficients u [E, 3, n] as monomial
    coefficients [E, 6, n] in each element's frame xi = (x - c_K) / h (degree k - 1 in the degree-k
    monomials); with rotations [E, 3, 3] the corotated strain sym(R^T (I + grad u)) - I."""
    D = B.derivative(basis.degree)  # [3, s, t]
    mono = np.einsum("epi,eis->eps", u, basis.T)  # u_p in monomials [E, 3, n]
    grad = np.einsum("eps,ast->epat", mono, D) / basis.h  # d u_p / d x_a [E, 3, 3, n] [1/m]
    if rotations is not None:
        # R^T (I + G) - I: the constant monomial (index 0) carries R^T - I
        grad = np.einsum("ebp,ebat->epat", rotations, grad)
        grad[..., 0] += rotations.transpose(0, 2, 1) - np.eye(3)
    pairs = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    return np.stack([0.5 * (grad[:, a, b] + grad[:, b, a]) for a, b in pairs], axis=1)


class PatchFit:
    """The patch least-squares fit of per-element polynomials of ``elements`` (see the module
    docstring); built once per geometry, :meth:`fit` per field."""

    @on_one_thread
    def __init__(self, elements: Elements, basis: Basis, own_weight: float = OWN_WEIGHT) -> None:
        self.elements, self.basis = elements, basis
        k, E = basis.degree, elements.count
        n = B.size(k)
        # the patch pairs (K, J): K itself and each face neighbour once (a union may share several faces)
        graph = sp.coo_matrix((np.ones(2 * len(elements.minus)), (np.concatenate([elements.minus, elements.plus]),
                                                                   np.concatenate([elements.plus, elements.minus]))),
                              shape=(E, E)).tocsr()
        graph.sum_duplicates()
        graph = (graph + sp.identity(E, format="csr")).tocoo()
        self._k, self._j = graph.row.astype(np.int64), graph.col.astype(np.int64)
        self._weight = np.where(self._k == self._j, own_weight, 1.0)
        # m(xi_K) = S m(xi_J) with xi_K = xi_J + (c_J - c_K) / h: whole cells, so few distinct shifts
        offset = (elements.cell[self._j] - elements.cell[self._k]).astype(np.float64)
        unique, inverse = np.unique(offset, axis=0, return_inverse=True)
        self._shift_of = B.shift(k, unique)[inverse.reshape(-1)]  # [pairs, n, n]
        self._hankel = B.hankel(elements.moments, k)  # [E, n, n]: int_J m_s m_t dV / h^3 in J's frame
        gram = np.zeros((E, n, n))  # sum_J w_KJ S H_J S^T: the patch's monomial products in K's frame
        np.add.at(gram, self._k, np.einsum("pst,ptu,pvu->psv", self._shift_of, self._hankel[self._j], self._shift_of)
                  * self._weight[:, None, None])
        # a patch that cannot pin a degree-k fit falls back to the element alone (its own polynomial)
        scale = 1.0 / np.sqrt(np.einsum("eii->ei", gram))
        scaled = gram * scale[:, :, None] * scale[:, None, :]
        self.determined = np.linalg.eigvalsh(scaled)[:, 0] > MIN_EIGENVALUE
        self._gram = np.where(self.determined[:, None, None], gram, self._hankel)

    def _gather(self, tested: np.ndarray) -> np.ndarray:
        """sum_J w_KJ S_KJ tested_J [E, n, c] for per-element right-hand sides tested [E, n, c]
        (J's monomials integrated against its data, in J's frame)."""
        moved = np.einsum("pst,ptc->psc", self._shift_of, tested[self._j]) * self._weight[:, None, None]
        out = np.zeros((self.elements.count,) + tested.shape[1:])
        np.add.at(out, self._k, moved)
        return out

    @on_one_thread
    def fit(self, coefficients: np.ndarray) -> np.ndarray:
        """Fitted monomial coefficients [E, c, n] (element frames) of per-element polynomials
        given as monomial coefficients [E, c, n]: degree-k least squares over each patch."""
        tested = np.einsum("est,ect->esc", self._hankel, coefficients)  # int_J m_s p_J dV / h^3
        rhs = np.where(self.determined[:, None, None], self._gather(tested), tested)
        return np.linalg.solve(self._gram, rhs).transpose(0, 2, 1)

    def evaluate(self, coefficients: np.ndarray, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Values [N, c] of monomial coefficients [E, c, n] at points [N, 3] [m] of ``element`` [N]."""
        xi = (np.asarray(points, dtype=float) - self.elements.centres[element]) / self.basis.h
        return np.einsum("ns,ncs->nc", B.monomials(xi, self.basis.degree), coefficients[element])
