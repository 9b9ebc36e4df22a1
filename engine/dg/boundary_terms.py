"""The DG method's boundary terms: the displacement patches' Nitsche data, the surface and body
loads, and the rigid modes the patches leave free (per body), as a part of ``DGElasticity``.

Mixed into ``elasticity.DGElasticity`` (it reads the method's elements, basis, material and
boundaries); kept apart so that the class reads by concern: setup and solves there, boundary
terms here, output fields in ``fields.py``.
"""

from __future__ import annotations

import numpy as np

from ..boundary import evaluate, select_patch
from ..errors import BoundaryError
from ..solvers.rigid import BALANCE_TOLERANCE, PIN_TOLERANCE, UnbalancedLoadError, rigid_motions, torque_vector
from .integrals import SurfacePoints, projected_load, surface_points


class BoundaryTerms:
    """Boundary terms of ``DGElasticity`` (see the module docstring)."""

    def _dirichlet_patches(self) -> dict:
        """Surface patches of the displacement boundaries: one row per (element, held components),
        so that boundaries meeting in an element share its penalty (eta_b grows with the held area)
        and its projection, as one boundary over both parts would."""
        el = self.elements
        tris, elem, masks, which = [], [], [], []
        for k, bc in enumerate(self.prescribed):
            clipped, source = select_patch(bc.region, el.boundary_triangles, bc.name)
            tris.append(clipped)
            elem.append(el.boundary_element[source])
            masks.append(np.broadcast_to(bc.mask(3), (len(clipped), 3)))
            which.append(np.full(len(clipped), k))
        if not tris:
            return {"count": 0}
        elem, masks = np.concatenate(elem), np.concatenate(masks)
        key = elem * 8 + masks @ np.array([1, 2, 4])
        rows, patch = np.unique(key, return_inverse=True)
        return {"count": len(rows), "triangles": np.concatenate(tris), "element": elem, "patch": patch,
                "mask": ((rows[:, None] % 8) >> np.arange(3) & 1).astype(float), "boundary": np.concatenate(which)}

    def _loads(self) -> np.ndarray:
        """Consistent load vector [E, 3, n] [N] of body force and surface loads (unscaled)."""
        el, basis, n = self.elements, self.basis, self.n
        f = np.zeros((el.count, 3, n))
        if self.body_force is not None:
            if callable(self.body_force):
                rule = self.volume_rule()
                b = evaluate(self.body_force, rule.points, (3,), "loads: the body force")
                f += basis.tested(el.count, rule.element, rule.xi, rule.weights[:, None] * b)
            else:
                g = np.asarray(self.body_force, dtype=float).reshape(3)
                mean = basis.h**3 * np.einsum("eis,es->ei", basis.T, el.moments[:, :n])  # int psi_I dV
                f += g[None, :, None] * mean[:, None, :]
        for load in self.surface_loads:
            clipped, source = select_patch(load.region, el.boundary_triangles, load.name)
            sp_ = surface_points(clipped, el.boundary_element[source], self.degree + 3)
            t = load.tractions(sp_.points, sp_.normals)
            f += basis.tested(el.count, sp_.element, self._xi(sp_.element, sp_.points), sp_.weights[:, None] * t)
        if not np.all(np.isfinite(f)):
            raise BoundaryError("loads: the load vector is not finite (check loads.gravity and the traction values)")
        return f

    def _xi(self, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points) - self.elements.centres[element]) / self.basis.h

    def patch_points(self) -> SurfacePoints:
        """The displacement patches' quadrature points (exact to degree 2 k + 2)."""
        P = self.patches
        return surface_points(P["triangles"], P["element"], 2 * self.degree + 2)

    def prescribed_at(self, points: SurfacePoints, value_scale: float = 1.0) -> np.ndarray:
        """The prescribed values g [Q, 3] [m] at the patches' ``points``, times ``value_scale``, zero in
        the components their boundary leaves free."""
        P = self.patches
        g = np.zeros((len(points.points), 3))
        for k, bc in enumerate(self.prescribed):
            on = P["boundary"][points.triangle] == k
            if not np.any(on):
                continue
            g[on] = bc.values(points.points[on])  # shape and finiteness checked, naming the boundary
        return value_scale * g * P["mask"][P["patch"][points.triangle]]

    def _dirichlet_rhs(self, eta_b: np.ndarray, value_scale: float = 1.0, rotations: np.ndarray | None = None
                       ) -> np.ndarray:
        """Nitsche right-hand side [E, 3, n] for the prescribed values g (times value_scale):
        -int (Pi g) . sigma(v) n + eta_b int (mu (Pi g . v + (Pi g . n) (v . n)) + s lam P(Pi g . n) P(v . n)), P the
        projection onto degree k - 1 (``kernels.nitsche_blocks``), s the volumetric penalty's share
        eta_volumetric / eta. Warped (rotations [E, 3, 3]):
        the consistency part sees g in the element's frame, R^T (x + g) - x, and its force is rotated back."""
        el, basis, n = self.elements, self.basis, self.n
        out = np.zeros((el.count, 3, n))
        P = self.patches
        if P["count"] == 0:
            return out
        sp_ = self.patch_points()
        patch = P["patch"][sp_.triangle]
        mask = P["mask"][patch]
        g = self.prescribed_at(sp_, value_scale)
        gc = g
        if rotations is not None:
            x = sp_.points
            gc = (np.einsum("qba,qb->qa", rotations[sp_.element], x + g) - x) * mask
        nrm, w = sp_.normals, sp_.weights
        xi = self._xi(sp_.element, sp_.points)
        mu, lam = self.mu, self.lam
        gn = np.einsum("qa,qa->q", g, nrm)
        pen = eta_b[patch][:, None] * mask * mu * (g + gn[:, None] * nrm)  # [Q, p]
        out += basis.tested(el.count, sp_.element, xi, w[:, None] * pen)
        # the volumetric part penalises only the normal jump's projection onto degree k - 1 (kernels.nitsche_blocks)
        out += projected_load(basis, self.patch_low, self.patch_owner, P["mask"], xi, patch,
                              lam * self.eta_volumetric / self.eta * eta_b[patch] * w * gn, el.count)
        if self.flux != "ip":
            return out
        # g . sigma(psi_I e_p) n = sum_a V_pa d_a psi_I, V_pa = mu (g_p n_a + n_p g_a) + lam (g . n) delta_pa
        gn_c = np.einsum("qa,qa->q", gc, nrm)
        V = mu * (gc[:, :, None] * nrm[:, None, :] + nrm[:, :, None] * gc[:, None, :]) + lam * gn_c[:, None, None] * np.eye(3)
        cons = basis.tested(el.count, sp_.element, xi, w[:, None, None] * V, gradient=True)  # [E, p, I]
        if rotations is not None:  # one rotation per element: it commutes with the sum over its points
            cons = np.einsum("eps,esi->epi", rotations, cons)
        return out - cons

    def _free_modes(self) -> list:
        """Per body, the rigid modes the Dirichlet patches leave free: (elements, basis [E_b*3*n, k])."""
        el = self.elements
        body = el.bodies()
        P = self.patches
        held = np.zeros((body.max() + 1, 6, 6))
        centre = np.zeros((body.max() + 1, 3))
        np.add.at(centre, body, el.centres * el.volume[:, None])
        centre /= np.bincount(body, weights=el.volume)[:, None]
        if P["count"]:
            sp_ = surface_points(P["triangles"], P["element"], 2)
            mask = P["mask"][P["patch"][sp_.triangle]]
            b = body[sp_.element]
            r = rigid_motions(sp_.points, centre[b])  # [Q, 6, 3], each body's about its centre
            r = r * mask[:, None, :]
            np.add.at(held, b, sp_.weights[:, None, None] * np.einsum("qmp,qlp->qml", r, r))
        out, loose_bodies = [], []
        for label in np.unique(body):
            members = np.nonzero(body == label)[0]
            scale = np.bincount(body, weights=el.volume)[label] ** (1 / 3)
            G = held[label]
            # normalise rotations by the body's size so translations and rotations compare
            S = np.diag([1, 1, 1, 1 / scale, 1 / scale, 1 / scale])
            w, v = np.linalg.eigh(S @ G @ S)
            loose = v[:, w < PIN_TOLERANCE * max(float(w.max(initial=0.0)), 1e-300) + (w.max(initial=0.0) == 0)]
            if loose.shape[1] == 0:
                continue
            modes = self._mode_coefficients(members, centre[label], S @ loose)  # [members * 3 n, k]
            q, _ = np.linalg.qr(modes)
            out.append((members, q))
            loose_bodies.append(label)
        if out and self.time_step is None:
            size = np.abs(self.load_vector).sum()
            for (members, q), label in zip(out, loose_bodies):
                f = self.load_vector[members].reshape(-1)
                if size > 0 and np.abs(q.T @ f).max() * np.sqrt(len(f)) > BALANCE_TOLERANCE * size:
                    # the loads' work on unit translations and rotations about the centroid: a pure
                    # couple has no net force, and naming only that read "[0.0, -0.0, 0.0] N"
                    work = self._mode_coefficients(members, centre[label], np.eye(6)).T @ f
                    raise UnbalancedLoadError(
                        f"boundaries: the displacement boundaries leave {q.shape[1]} rigid-body mode(s) of a body of "
                        f"{len(members)} element(s) free and its loads do not balance (net force "
                        f"{(np.round(work[:3], 9) + 0.0).tolist()} N, net torque about its centroid "
                        f"{torque_vector(work[3:], 9)} N m); add a displacement boundary on that body or balance "
                        "the loads")
            self.warnings.append(
                f"{sum(q.shape[1] for _, q in out)} rigid-body mode(s) are not held by any displacement boundary; "
                "the loads balance, so the solution is the one with no rigid motion (orthogonal to those modes)")
        return out

    def _mode_coefficients(self, members: np.ndarray, centre: np.ndarray, combos: np.ndarray) -> np.ndarray:
        """Coefficients [len(members) * 3 n, k] of rigid motions sum_m combos[m, j] r_m (rotations about centre [3])."""
        basis, h = self.basis, self.basis.h
        c = self.elements.centres[members] - centre
        L = basis.L[members]  # rows: monomials 1, xi_x, xi_y, xi_z in the basis
        one = L[:, 0, :]  # [members, n]: coefficients of the constant 1
        x = np.stack([c[:, a, None] * one + h * L[:, 1 + a, :] for a in range(3)], axis=-1)  # of x_a: [members, n, 3]
        # a rigid motion t + W x is affine in x: its coefficients are the motion evaluated at the
        # coefficients of x, with the translations' constant 1 replaced by the coefficients of 1
        r = rigid_motions(x.reshape(-1, 3), np.zeros(3))  # [members * n, 6, 3]
        r[:, np.arange(3), np.arange(3)] = one.reshape(-1, 1)
        cols = r.reshape(len(members), -1, 6, 3).transpose(0, 3, 1, 2).reshape(-1, 6)  # [members*3*n, 6]
        return cols @ combos

    # ------------------------------------------------------------------ system

    def _mode_matrix(self) -> np.ndarray:
        """The free rigid modes as columns [size, k] over all coefficients (orthonormal per body)."""
        Q = np.zeros((self.size, sum(q.shape[1] for _, q in self.modes)))
        col = 0
        s = 3 * self.n
        for members, q in self.modes:
            rows = (members[:, None] * s + np.arange(s)[None, :]).reshape(-1)
            Q[rows, col:col + q.shape[1]] = q
            col += q.shape[1]
        return Q
