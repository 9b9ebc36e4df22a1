"""Hex-sliced DG linear elasticity (Kaufmann et al. 2009): setup, solves, fields.

``DGElasticity`` is built once per geometry: elements (tiny pieces merged), orthonormal bases,
element / interface / Nitsche blocks, loads, the rigid modes left free; then an analysis driver
(``engine.analysis``) calls ``solve`` as often as it needs and ``fields`` per state. The system
is factorised once per (penalty, time step, rotations) by a sparse Cholesky; an IP matrix that
is not positive definite doubles the penalty and is refactorised (section 9.1), the penalty used
being reported. Mass: the bases are orthonormal, so M = rho h^3 I and backward Euler only shifts
the diagonal. ``material.model = "corotated"`` warps element and interface blocks by each
element's rotation (section 6) and iterates the rotations to a fixed point per solve.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..boundary import Prescribed, hold_warnings, select_patch
from ..errors import BoundaryError, VoxelasticError
from ..geometry.slicing import CutCells
from ..geometry.surface import Surface
from ..material import STRESS_FIELDS, Material, pressure, von_mises
from ..method import Setup, State
from ..output import FieldData
from ..solvers.direct import DirectSolver, NotPositiveDefinite
from ..solvers.linear import SolveStats
from ..solvers.rigid import BALANCE_TOLERANCE, PIN_TOLERANCE, UnbalancedLoadError, rigid_motions
from . import assembly, warping
from .elements import MERGE_FRACTION, Elements, make_elements
from .embedding import SurfaceEmbedding
from .integrals import Basis, make_basis, projected_load, surface_points
from .location import locate, owners
from .quadrature import VolumeRule, volume_rule

# Kaufmann et al. 9.1 start low and double until positive definite: a large eta pushes the method
# towards continuous P_k on the hex grid, which for k = 1 stiffens bending (cantilever tip 0.1005 at 2.5,
# 0.0947 at 5, k = 2: 0.0997) and slows the convergence on curved surfaces; k = 2 hardly depends on it
# (docs/benchmarks.md). The k = 1 matrix becomes positive definite between 1.25 and 1.5 on the ball
# (between 1 and 2 on the thick sphere): 2.5 keeps a margin.
DEFAULT_PENALTY = {1: 2.5, 2: 10.0}
# k = 1 stresses are constant per element, so the IP consistency terms see only the face mean of a jump,
# and only that part needs eta for coercivity. The rest is what a piecewise-affine field cannot avoid
# (a bilinear term of the solution jumps linearly across every face); penalised in full it stiffens
# k = 1 like a large eta (Lame sphere 1.56-1.70 per step, cantilever tip 24% short). Weighed at 1/10 it
# still keeps alternating element rotations from costing nothing (at 0 the cantilever's matrix is
# singular): Lame 1.8-2.2 per step, tip within 1.5% of k = 2 (docs/benchmarks.md). k = 2 keeps the full jump.
JUMP_REST = {1: 0.1, 2: 1.0}
MAX_DOUBLINGS = 12  # eta * 4096 without a positive definite matrix means something else is wrong


@dataclass
class DGElasticity:
    """The DG method on one sliced geometry. ``loads`` are staggered-style ``SurfaceLoad`` objects
    (traction / pressure / stress on the surface inside a region); body_force [3] or callable [N/m^3]."""

    cut: CutCells
    surface: Surface
    material: Material
    degree: int = 1
    flux: str = "ip"
    penalty: float | None = None  # None: DEFAULT_PENALTY[degree]
    prescribed: list[Prescribed] = field(default_factory=list)
    surface_loads: list = field(default_factory=list)
    body_force: np.ndarray | Callable | None = None
    merge_fraction: float = MERGE_FRACTION
    warnings: list[str] = field(default_factory=list)
    progress: Setup | None = field(default=None, repr=False)  # hears of the setup's parts

    def __post_init__(self) -> None:
        if self.degree not in (1, 2):
            raise VoxelasticError(f"method.degree: 1 or 2, got {self.degree}")
        if self.flux not in ("ip", "bz"):
            raise VoxelasticError(f"method.flux: 'ip' or 'bz', got {self.flux!r}")
        if self.cut.degree < 2 * self.degree:
            raise VoxelasticError(f"dg: degree {self.degree} needs moments of degree {2 * self.degree}, "
                                  f"the slicing has {self.cut.degree}")
        if self.penalty is None:
            self.penalty = DEFAULT_PENALTY[self.degree]
        say = self.progress or (lambda part, share: None)
        say("elements and basis", 0.0)
        t = time.perf_counter()
        self.timings: dict[str, float] = {}
        self.elements: Elements = make_elements(self.cut, self.merge_fraction)
        if self.elements.count == 0:
            raise VoxelasticError("geometry: no material inside the grid")
        self.warnings += self.elements.warnings
        self.basis: Basis = make_basis(self.elements, self.degree)
        self.n = self.basis.size
        self.lam, self.mu = self.material.lame
        self.timings["basis"] = time.perf_counter() - t
        say("element integrals", 0.2)
        t = time.perf_counter()
        self.element_blocks = assembly.element_blocks(self.elements, self.basis, self.mu, self.lam)
        self.timings["element_blocks"] = time.perf_counter() - t
        say("boundaries and loads", 0.4)
        t = time.perf_counter()
        self.patches = self._dirichlet_patches()
        self.warnings += hold_warnings(self.prescribed, self.surface)
        self.load_vector = self._loads()
        self.timings["loads"] = time.perf_counter() - t
        self.modes = self._free_modes()
        self.eta = float(self.penalty)
        self.dt: float | None = None
        self.rotations: np.ndarray | None = None
        self.warp_load = None
        self.solver: DirectSolver | None = None  # the factorised system; None once released
        self._last_u: np.ndarray | None = None  # the corotated fixed point's start: the last solution
        self._gradients: np.ndarray | None = None  # warping.mean_gradients, when the model warps
        say("assembly and factorisation", 0.6)
        self._build()

    # ------------------------------------------------------------------ setup
    @property
    def size(self) -> int:
        return self.elements.count * 3 * self.n

    def _dirichlet_patches(self) -> dict:
        """Surface patches of the displacement boundaries: one row per (boundary, element)."""
        el = self.elements
        tris, elem, patch, masks, values, names = [], [], [], [], [], []
        count = 0
        for k, bc in enumerate(self.prescribed):
            clipped, source = select_patch(bc.region, el.boundary_triangles, bc.name)
            owner = el.boundary_element[source]
            uniq, local = np.unique(owner, return_inverse=True)
            comp = bc.mask(3)
            tris.append(clipped)
            elem.append(owner)
            patch.append(local + count)
            masks.append(np.tile(comp.astype(float), (len(uniq), 1)))
            values += [k] * len(uniq)
            count += len(uniq)
        if count == 0:
            return {"count": 0}
        return {"count": count, "triangles": np.concatenate(tris), "element": np.concatenate(elem),
                "patch": np.concatenate(patch), "mask": np.concatenate(masks), "boundary": np.asarray(values)}

    def _loads(self) -> np.ndarray:
        """Consistent load vector [E, 3, n] [N] of body force and surface loads (unscaled)."""
        el, basis, n = self.elements, self.basis, self.n
        f = np.zeros((el.count, 3, n))
        if self.body_force is not None:
            if callable(self.body_force):
                rule = self.volume_rule()
                b = np.asarray(self.body_force(rule.points), dtype=float).reshape(-1, 3)
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

    def volume_rule(self) -> VolumeRule:
        """Quadrature exact to degree 4 on every element (cached)."""
        if getattr(self, "_rule", None) is None:
            self._rule = volume_rule(self.elements)
        return self._rule

    def _xi(self, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points) - self.elements.centres[element]) / self.basis.h

    def _dirichlet_rhs(self, eta_b: np.ndarray, value_scale: float = 1.0, rotations: np.ndarray | None = None
                       ) -> np.ndarray:
        """Nitsche right-hand side [E, 3, n] for the prescribed values g (times value_scale):
        -int (Pi g) . sigma(v) n + eta_b int (mu (Pi g . v + (Pi g . n) (v . n)) + lam P(Pi g . n) P(v . n)), P the
        projection onto degree k - 1 (``kernels.nitsche_blocks``). Warped (rotations [E, 3, 3]):
        the consistency part sees g in the element's frame, R^T (x + g) - x, and its force is rotated back."""
        el, basis, n = self.elements, self.basis, self.n
        out = np.zeros((el.count, 3, n))
        P = self.patches
        if P["count"] == 0:
            return out
        sp_ = surface_points(P["triangles"], P["element"], 2 * self.degree + 2)
        patch = P["patch"][sp_.triangle]
        mask = P["mask"][patch]
        g = np.zeros((len(sp_.points), 3))
        for k, bc in enumerate(self.prescribed):
            on = P["boundary"][patch] == k
            if not np.any(on):
                continue
            if callable(bc.value):
                g[on] = np.asarray(bc.value(sp_.points[on]), dtype=float).reshape(-1, 3)
            else:
                g[on] = np.array([0.0 if v is None else float(v) for v in bc.value])
        if not np.all(np.isfinite(g)):
            raise BoundaryError("boundaries: a prescribed displacement is not finite at some surface points")
        g = value_scale * g * mask
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
                              lam * eta_b[patch] * w * gn, el.count)
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
        el, basis, n = self.elements, self.basis, self.n
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
        out = []
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
        if out:
            size = np.abs(self.load_vector).sum()
            for members, q in out:
                f = self.load_vector[members].reshape(-1)
                if size > 0 and np.abs(q.T @ f).max() * np.sqrt(len(f)) > BALANCE_TOLERANCE * size:
                    # work of the loads on a unit translation: the coefficients of 1 are L[:, 0, :]
                    net = np.einsum("epi,ei->p", self.load_vector[members], basis.L[members][:, 0, :])
                    raise UnbalancedLoadError(
                        f"boundaries: the displacement boundaries leave {q.shape[1]} rigid-body mode(s) of a body of "
                        f"{len(members)} element(s) free and its loads do not balance (net force "
                        f"{np.round(net, 9).tolist()} N); add a displacement boundary on that body or balance the loads")
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
    @property
    def jump_rest(self) -> float:
        """Penalty weight on the zero-mean part of interface jumps (JUMP_REST; BZ: 1)."""
        return JUMP_REST[self.degree] if self.flux == "ip" else 1.0

    def _build(self) -> None:
        """Assemble and factorise; double eta until an IP matrix is positive definite."""
        for attempt in range(MAX_DOUBLINGS + 1):
            t = time.perf_counter()
            groups, self.eta_b = self._groups()
            if self.rotations is not None:
                X0 = warping.reference_state(self.elements, self.basis)
                groups, self.warp_load = warping.rotate(groups, self.rotations, X0)
            A = assembly.to_matrix(assembly.Blocks(np.concatenate([g.rows for g in groups]),
                                                   np.concatenate([g.cols for g in groups]),
                                                   np.concatenate([g.data for g in groups])), self.elements.count)
            if self.dt is not None:
                A = A + sp.identity(A.shape[0], format="csr") * (self.material.density * self.basis.h**3 / self.dt**2)
            self.matrix = A
            self.timings["assembly"] = self.timings.get("assembly", 0.0) + time.perf_counter() - t
            t = time.perf_counter()
            try:
                self.solver = DirectSolver(A, self._mode_matrix() if self.modes else None)
                self.timings["factorisation"] = self.timings.get("factorisation", 0.0) + time.perf_counter() - t
                break
            except NotPositiveDefinite:
                self.timings["factorisation"] = self.timings.get("factorisation", 0.0) + time.perf_counter() - t
                if self.flux == "bz" and self.patches["count"] == 0:
                    raise VoxelasticError("dg: the BZ matrix is not positive definite; the geometry is degenerate")
                self.eta *= 2
        else:
            raise VoxelasticError(f"dg: the matrix is not positive definite even with penalty {self.eta:g}")
        if self.eta != self.penalty and not any(w.startswith("the penalty was doubled") for w in self.warnings):
            self.warnings.append(f"the penalty was doubled to {self.eta:g} (from {self.penalty:g}) until the matrix "
                                 "was positive definite")
        self._dirichlet_cache = None

    def set_rotations(self, rotations: np.ndarray) -> None:
        """Warp the operator by element rotations [E, 3, 3] (corotated model) and refactorise."""
        self.rotations = rotations
        self._build()

    def release_solver(self) -> None:
        """Free the factorisation now, before the next one is made: PARDISO's memory is not
        Python's, so a replaced factor would otherwise stay resident (issue 18)."""
        if self.solver is not None:
            self.solver.free()
            self.solver = None

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

    def _groups(self) -> tuple[list[assembly.Group], np.ndarray]:
        """All blocks of the operator (element, interface, Nitsche) and the Nitsche penalties [b]."""
        el, basis, mu, lam, eta = self.elements, self.basis, self.mu, self.lam, self.eta
        E = el.count
        warp = self.material.model == "corotated"
        ip = 1.0 if self.flux == "ip" else 0.0
        every = np.arange(E)
        groups = [assembly.Group(every, every, self.element_blocks, every if warp else None)]

        def faces(weights, owner) -> None:
            b = assembly.face_blocks(el, basis, mu, lam, eta, weights, self.jump_rest)
            groups.extend([assembly.Group(el.minus, el.minus, b[:, 0, 0], owner),
                           assembly.Group(el.plus, el.plus, b[:, 1, 1], owner),
                           assembly.Group(el.minus, el.plus, b[:, 0, 1], owner)])

        if warp:
            faces((1.0, 0.0, 0.0), None)
            if ip:
                faces((0.0, 1.0, 0.0), el.minus)
                faces((0.0, 0.0, 1.0), el.plus)
        else:
            faces((1.0, ip, ip), None)
        eta_b = np.zeros(0)
        P = self.patches
        if P["count"]:
            owner = np.zeros(P["count"], dtype=np.int64)
            owner[P["patch"]] = P["element"]
            args = (el, basis, mu, lam, eta, P["triangles"], P["element"], P["patch"], P["mask"])
            self.patch_owner = owner
            if warp:
                pen, eta_b, self.patch_low = assembly.nitsche_blocks(*args, weights=(1.0, 0.0))
                groups.append(assembly.Group(owner, owner, pen))
                if ip:
                    cons, _, _ = assembly.nitsche_blocks(*args, weights=(0.0, 1.0))
                    groups.append(assembly.Group(owner, owner, cons, owner))
            else:
                both, eta_b, self.patch_low = assembly.nitsche_blocks(*args, weights=(1.0, ip))
                groups.append(assembly.Group(owner, owner, both))
        return groups, eta_b

    # ------------------------------------------------------------------ solve
    def set_time_step(self, dt: float | None) -> None:
        """Backward Euler with step dt [s] adds M / dt^2 = rho h^3 / dt^2 I; None goes back to statics."""
        if dt != self.dt:
            self.dt = dt
            self._build()

    def solve(self, load_scale: float = 1.0, value_scale: float = 1.0, x0: np.ndarray | None = None,
              inertia: np.ndarray | None = None, on_iteration: Callable[[int, float], None] | None = None) -> State:
        """Coefficients minimising the energy with loads and prescribed values scaled; ``inertia``:
        the predicted u^k + dt v^k [E, 3, n] of a backward-Euler step (after ``set_time_step``)."""
        t0 = time.perf_counter()
        if self.material.model == "corotated":
            return self._solve_corotated(load_scale, value_scale, inertia, on_iteration, t0)
        u, stats = self._linear_solve(load_scale, value_scale, inertia, on_iteration)
        return State(u, stats, time.perf_counter() - t0)

    def _solve_corotated(self, load_scale: float, value_scale: float, inertia: np.ndarray | None,
                         on_iteration: Callable[[int, float], None] | None, t0: float) -> State:
        """The fixed point of rotations and displacement (``warping.solve_corotated``), from the last solution."""
        if self._gradients is None:
            self._gradients = warping.mean_gradients(self.elements, self.basis)

        def warped_solve(rotations: np.ndarray) -> tuple[np.ndarray, SolveStats]:
            self.release_solver()  # before the refactorisation, not after it: one factor resident at a time
            self.set_rotations(rotations)
            return self._linear_solve(load_scale, value_scale, inertia)

        start = np.zeros((self.elements.count, 3, self.n)) if self._last_u is None else self._last_u
        try:
            state = warping.solve_corotated(warped_solve, start, self._gradients, on_iteration, t0)
        except warping.CorotatedDiverged:
            self.release_solver()  # the job ends here: its factor need not wait for the method to go
            raise
        self._last_u = state.u
        return state

    def _rhs(self, load_scale: float, value_scale: float, inertia: np.ndarray | None) -> np.ndarray:
        if self.rotations is not None:  # the rotated prescribed values are not linear in their scale
            b = load_scale * self.load_vector + self._dirichlet_rhs(self.eta_b, value_scale, self.rotations)
            b = b + self.warp_load
        else:
            if self._dirichlet_cache is None:
                self._dirichlet_cache = self._dirichlet_rhs(self.eta_b)
            b = load_scale * self.load_vector + value_scale * self._dirichlet_cache
        if inertia is not None and self.dt is not None:
            b = b + self.material.density * self.basis.h**3 / self.dt**2 * inertia
        return b.reshape(-1)

    def _linear_solve(self, load_scale: float, value_scale: float, inertia: np.ndarray | None,
                      on_iteration: Callable[[int, float], None] | None = None) -> tuple[np.ndarray, SolveStats]:
        """Coefficients [E, 3, n] of one solve with the current factorisation, and its statistics."""
        x, stats = self.solver.solve(self._rhs(load_scale, value_scale, inertia), on_iteration=on_iteration)
        return x.reshape(self.elements.count, 3, self.n), stats

    def condition_estimate(self) -> float:
        """2-norm condition number of the factorised matrix (Lanczos on A and on A^-1 through the
        factor, 1e-3 relative accuracy); NaN when rigid modes are bordered out."""
        import scipy.sparse.linalg as spla

        if self.modes:
            return float("nan")
        n = self.matrix.shape[0]
        top = spla.eigsh(self.matrix, k=1, which="LA", tol=1e-3, return_eigenvectors=False)[0]
        inverse = spla.LinearOperator((n, n), matvec=lambda v: self.solver.apply_inverse(np.asarray(v).ravel()),
                                      dtype=float)
        bottom = 1.0 / spla.eigsh(inverse, k=1, which="LA", tol=1e-3, return_eigenvectors=False)[0]
        return float(top / bottom)

    # ------------------------------------------------------------------ fields
    def evaluate(self, u: np.ndarray, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Displacement [N, 3] [m] of coefficients u [E, 3, n] at points [N, 3] of ``element`` [N]."""
        psi = self.basis.values(element, self._xi(element, points))
        return np.einsum("qpi,qi->qp", u[element], psi)

    def gradient(self, u: np.ndarray, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Displacement gradient [N, 3, 3] (du_p / dx_a at [:, p, a]) at points of ``element``."""
        grad = self.basis.gradients(element, self._xi(element, points))
        return np.einsum("qpi,qai->qpa", u[element], grad)

    def stress_at(self, u: np.ndarray, element: np.ndarray, points: np.ndarray,
                  rotations: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(strain, stress) Voigt [N, 6] (xx, yy, zz, yz, xz, xy; tensor strain) at points of ``element``;
        with rotations [E, 3, 3] the corotated strain sym(R^T F) - I."""
        G = self.gradient(u, element, points)
        if rotations is not None:
            F = np.eye(3) + G
            G = np.einsum("qba,qbc->qac", rotations[element], F) - np.eye(3)
        eps = 0.5 * (G + G.transpose(0, 2, 1))
        voigt = np.stack([eps[:, 0, 0], eps[:, 1, 1], eps[:, 2, 2], eps[:, 1, 2], eps[:, 0, 2], eps[:, 0, 1]], axis=1)
        from ..material import stress as hooke

        return voigt, hooke(voigt, self.lam, self.mu, 3)

    def cell_elements(self) -> tuple[np.ndarray, np.ndarray]:
        """(cells [C, 3], element [C]): every cell holding material and the element of its largest piece."""
        cut, el = self.cut, self.elements
        order = np.lexsort((-cut.volume, self.elements.grid.linear_index(cut.piece_cell)))
        lin = self.elements.grid.linear_index(cut.piece_cell[order])
        first = np.concatenate([[True], lin[1:] != lin[:-1]])
        pick = order[first]
        return cut.piece_cell[pick], el.piece_element[pick]

    def locate(self, points: np.ndarray) -> np.ndarray:
        """Element [N] containing each point, -1 outside the material (surface points count as inside)."""
        return locate(self.elements, self.cut, self.surface, points)

    def owners(self, points: np.ndarray) -> np.ndarray:
        """Element [N] of points known to lie in the solid or on its surface (``location.owners``)."""
        return owners(self.elements, self.cut, points)

    def fields(self, state: State, names: list[str], probes: np.ndarray | None, surface: bool,
               time_value: float | None = None, velocity: np.ndarray | None = None) -> FieldData:
        grid = self.elements.grid
        u = state.u
        rot = state.rotations
        cells, element = self.cell_elements()
        centres = grid.sample_points(cells)
        data = FieldData(time=time_value)
        idx = tuple(cells.T)

        def dense(values: np.ndarray) -> np.ndarray:
            out = np.full(tuple(grid.shape) + values.shape[1:], np.nan)
            out[idx] = values
            return out

        need_stress = any(n in names for n in STRESS_FIELDS)
        if "displacement" in names:
            data.cells["displacement"] = dense(self.evaluate(u, element, centres))
        if velocity is not None and "velocity" in names:
            data.cells["velocity"] = dense(self.evaluate(velocity, element, centres))
        if need_stress:
            eps, sig = self.stress_at(u, element, centres, rot)
            for name, val in (("strain", eps), ("stress", sig), ("von_mises", von_mises(sig, 3)),
                              ("pressure", pressure(sig, 3))):
                if name in names:
                    data.cells[name] = dense(val)
        if probes is not None and len(probes):
            probes = np.asarray(probes, dtype=float)
            where = self.locate(probes)
            ok = where >= 0
            sel = where[ok]

            def probe(values: np.ndarray, width: tuple) -> np.ndarray:
                out = np.full((len(probes),) + width, np.nan)
                out[ok] = values
                return out

            if "displacement" in names:
                data.probes["displacement"] = probe(self.evaluate(u, sel, probes[ok]), (3,))
            if velocity is not None and "velocity" in names:
                data.probes["velocity"] = probe(self.evaluate(velocity, sel, probes[ok]), (3,))
            if need_stress:
                eps, sig = self.stress_at(u, sel, probes[ok], rot)
                for name, val, width in (("strain", eps, (6,)), ("stress", sig, (6,)),
                                         ("von_mises", von_mises(sig, 3), ()), ("pressure", pressure(sig, 3), ())):
                    if name in names:
                        data.probes[name] = probe(val, width)
        if surface:
            data.surface["displacement"] = self.embedding().displacement(u)
        return data

    def embedding(self) -> SurfaceEmbedding:
        if getattr(self, "_embedding", None) is None:
            self._embedding = SurfaceEmbedding(self)
        return self._embedding

