"""Hex-sliced DG linear elasticity (Kaufmann et al. 2009): setup and solves; the boundary terms
(``boundary_terms.py``) and the output fields (``fields.py``) are the class's other two parts.

``DGElasticity`` is built once per geometry: elements (tiny pieces merged), orthonormal bases,
element / interface / Nitsche blocks, loads, the rigid modes left free; then an analysis driver
(``engine.analysis``) calls ``solve`` as often as it needs and ``fields`` per state. The system
is factorised once per (penalty, time step, rotations) by a sparse Cholesky; an IP matrix that
is not positive definite raises the penalty and is refactorised (section 9.1; near incompressibility
the volumetric terms' penalty first, ``_raise_penalty``), a doubled penalty being reported. Mass:
the bases are orthonormal, so M = rho h^3 I and backward Euler only shifts the diagonal.
``material.model = "corotated"`` warps element and interface blocks by each element's rotation
(section 6) and iterates the rotations to a fixed point per solve.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..boundary import Prescribed, check_holds, exclusive_holds
from ..errors import VoxelasticError
from ..geometry.slicing import CutCells
from ..geometry.surface import Surface, thickness
from ..material import Material
from ..method import Setup, State, no_progress
from ..solvers.direct import DirectSolver, NotPositiveDefinite
from ..solvers.linear import SolverError, SolveStats
from ..solvers.pmultigrid import PMultigrid
from . import assembly, basis as B, warping
from .boundary_terms import BoundaryTerms
from .fields import Fields
from .elements import MERGE_FRACTION, Elements, make_elements
from .integrals import Basis, make_basis
from .problem import COARSE_DIRECT, DIRECT_LIMIT, DIRECT_LIMIT_INCOMPRESSIBLE, INCOMPRESSIBLE_RATIO
from .quadrature import VolumeRule, volume_rule

# Kaufmann et al. 9.1 start low and double until positive definite: a large eta pushes the method
# towards continuous P_k on the hex grid, which for k = 1 stiffens bending (tests/test_dg.py's bar:
# tip 0.1027 at 2.5, 0.0984 at 5) and for k = 2 biases stresses and displacements near curved
# surfaces (thick sphere at h = 1/8, outer-surface von Mises max over the exact: 1.013 / 1.018 /
# 1.031 / 1.057 at eta 3 / 5 / 10 / 20; the bracket benchmark at 5 mm: 9.0e-3 at 5, 1.8e-2 at 10).
# The matrix becomes positive definite at k = 1 between 1.25 and 1.5 on the ball (1 and 2 on the
# thick sphere); at k = 2 between 2 and 2.5 on the thick sphere, 3 and 4 on the ball, 3 and 5 on the
# bracket; at nu 0.4999 the volumetric terms' threshold rises above 5 (below VOLUMETRIC_STEP)
# (docs/benchmarks.md, "The DG penalty").
DEFAULT_PENALTY = {1: 2.5, 2: 5.0}
# k = 1 stresses are constant per element, so the IP consistency terms see only the face mean of a jump,
# and only that part needs eta for coercivity. The rest is what a piecewise-affine field cannot avoid
# (a bilinear term of the solution jumps linearly across every face); penalised in full it stiffens
# k = 1 like a large eta (Lame sphere 1.56-1.70 per step, cantilever tip 24% short). Weighed at 1/10 it
# still keeps alternating element rotations from costing nothing (at 0 the cantilever's matrix is
# singular): Lame 1.8-2.2 per step, tip within 1.5% of k = 2 (docs/benchmarks.md). k = 2 keeps the full jump.
JUMP_REST = {1: 0.1, 2: 1.0}
MAX_DOUBLINGS = 12  # eta * 4096 without a positive definite matrix means something else is wrong
# The volumetric terms lam ((div u, div v) - consistency + eta Pi[u]_n Pi[v]_n) are a form of their own, positive
# semi-definite once their eta passes a trace constant, and so are the shear terms with theirs. Near
# incompressibility the volumetric form, lam / mu times the other, is the one that fails (the thick sphere at nu
# 0.4999: between 5.5 and 6.05 at h = 1/6, while the shear form holds at 5), and raising the shear penalty with it
# only stiffens the method: the sphere's error at nu 0.4999 over nu 0.3's was 2.69x / 3.54x at h = 1/8 / 1/6 with
# both doubled to 10, 1.80x / 2.45x with the volumetric one alone at 6.25 (docs/benchmarks.md, "DG near
# incompressibility"). So above INCOMPRESSIBLE_RATIO the volumetric penalty rises alone, by VOLUMETRIC_STEP (a
# smaller step lands nearer the threshold at the price of more failed factorisations), until it is
# VOLUMETRIC_AHEAD times the shear one; then both double.
VOLUMETRIC_AHEAD = 2.0
VOLUMETRIC_STEP = 1.25


def degree_chain(degree: int) -> list[np.ndarray]:
    """The p-multigrid's levels below degree k: per level, the places of the degree-(j - 1) functions
    among a block of degree j's (three components of C(j + 3, 3) functions each). They come first in
    every component's orthonormal basis, which is built degree by degree."""
    return [(np.arange(3)[:, None] * B.size(j) + np.arange(B.size(j - 1))[None, :]).reshape(-1)
            for j in range(degree, 0, -1)]


