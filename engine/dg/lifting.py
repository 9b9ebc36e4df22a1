"""The lifted divergence of a DG field: what the volumetric energy holds near incompressibility.

The interior-penalty form's volumetric part is lam ((div u, div v) - sum_F <{div v}, Pi[u]_n> - ...),
which is lam (D_h u, D_h v) plus face terms, with D_h u = div u - r([u]_n) and r the lifting of the
normal jumps into P_{k-1} per element: (r(j), q)_K = sum over the faces F of K of w_F int_F q j dA for
every q in P_{k-1}(K) (w_F = 1/2 on interfaces, the {q} average; 1 on a displacement patch, whose
jump is the held components' (u - g) . n). D_h u is the L2 projection of u's distributional
divergence, and it, not the element's own div u, is what lam drives to zero: near nu = 1/2 the
element's div u carries the jumps' share, and lambda times it was pressure noise as large as the
pressure (the free thick sphere at nu 0.4999, h = 1/8: 56% off at the probes, 3.2% now; 1.6% at nu 0.3).
"""

from __future__ import annotations

import numpy as np

from . import basis as B
from .elements import Elements
from .integrals import Basis, SurfacePoints, face_products

FACE_CHUNK = 4096  # faces per pass (the face products of a chunk: ~0.1 GB for k = 2)
POINT_CHUNK = 2**16  # patch points per pass


def lifted_jumps(el: Elements, basis: Basis, u: np.ndarray, patches: dict, points: SurfacePoints | None = None,
                 held: np.ndarray | None = None) -> np.ndarray:
    """r(j) [E, n] [-] as coefficients of each element's basis psi_I (zero for I of
    degree k or more) for coefficients u [E, 3, n]; ``patches`` the displacement patches
    (``DGElasticity.patches``), ``points`` their quadrature and ``held`` [Q, 3] the prescribed values
    there (zero where a component is free; None: no patches)."""
    k, h = basis.degree, basis.h
    low = B.size(k - 1)
    out = np.zeros((el.count, basis.size))

    def add(faces: np.ndarray, M: np.ndarray) -> None:
        """int_F psi^X_I [u]_n / 2 into both sides' rows, [u]_n = u^- . n - u^+ . n (n = e_axis);
        M [F | 1, X, Y, I < low, J] the faces' products."""
        a = el.axis[faces]
        minus, plus = u[el.minus[faces], a], u[el.plus[faces], a]  # [F, n]: the normal component
        for X, side in ((0, el.minus[faces]), (1, el.plus[faces])):
            moment = (M[:, X, 0] @ minus[:, :, None] - M[:, X, 1] @ plus[:, :, None])[:, :, 0]  # M broadcasts
            np.add.at(out[:, :low], side, 0.5 * moment)

    # faces between two full cells share one product per axis (as the assembly's reference blocks)
    for a in range(3):
        shared = np.nonzero(el.reference_faces & (el.axis == a))[0]
        if len(shared):
            add(shared, face_products(el, basis, shared[:1])[0][:, :, :, :low, :])
    others = np.nonzero(~el.reference_faces)[0]
    for lo in range(0, len(others), FACE_CHUNK):
        faces = others[lo:lo + FACE_CHUNK]
        add(faces, face_products(el, basis, faces)[0][:, :, :, :low, :])
    if patches["count"] and points is not None:
        # a chunk at a time: u at every point of a scanned surface's patches is [Q, 3, n]
        for lo in range(0, len(points.weights), POINT_CHUNK):
            q = slice(lo, lo + POINT_CHUNK)
            element = points.element[q]
            mask = patches["mask"][patches["patch"][points.triangle[q]]]
            xi = (points.points[q] - el.centres[element]) / h
            uq = np.einsum("qpi,qi->qp", u[element], basis.values(element, xi))
            jump = np.einsum("qp,qp->q", mask * uq - held[q], points.normals[q])
            out += basis.tested(el.count, element, xi, (points.weights[q] * jump)[:, None])[:, 0]
    out[:, low:] = 0.0
    return out / h**3  # the bases are orthonormal: int_K psi_I psi_J dV = h^3 delta_IJ
