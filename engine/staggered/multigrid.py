"""Geometric multigrid V-cycle for the staggered operator (a preconditioner for CG).

Coarse levels are rediscretised from averaged cell fractions (Zhu et al. 2010): the energy of a
2h control volume is weighted by the solid fraction of the 2^d fine cells it is made of, so free
surfaces stay implicit on every level. Transfers are the multilinear interpolation of each
component on its own faces (which keeps rigid motions) and its transpose. A coarse DOF is
prescribed when more than a quarter (by interpolation weight) of the fine DOFs it interpolates to
are. Smoothing is a Chebyshev polynomial in D^-1 A (symmetric, so the cycle is a valid CG
preconditioner), with extra steps on a band around cut cells and prescribed DOFs, where the
rediscretised coarse operator departs most from the fine one (the boundary smoothing of Zhu et
al. 2010 and McAdams et al. 2010); the coarsest level is solved directly (sparse Cholesky) with the
rigid modes of floating bodies bordered out.

Near incompressibility (lambda / mu above ROBUST_RATIO) point smoothing cannot reduce the
divergence-free errors the lambda (div u)^2 term leaves nearly unpenalised: the levels are then
smoothed by Chebyshev iteration on M^-1 A with M^-1 = D^-1 + C Theta^-1 C^T, Jacobi on the faces
and on the discrete curls (``curls.py``), and the transfers are the face interpolation
(``kernels.FACE``), which keeps the divergence of every fine cell equal to its coarse cell's. Both
are needed: either alone left the free thick sphere at hundreds of iterations at nu = 0.4999
(docs/design-notes.md). Held surfaces carry lambda's scale too, so on that path the coarse levels'
surface terms are the Galerkin product of the finer level's (``galerkin.py``) and the band around
them is smoothed by exact vertex-patch solves as well (``patches.py``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp

from ..errors import ThinFeatureError
from ..method import Setup, no_progress
from ..grid import axis_pairs
from ..runtime import device_array
from ..solvers.cg import SolverError
from ..solvers.direct import Cholesky, NotPositiveDefinite
from ..solvers.rigid import free_modes
from . import assembly, kernels, smoother_kernels
from .nitsche import make_surface_operator
from .operator import Level, Mechanisms, Part, describe_thin_features, dof_bodies, make_coarse_level, unheld_groups
from .curls import CurlSmoother
from .galerkin import galerkin_surface

COARSEST_DOFS = 1000  # no coarser level below this many unknowns
# A level whose material cells are nearly all cut no longer resolves the part (thin walls, small
# features): its correction is poor, so the hierarchy stops before it. Shares measured: sphere
# 0.53 / 0.70 / 0.89 at boxes 20 / 13 / 9; shell (radii 1 and 0.6) 0.78 / 1.0 at boxes 21 / 13.
# Shell at 128^3: 41 iterations when coarsening to a 9 box, 23 stopping at 21, 18 stopping at 37
# (whose sparse LU, SuperLU then, took 30 s).
MAX_CUT_SHARE = 0.85
DEGREE = 3  # Chebyshev smoothing steps before and after the coarse correction
# The smoother targets the eigenvalues of D^-1 A in [UPPER / SPREAD, UPPER] with UPPER a
# safety margin above the estimated largest one; damped Jacobi (one fixed weight) stalls here
# because the largest eigenvalue (~3.9 in 3D) leaves only a small weight for the rest. SPREAD 6
# was tuned with power iteration's low bound; with Lanczos' 8 keeps the counts (held bodies at nu
# 0.3: docs/design-notes.md, "The point smoothing's bound").
SPREAD = 8.0
MARGIN = 1.1
LANCZOS_STEPS = 12  # CG steps of the smoothing bound's estimate (``_lanczos_largest``)
# Boundary smoothing: BAND_DEGREE more Chebyshev steps on [UPPER / BAND_SPREAD, UPPER], only on
# the free DOFs within one cell of a cut cell or a prescribed DOF. Near the surface the averaged
# coarse fractions misjudge the energy of interpolated errors: on the 64^3 sphere the stationary
# V-cycle's error grows 5.2x per cycle without the band, 1.1x with it (benchmarks/staggered.py
# --growth). Shell to 1e-6: 23 / 61 CG iterations at 128^3 / 256^3 before the band and the
# quarter-share rule below, 14 / 23 with them.
BAND_DEGREE = 5
BAND_SPREAD = 30.0
# A coarse DOF is prescribed when more than this share (by interpolation weight) of the fine DOFs
# it interpolates to are. A free coarse DOF interpolating onto prescribed fine ones makes a jump
# (they are masked) whose energy the coarse operator does not see: error growth per stationary
# V-cycle (64^3 sphere clamped below z = -0.8, no band) 51.5 with a majority, 2520 with 3/4,
# 5.2 with 1/4 or "any"; but "any" grows the clamp by a coarse cell per level, and then CG
# iterations rose (sphere 128^3 clamped below -0.7, degree-5 smoothing with the band: 31 with
# "any", 14 with 1/4, 16 with 1/2).
FIXED_SHARE = 0.25
# Above this lambda / mu the levels are smoothed on the curls too (nu = 0.4: lambda / mu = 4).
ROBUST_RATIO = 4.0
CURL_DEGREE = 8  # Chebyshev steps on M^-1 A (curl smoothing) before and after the coarse correction
# The curl smoothing takes eigenvalues in [upper / CURL_SPREAD, upper]. With the band's patches and
# the Lanczos bound, the held shell (64^3, CG iterations) at spread 30 / 60 / 100: nu 0.45 10 / 14 /
# 19, 0.4999 32 / 25 / 24, 0.49999 42 / 34 / 30; 128^3 at 0.4999 46 -> 32 (30 -> 60); the free thick
# sphere (h = 1/16) 9 / 11 / 12 at 0.4999 (before the patches 30 was best: 71 / 131 at 30 / 100)
CURL_SPREAD = 60.0


class Multigrid:
    """V-cycle preconditioner on ``levels`` (finest first). Call :meth:`update` after the fine
    level's free DOFs or shift change. ``robust``: curl smoothing and face transfers (default:
    when lambda / mu > ROBUST_RATIO). ``max_levels`` 1 makes the cycle the fine level's sparse
    factorisation: an exact solve (small problems, ``StaggeredElasticity.solver``)."""

    def __init__(self, fine: Level, *, max_levels: int = 12, progress: Setup | None = None,
                 robust: bool | None = None) -> None:
        say = progress or no_progress
        # curl smoothing and face transfers (near incompressibility; default by lambda / mu)
        self.robust = fine.lam > ROBUST_RATIO * fine.mu if robust is None else bool(robust)
        self.kind = kernels.FACE if self.robust else kernels.LINEAR
        self.levels = [fine]
        while len(self.levels) < max_levels:
            say(f"multigrid level {len(self.levels) + 1}", 0.4 * len(self.levels) / max_levels)
            last = self.levels[-1]
            if int(last.active.sum()) <= COARSEST_DOFS or max(last.layout.box) <= 5:
                break
            coarse = make_coarse_level(last)
            if cut_share(coarse) > MAX_CUT_SHARE:
                break
            if fine.hold is not None and self.robust:  # lambda-scaled holds: the Galerkin product
                coarse.set_surface(galerkin_surface(last, coarse, self.kind), fine.hold)
            elif fine.hold is not None:  # the displacement boundaries, rediscretised on this level
                # a preconditioner's terms need no per-triangle rule: a scanned mesh's 1.8 M points on
                # every level were most of its setup (engine.clusters)
                quad = fine.hold.quadrature(2 * coarse.spacing, merge=True)
                coarse.set_surface(make_surface_operator(coarse, quad), fine.hold)
            self.levels.append(coarse)
        # coarse tiles around each fine tile's parent (prolongation), fine tiles around each
        # coarse tile's children (restriction)
        self.parents = [device_array(up.layout.parents(lv.layout)) for up, lv in zip(self.levels, self.levels[1:])]
        self.children = [device_array(lv.layout.children(up.layout)) for up, lv in zip(self.levels, self.levels[1:])]
        # per level: the residual (which is also the Chebyshev step), and the rhs / solution it
        # receives from the level above (the finest level's come from the caller)
        # (the curl smoothing keeps its step apart from the residual: one more array per level)
        extra = 1 if self.robust else 0
        self.work = [tuple(lv.zeros() for _ in range((3 if k else 1) + extra)) for k, lv in enumerate(self.levels)]
        # the first job in a process compiles kernels here
        say("multigrid smoothers and coarsest factor" if len(self.levels) > 1 else "sparse factor", 0.5)
        self._held_checked = False  # the thin features' test, made once even when a mass is set from the start
        self.update()

    def update(self) -> None:
        """Propagate the fine level's prescribed DOFs and shift to the coarse levels; refactor.
        Raises ThinFeatureError when the fine stiffness (no shift) has zero-energy motions that
        are not rigid motions: thin features the grid cannot hold (see ``unheld_groups``), also when
        a mass holds them (a dynamic job's first setup): a sample tied to nothing would move alone."""
        fine = self.levels[0]
        if fine.shift == 0.0 or not self._held_checked:
            mech = unheld_groups(fine)
            if mech.count:
                raise ThinFeatureError(describe_thin_features(fine, mech))
            self._held_checked = True
        for k in range(1, len(self.levels)):
            lv, up = self.levels[k], self.levels[k - 1]
            d = lv.dim
            if np.array_equal(up.free, up.active):
                # nothing prescribed above (a job's holds are all on the surface patch: Nitsche), so
                # every share below is 0: the two restrictions and their device copies cost 1.9 s
                # on the 256^3 shell
                free = lv.active
            else:
                # the shares P^T(active & ~free) / P^T(active), with the cycle's own restriction
                # (device arrays, the mask as int8 like the levels' own: another variant of the kernel
                # would be compiled again)
                ones, reach, kept = device_array(np.ones((d, lv.size), np.int8)), lv.zeros(), lv.zeros()
                children = self.children[k - 1]
                kernels.restrict(d, self.kind, lv.coords, children, ones, device_array(up.active, lv.dtype), reach)
                kernels.restrict(d, self.kind, lv.coords, children, ones, device_array(up.free, lv.dtype), kept)
                reach = reach.to_numpy().astype(np.float64)
                share = (reach - kept.to_numpy()) / np.maximum(reach, 1e-300)
                free = lv.active & ~(share > FIXED_SHARE)
            lv.set_free(free)
            if fine.shift != 0.0 or lv.shift != 0.0:
                lv.set_shift(fine.shift, fine.density)
        self.coarse = CoarseSolver(self.levels[-1], "coarsest multigrid level" if len(self.levels) > 1 else "problem")
        if self.robust:
            self.curls = [CurlSmoother(lv) for lv in self.levels[:-1]]
            self.bounds = [_lanczos_largest(lv, _curl_inverse(sm)) * MARGIN for lv, sm in zip(self.levels, self.curls)]
            self.bands = [None] * (len(self.levels) - 1)
        else:
            self.curls = None
            self.bounds = [_lanczos_largest(lv, _jacobi(lv)) * MARGIN for lv in self.levels[:-1]]
            self.bands = [boundary_band(lv) for lv in self.levels[:-1]]

    def precondition(self, r, z) -> None:
        """z = V-cycle(r) with a zero initial guess."""
        self._cycle(0, r, z)

    def _cycle(self, k: int, b, x) -> None:
        lv = self.levels[k]
        if k == len(self.levels) - 1:
            self.coarse.solve(b, x)
            return
        r = self.work[k][0]
        down = self.levels[k + 1]
        self._smooth(k, b, x, first=True)
        lv.residual(x, b, r)
        bc, xc = self.work[k + 1][1:3]
        kernels.restrict(lv.dim, self.kind, down.coords, self.children[k], down.mask, r, bc)
        self._cycle(k + 1, bc, xc)
        kernels.prolong_add(lv.dim, self.kind, lv.coords, self.parents[k], lv.mask, xc, x)
        self._smooth(k, b, x, first=False)

    def _smooth(self, k: int, b, x, first: bool) -> None:
        """Pre-smoothing (``first``: x is zero on entry) is the interior steps then the band's;
        post-smoothing the same in reverse order, so the cycle stays symmetric."""
        if self.robust:
            self._curl_chebyshev(k, b, x, first)
            return
        lv = self.levels[k]
        band = self.bands[k]
        if first:
            self._chebyshev(k, b, x, lv.dinv, None, SPREAD, DEGREE, first=True)
        if band is not None:
            self._chebyshev(k, b, x, lv.dinv, band, BAND_SPREAD, BAND_DEGREE, first=False)
        if not first:
            self._chebyshev(k, b, x, lv.dinv, None, SPREAD, DEGREE, first=False)

    def _chebyshev(self, k: int, b, x, dinv, part, spread: float, degree: int, first: bool) -> None:
        """``degree`` steps of Chebyshev iteration on D^-1 A with eigenvalues taken in
        [upper / spread, upper] (a fixed polynomial); updates only where ``dinv`` is non-zero,
        computing A x only at ``part``'s positions (all when None). ``first``: x is zero on entry."""
        lv = self.levels[k]
        step = self.work[k][0]
        for i, (c1, c2) in enumerate(chebyshev_coefficients(self.bounds[k], spread, degree)):
            if first and i == 0:
                kernels.chebyshev_start(lv.dim, x, step, dinv, b, c2)
            else:
                lv.chebyshev_step(x, b, step, dinv, c1, c2, part)

    def _curl_chebyshev(self, k: int, b, x, first: bool) -> None:
        """CURL_DEGREE steps of Chebyshev iteration on M^-1 A (M^-1: Jacobi on the faces and the
        curls, ``curls.py``), eigenvalues taken in [upper / CURL_SPREAD, upper]; ``first``: x is
        zero on entry. The smoothing is symmetric, so pre- and post-smoothing are the same."""
        lv, smoother = self.levels[k], self.curls[k]
        r, step = self.work[k][0], self.work[k][-1]
        for i, (c1, c2) in enumerate(chebyshev_coefficients(self.bounds[k], CURL_SPREAD, CURL_DEGREE)):
            if first and i == 0:
                smoother.apply(smoother_kernels.START, b, x, step, c1, c2)
            else:
                lv.residual(x, b, r)
                smoother.apply(smoother_kernels.STEP, r, x, step, c1, c2)


def chebyshev_coefficients(upper: float, spread: float, degree: int) -> list[tuple[float, float]]:
    """(c1, c2) of each step ``step = c1 step + c2 M^-1 (b - A x), x += step`` of the Chebyshev
    iteration for the eigenvalues of M^-1 A in [upper / spread, upper] (c1 = 0 in the first)."""
    lower = upper / spread
    theta, delta = 0.5 * (upper + lower), 0.5 * (upper - lower)
    sigma = theta / delta
    rho = 1.0 / sigma
    out = [(0.0, 1.0 / theta)]
    for _ in range(degree - 1):
        rho_next = 1.0 / (2.0 * sigma - rho)
        out.append((rho_next * rho, 2.0 * rho_next / delta))
        rho = rho_next
    return out


def _curl_inverse(smoother: CurlSmoother) -> Callable:
    """z = M^-1 r with M^-1 the curl smoother (the curl path's ``inverse`` for :func:`_lanczos_largest`)."""
    return lambda r, z: smoother.apply(smoother_kernels.APPLY, r, z, z, 0.0, 1.0)


def _jacobi(level: Level) -> Callable:
    """z = D^-1 r on the free DOFs (the point smoothing's ``inverse`` for :func:`_lanczos_largest`)."""
    return lambda r, z: kernels.chebyshev_start(level.dim, z, z, level.dinv, r, 1.0)


def _lanczos_largest(level: Level, inverse: Callable, steps: int = LANCZOS_STEPS) -> float:
    """The largest Ritz value of M^-1 A on the free DOFs (``inverse(r, z)``: z = M^-1 r) after
    ``steps`` steps of preconditioned CG from a random right-hand side (the Lanczos coefficients CG
    yields): the Chebyshev smoothing's upper bound, from below. Power iteration converges too slowly
    where the surface terms or the band's patch solves make the top of the spectrum local: on the
    curl path (64^3 held shell, nu 0.45) its 12 steps gave 12.5 where 200 gave 15.3, and the
    smoothing amplified what lay above (371 CG iterations; 10 with the 200-step bound); on the point
    path (the sphere clamped on its outer surface, nu 0.3, h = 0.05) 53 CG iterations against 13."""
    r, z, p, q = (level.zeros() for _ in range(4))  # setup only: freed on return
    d = level.dim
    kernels.random_fill(d, r, level.mask, 7)
    inverse(r, z)
    kernels.copy(d, z, p)
    rz = kernels.dot(d, r, z)
    alphas, betas = [], []
    for _ in range(steps):
        level.apply(p, q)
        pq = kernels.dot(d, p, q)
        if not (pq > 0.0 and rz > 0.0):
            break
        alpha = rz / pq
        kernels.axpy(d, -alpha, q, r)
        inverse(r, z)
        rz_next = kernels.dot(d, r, z)
        beta = rz_next / rz
        alphas.append(alpha)
        betas.append(beta)
        kernels.xpby(d, z, beta, p)
        rz = rz_next
        if not rz > 0.0:
            break
    if not alphas:
        return 1.0
    a, b = np.asarray(alphas), np.asarray(betas)
    diagonal = 1.0 / a + np.concatenate([[0.0], b[:-1] / a[:-1]])
    off = np.sqrt(b[:-1]) / a[:-1]
    return float(np.linalg.eigvalsh(np.diag(diagonal) + np.diag(off, 1) + np.diag(off, -1))[-1])


def boundary_band(level: Level) -> Part | None:
    """The ``Part`` of the boundary smoothing of ``level``, or None when no free DOF is within one
    cell of a cut cell or a prescribed DOF. The part lists the band's positions, not its tiles: the
    band is a few cells thick, and its tiles (7,386 of 17,050 on the 256^3 shell) made each band
    step cost 75% of a full one. Every free DOF at a listed position is in the band, so the band's
    smoothing reads the level's own D^-1 there (a D^-1 of its own, zero off the band, cost a full
    vector per level: 10 bytes per unknown on the 256^3 shell)."""
    d, lay = level.dim, level.layout
    vc = level.vc_host
    seeds = lay.dense((((vc > 0) & (vc < 1)) | (level.active & ~level.free).any(axis=0)).astype(np.uint8))
    # the 3^d block around each index: one running maximum per axis (a 3^d stencil per position
    # cost seconds at 256^3)
    for a in range(d):
        seeds = ndi.maximum_filter1d(seeds, 3, axis=a, mode="constant")
    members = (level.free & (lay.flat(seeds) > 0)[None]).any(axis=0)
    if not members.any():
        return None
    return level.part(np.nonzero(members)[0])


def cut_share(level: Level) -> float:
    """Share of the level's material cells that are cut (0 < fraction < 1)."""
    vc = level.vc_host
    solid = np.count_nonzero(vc > 0)
    return np.count_nonzero((vc > 0) & (vc < 1)) / solid if solid else 1.0


class CoarseSolver:
    """Sparse Cholesky (``engine.solvers.direct``) of a level's operator on its free DOFs: the
    coarsest level of a V-cycle, or the fine level itself when the whole problem is solved
    directly (a one-level hierarchy). Bodies whose rigid modes the level's Dirichlet DOFs leave
    free (and no mass term) are bordered with those modes, and so are the zero-energy motions of
    thin features the averaged coarse fractions make (``unheld_groups``; the fine level has none,
    or the setup stopped): the bordered system is regular and returns the solution orthogonal to
    them, which the finer levels' smoothing, or CG's projection, corrects. ``name`` says which
    operator it is in errors."""

    def __init__(self, level: Level, name: str = "coarsest multigrid level") -> None:
        self.level = level
        lay = level.layout
        d = lay.dim
        cells = tuple(n - 1 for n in lay.box)
        idx = lay.indices()
        pos = np.nonzero(np.all(idx < np.asarray(lay.box), axis=1))[0]
        idx = idx[pos]
        comp = np.repeat(np.arange(d), len(idx))
        flat_pos = np.tile(pos, d)
        free = level.free[comp, flat_pos]
        self.comp, self.pos = comp[free], flat_pos[free]
        gid = assembly.dof_index(comp, np.tile(idx, (d, 1)), cells)
        cell = lay.dense(level.vc_host)
        edges = {p: lay.dense(level.ve_host[q]) for q, p in enumerate(axis_pairs(d))}
        K = assembly.stiffness(cell, edges, level.spacing, level.lam, level.mu).tocsr()
        order = gid[free]
        A = K[order][:, order]
        if level.shift != 0.0 and level.mass is not None:
            A = A + sp.diags(level.shift * level.mass.to_numpy()[self.comp, self.pos])
        held = None
        if level.surface is not None:
            S = _on_free(level.surface, level.surface.matrix(), self.comp, self.pos, level.size)
            A = A + S
            held = _on_free(level.surface, level.surface.hold_mass, self.comp, self.pos, level.size)
        n = A.shape[0]
        self.n = n
        self.mechanisms = 0
        border = None
        if level.shift == 0.0:
            border = self._floating_modes(level, comp, flat_pos, idx, free, held)
            mech = unheld_groups(level)
            if mech.count:
                self.mechanisms = mech.count
                border = _with_mechanisms(border, mech, self.comp, self.pos, level.size)
        bordered = border is not None and border.shape[1] > 0
        if bordered:
            k = border.shape[1]
            zero = sp.csr_matrix((np.zeros(k), (np.arange(k), np.arange(k))), shape=(k, k))  # PARDISO needs the diagonal
            A = sp.bmat([[A, sp.csr_matrix(border)], [sp.csr_matrix(border.T), zero]], format="csr")
        self.factor = None
        if A.shape[0]:
            # sparse Cholesky (PARDISO): SuperLU's LU took 0.73 s on the 8,856 unknowns of a ball
            # at 16 cells across and 9.2 s on 26,964 (PARDISO 0.07 / 0.31 s; docs/benchmarks.md)
            try:
                self.factor = Cholesky(A.tocsr(), definite=not bordered)
                negatives = self.factor.negatives - (border.shape[1] if bordered else 0)
                if negatives > 0:
                    raise NotPositiveDefinite(f"{negatives} negative pivot(s) beyond the bordered modes")
            except (NotPositiveDefinite, RuntimeError) as exc:
                raise SolverError(
                    f"solver: the operator of the {name} ({n} unknowns at spacing "
                    f"{level.spacing:.4g} m) is singular beyond its rigid modes and {self.mechanisms} thin-feature "
                    f"motion(s) ({exc}): some displacement samples are held by nothing; refine the grid around thin "
                    "walls or rods, or use method.kind 'dg'",
                    "singular",
                ) from None

    @staticmethod
    def _floating_modes(level: Level, comp, flat_pos, idx, free, held) -> np.ndarray:
        lay = level.layout
        d = lay.dim
        active = level.active[comp, flat_pos]
        points = (np.tile(idx, (d, 1)) + 0.5 - 0.5 * np.eye(d, dtype=int)[comp]) * level.spacing
        body = dof_bodies(level, comp, flat_pos)
        on = active & (body > 0)
        if held is not None:  # the penalty over the free DOFs -> over the DOFs "on"
            number = -np.ones(len(comp), dtype=np.int64)
            number[on] = np.arange(int(on.sum()))
            number = number[np.nonzero(free)[0]]
            m = held.tocoo()
            keep = (number[m.row] >= 0) & (number[m.col] >= 0)
            held = sp.csr_matrix((m.data[keep], (number[m.row[keep]], number[m.col[keep]])), shape=(int(on.sum()),) * 2)
        modes = free_modes(points[on], comp[on], ~free[on], body[on], held=held)
        free_index = -np.ones(len(comp), dtype=np.int64)
        free_index[free] = np.arange(int(free.sum()))
        on_index = np.nonzero(on)[0]
        cols = []
        for dofs, q in modes:
            col = np.zeros((int(free.sum()), q.shape[1]))
            col[free_index[on_index[dofs]]] = q
            cols.append(col)
        return np.concatenate(cols, axis=1) if cols else np.zeros((int(free.sum()), 0))

    def solve(self, b, x) -> None:
        lv = self.level
        out = np.zeros((lv.dim, lv.size))
        if self.factor is not None:
            rhs = np.zeros(self.factor.n)
            rhs[: self.n] = b.to_numpy()[self.comp, self.pos]
            out[self.comp, self.pos] = self.factor.solve(rhs)[: self.n]
        x.from_numpy(out.astype(lv.dtype, copy=False))


def _with_mechanisms(border: np.ndarray, mech: Mechanisms, comp: np.ndarray, pos: np.ndarray, size: int) -> np.ndarray:
    """``border`` [n, k] (rigid modes on the free DOFs (comp [n], pos [n])) with the motions of
    ``mech`` appended as orthonormal columns; rigid columns that the motions span are dropped (a
    floating thin feature's translation is one of its motions), the rest re-orthonormalised."""
    n = len(comp)
    order = np.argsort(comp * size + pos)
    keys = (comp * size + pos)[order]
    at = order[np.searchsorted(keys, mech.comp * size + mech.pos)]  # free DOF number of each moving sample
    sizes = np.bincount(mech.group, minlength=mech.count)
    motions = np.zeros((n, mech.count))
    motions[at, mech.group] = mech.sign / np.sqrt(sizes[mech.group])
    if border is None or not border.shape[1]:
        return motions
    rest = border - motions @ (motions.T @ border)
    # an orthonormal basis of what the motions leave of the (orthonormal) rigid columns
    u, s, _ = np.linalg.svd(rest, full_matrices=False)
    return np.concatenate([motions, u[:, s > 1e-8]], axis=1)


def _on_free(surface, matrix: sp.spmatrix, comp: np.ndarray, pos: np.ndarray, size: int) -> sp.csr_matrix:
    """A surface-operator ``matrix`` [n, n] (over ``surface``'s DOFs) on the free DOFs (comp [N],
    pos [N]) of a level [N, N] (entries at DOFs that are not free dropped)."""
    keys = comp.astype(np.int64) * size + pos
    order = np.argsort(keys)
    mine = surface.comp.astype(np.int64) * size + surface.pos
    k = np.minimum(np.searchsorted(keys[order], mine), len(keys) - 1)
    found = keys[order][k] == mine
    at = order[k]
    m = matrix.tocoo()
    keep = found[m.row] & found[m.col]
    return sp.csr_matrix((m.data[keep], (at[m.row[keep]], at[m.col[keep]])), shape=(len(keys), len(keys)))