# a solid thinner than this many cells (2 V / A) bends too easily with degree 1: a cantilever plate's
# tip over beam theory 3.2 / 3.2 / 1.7 / 1.7 / 1.1 at 0.1 / 0.24 / 0.5 / 1 / 2 cells thick (degree 2:
# 0.99-1.05 at all of these; 2.3x at 0.016 cells, below THIN_CELLS[2])
THIN_CELLS = {1: 2.0, 2: 0.05}
# the sliced solid's volume may differ from the surface's by this share (round-off of the slicer's booleans)
VOLUME_TOLERANCE = 1e-6


def thin_solid_warning(surface: Surface, h: float, degree: int) -> list[str]:
    """A warning when the closed ``surface``'s solid is thin for elements of degree ``degree`` on cells of ``h`` [m]."""
    cells = thickness(surface) / h if surface.closed else float("inf")
    if cells >= THIN_CELLS[degree]:
        return []
    advice = "use method.degree 2 or refine the grid" if degree == 1 else "refine the grid (grid.resolution, grid.cell_size)"
    return [f"the solid is thin for this grid: twice its volume over its surface area (a plate's thickness) is {cells:.2g} "
            f"cells of h = {h:.4g} m; below {THIN_CELLS[degree]:g} cells degree-{degree} elements bend too easily "
            f"(a plate's deflection up to 3x too large): {advice}"]


def volume_warning(solid: float, surface: Surface) -> list[str]:
    """A warning when the sliced solid's volume ``solid`` [m^3] is not what the closed ``surface``
    encloses by the divergence theorem: a shell that folds over itself (self-intersecting) is cut
    as the union of its folds, +3.5% on a box with one corner pushed through the opposite face,
    where the staggered method's fractions warn of the overlap."""
    enclosed = surface.enclosed_volume()
    if not surface.closed or enclosed <= 0 or abs(solid - enclosed) <= VOLUME_TOLERANCE * enclosed:
        return []
    return [f"the cut cells hold {solid:.6g} m^3 of solid where the surface encloses {enclosed:.6g} m^3 "
            f"({100 * (solid / enclosed - 1):+.2g}%): the surface intersects itself or overlaps, and the pieces take the "
            "union of its folds; repair the mesh (remove the self-intersection) for an exact volume"]


@dataclass
class DGElasticity(BoundaryTerms, Fields):
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
    solver_kind: str = "auto"  # "direct" (sparse Cholesky), "iterative" (p-multigrid CG) or "auto" (by size)
    rtol: float = 1e-8  # relative residual of the iterative solver
    max_iterations: int = 5000
    warnings: list[str] = field(default_factory=list)
    progress: Setup | None = field(default=None, repr=False)  # hears of the setup's parts
    # a dynamic job's backward-Euler step [s]: the first factorisation is made with the mass (set_time_step
    # would make a second), and since every solve carries the mass, which holds a body no boundary holds,
    # such a body's loads need not balance (it accelerates)
    time_step: float | None = None

    def __post_init__(self) -> None:
        if self.degree not in (1, 2):
            raise VoxelasticError(f"method.degree: 1 or 2, got {self.degree}")
        if self.flux not in ("ip", "bz"):
            raise VoxelasticError(f"method.flux: 'ip' or 'bz', got {self.flux!r}")
        if self.solver_kind not in ("auto", "direct", "iterative"):
            raise VoxelasticError(f"method.solver: 'auto', 'direct' or 'iterative', got {self.solver_kind!r}")
        if self.cut.degree < 2 * self.degree:
            raise VoxelasticError(f"dg: degree {self.degree} needs moments of degree {2 * self.degree}, "
                                  f"the slicing has {self.cut.degree}")
        if self.penalty is None:
            self.penalty = DEFAULT_PENALTY[self.degree]
        say = self.progress or no_progress
        say("elements and basis", 0.0)
        t = time.perf_counter()
        self.timings: dict[str, float] = {}
        self.elements: Elements = make_elements(self.cut, self.merge_fraction)
        if self.elements.count == 0:
            raise VoxelasticError("geometry: no material inside the grid")
        self.warnings += self.elements.warnings
        self.warnings += volume_warning(self.elements.volume.sum(), self.surface)
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
        self.warnings += check_holds(self.prescribed, self.surface)
        self.warnings += thin_solid_warning(self.surface, self.elements.grid.spacing, self.degree)
        self.prescribed = exclusive_holds(self.prescribed, self.surface)
        self.patches = self._dirichlet_patches()
        self.load_vector = self._loads()
        self.timings["loads"] = time.perf_counter() - t
        self.modes = self._free_modes()
        self.eta = float(self.penalty)  # the shear terms' penalty
        self.eta_volumetric = self.eta  # the volumetric terms' (``_raise_penalty``)
        self.dt: float | None = self.time_step
        self.rotations: np.ndarray | None = None
        self.warp_load = None
        self.solver: DirectSolver | PMultigrid | None = None  # the set-up solver; None once released
        self._last_u: np.ndarray | None = None  # the corotated fixed point's start: the last solution
        self._gradients: np.ndarray | None = None  # warping.mean_gradients, when the model warps
        say("assembly and factorisation", 0.6)
        self._build()

    # ------------------------------------------------------------------ setup
    @property
    def size(self) -> int:
        return self.elements.count * 3 * self.n

    def volume_rule(self) -> VolumeRule:
        """Quadrature exact to degree 4 on every element (cached)."""
        if getattr(self, "_rule", None) is None:
            self._rule = volume_rule(self.elements)
        return self._rule

    @property
    def jump_rest(self) -> float:
        """Penalty weight on the zero-mean part of interface jumps (JUMP_REST; BZ: 1)."""
        return JUMP_REST[self.degree] if self.flux == "ip" else 1.0

    @property
    def iterative(self) -> bool:
        """Whether the system is solved by p-multigrid CG (``solver_kind``; "auto": above
        DIRECT_LIMIT[degree] unknowns, or DIRECT_LIMIT_INCOMPRESSIBLE[degree] when lambda / mu exceeds
        INCOMPRESSIBLE_RATIO)."""
        if self.solver_kind != "auto":
            return self.solver_kind == "iterative"
        limits = DIRECT_LIMIT_INCOMPRESSIBLE if self.lam > INCOMPRESSIBLE_RATIO * self.mu else DIRECT_LIMIT
        return self.size > limits[self.degree]

    def _build(self) -> None:
        """Assemble and set up the solver; double eta until an IP matrix is positive definite."""
        while True:  # _raise_penalty stops after MAX_DOUBLINGS
            t = time.perf_counter()
            groups, self.eta_b = self._groups()
            if self.rotations is not None:
                X0 = warping.reference_state(self.elements, self.basis)
                groups, self.warp_load = warping.rotate(groups, self.rotations, X0)
            A = assembly.to_matrix(groups, self.elements.count)
            del groups
            if self.dt is not None:
                assembly.add_to_diagonal(A, self.material.density * self.basis.h**3 / self.dt**2)
            self.timings["assembly"] = self.timings.get("assembly", 0.0) + time.perf_counter() - t
            t = time.perf_counter()
            # with a mass every body is held; without one a free body's rigid modes are bordered out
            modes = self._mode_matrix() if self.modes and self.dt is None else None
            try:
                if self.iterative:
                    self.matrix = A
                    self.solver = PMultigrid(A, 3 * self.n, degree_chain(self.degree), modes, rtol=self.rtol,
                                             max_iterations=self.max_iterations, coarse_direct=COARSE_DIRECT)
                else:
                    self.matrix = A = A.tocsr()
                    self.solver = DirectSolver(A, modes)
                self.timings["factorisation"] = self.timings.get("factorisation", 0.0) + time.perf_counter() - t
                break
            except NotPositiveDefinite:
                self.timings["factorisation"] = self.timings.get("factorisation", 0.0) + time.perf_counter() - t
                self._raise_penalty()
        if self.eta != self.penalty and not any(w.startswith("the penalty was doubled") for w in self.warnings):
            self.warnings.append(f"the penalty was doubled to {self.eta:g} (from {self.penalty:g}) until the matrix "
                                 "was positive definite")
        self._dirichlet_cache = None

    def _raise_penalty(self) -> None:
        """The next penalties after a matrix that was not positive definite: the volumetric one alone near
        incompressibility (VOLUMETRIC_STEP, up to VOLUMETRIC_AHEAD times the shear one), else both doubled."""
        if self.flux == "bz" and self.patches["count"] == 0:
            raise VoxelasticError("dg: the BZ matrix is not positive definite; the geometry is degenerate")
        if self.eta_volumetric >= self.penalty * 2**MAX_DOUBLINGS:
            raise VoxelasticError(f"dg: the matrix is not positive definite even with penalty {self.eta_volumetric:g}")
        if self.lam > INCOMPRESSIBLE_RATIO * self.mu and self.eta_volumetric < VOLUMETRIC_AHEAD * self.eta:
            self.eta_volumetric *= VOLUMETRIC_STEP
        else:
            self.eta *= 2
            self.eta_volumetric *= 2

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

    def _groups(self) -> tuple[list[assembly.Group], np.ndarray]:
        """All blocks of the operator (element, interface, Nitsche) and the Nitsche penalties [b]."""
        el, basis, mu, lam, eta = self.elements, self.basis, self.mu, self.lam, self.eta
        volumetric = self.eta_volumetric / eta
        E = el.count
        warp = self.material.model == "corotated"
        ip = 1.0 if self.flux == "ip" else 0.0
        every = np.arange(E)
        blocks, pick = self.element_blocks
        groups = [assembly.Group(every, every, blocks, every if warp else None, pick)]

        def faces(weights, owner) -> None:
            b, pick = assembly.face_blocks(el, basis, mu, lam, eta, weights, self.jump_rest, volumetric)
            flat = b.reshape(-1, *b.shape[-2:])  # face f's side pair c at 3 f + c: no strided views
            groups.extend([assembly.Group(el.minus, el.minus, flat, owner, 3 * pick),
                           assembly.Group(el.plus, el.plus, flat, owner, 3 * pick + 1),
                           assembly.Group(el.minus, el.plus, flat, owner, 3 * pick + 2)])

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
                pen, eta_b, self.patch_low = assembly.nitsche_blocks(*args, weights=(1.0, 0.0), volumetric=volumetric)
                groups.append(assembly.Group(owner, owner, pen))
                if ip:
                    cons, _, _ = assembly.nitsche_blocks(*args, weights=(0.0, 1.0), volumetric=volumetric)
                    groups.append(assembly.Group(owner, owner, cons, owner))
            else:
                both, eta_b, self.patch_low = assembly.nitsche_blocks(*args, weights=(1.0, ip), volumetric=volumetric)
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
            state = self._solve_corotated(load_scale, value_scale, inertia, on_iteration, t0)
            state.load_scale = load_scale  # the surface stress carries this share of the loads
        else:
            u, stats = self._linear_solve(load_scale, value_scale, inertia, on_iteration, x0)
            state = State(u, stats, time.perf_counter() - t0, load_scale=load_scale, value_scale=value_scale)
        self.warnings.extend(w for w in state.stats.warnings if w not in self.warnings)
        return state

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
        reference = float(np.linalg.norm(warping.reference_state(self.elements, self.basis)))
        try:
            state = warping.solve_corotated(warped_solve, start, self._gradients, on_iteration, t0, reference)
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
                      on_iteration: Callable[[int, float], None] | None = None, x0: np.ndarray | None = None
                      ) -> tuple[np.ndarray, SolveStats]:
        """Coefficients [E, 3, n] of one solve with the current solver (the iterative one starts from x0
        [E, 3, n] where given: the last step's solution), and its statistics. CG meeting a
        direction of non-positive curvature is the iterative path's sign of a matrix that is not
        positive definite: the penalty doubles as it does on a failed Cholesky."""
        while True:
            try:
                start = None if x0 is None or not self.iterative else np.asarray(x0, dtype=np.float64).reshape(-1)
                x, stats = self.solver.solve(self._rhs(load_scale, value_scale, inertia), start, on_iteration)
                break
            except SolverError as exc:
                if exc.reason != "indefinite" or not self.iterative:
                    raise
                self.release_solver()
                self._raise_penalty()
                self._build()
        return x.reshape(self.elements.count, 3, self.n), stats

    def condition_estimate(self) -> float:
        """2-norm condition number of the factorised matrix (Lanczos on A and on A^-1 through the
        factor, 1e-3 relative accuracy); NaN when rigid modes are bordered out."""
        import scipy.sparse.linalg as spla

        if self.modes and self.dt is None:
            return float("nan")
        n = self.matrix.shape[0]
        top = spla.eigsh(self.matrix, k=1, which="LA", tol=1e-3, return_eigenvectors=False)[0]
        inverse = spla.LinearOperator((n, n), matvec=lambda v: self.solver.apply_inverse(np.asarray(v).ravel()),
                                      dtype=float)
        bottom = 1.0 / spla.eigsh(inverse, k=1, which="LA", tol=1e-3, return_eigenvectors=False)[0]
        return float(top / bottom)









