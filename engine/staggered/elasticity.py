"""The staggered-grid method as a whole: fractions + material + boundary conditions -> solves -> fields.

``StaggeredElasticity`` sequences the pieces: the fine ``Level`` (tiles touching material, exact
fractions), the displacement boundaries held on their surface patches (Nitsche terms on every
level, ``nitsche.py``), the consistent load vector (body force
weighted by face fractions, surface tractions by quadrature on the mesh triangles; on a body that
no displacement boundary holds, with the surface loads' exact net moment, so that loads balanced on
the surface stay balanced), rigid-mode checks for bodies the holds leave free, the
multigrid-preconditioned CG solve (small grids: the fine level factorised, ``solves_directly``)
and the fields at cell centres, probes and surface vertices.
``engine.analysis`` drives it in time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import InitVar, dataclass, field

import numpy as np
import scipy.sparse as sp

from ..boundary import (Prescribed, SurfaceLoad, area_vectors, check_holds, evaluate, exclusive_holds,
                        patch_quadrature, select_patch, surface_quadrature, tractions)
from ..errors import BoundaryError, VoxelasticError
from ..geometry.fractions import VolumeFractions
from ..geometry.surface import Surface, thickness
from ..grid import axis_pairs
from ..material import Material
from ..method import Setup, State, no_progress
from ..runtime import device_array
from ..solvers.cg import PCG, SolverError, pcg
from ..solvers.rigid import check_balance, free_modes
from . import kernels, sampling
from .fields import StaggeredFields
from .joined import JOINED, close_bodies_warning, joined_bodies_warning
from .layers import partial_layer_warning
from .multigrid import Multigrid
from . import flat_layers, held
from .nitsche import hold_patches, with_bulk
from .operator import Level, dof_bodies, make_fine_level
from .problem import solves_directly
from .shares import patch_shares

PointFunction = Callable[[np.ndarray], np.ndarray]


# Rows of a divergence-form load evaluated at once (its [rows, d, d] stress samples: ~19 MB each in 3D).
CHUNK = 1 << 18
# DOFs whose sample points are made at once (``sample_points``; ~25 MB of temporaries in 3D)
POINT_ROWS = 1 << 20


# Twice a solid's volume over its surface is a plate's thickness and half a square bar's width;
# below this many cells the staggered displacements can be off by 5-30%: the bundled cantilever
# (0.2 m square) at resolution 12 / 16 / 24 / 32 / 48, 1.1 / 1.45 / 2.2 / 2.9 / 4.4 cells by this
# measure, tip 30 / 24 / 4 / 7 / 3% under DG k = 2's, mostly the partial layers' bending stiffness
# (docs/design-notes.md, "Cut cells weighed at their solid's centroid")
THIN_CELLS = 1.5
# a divergence-form load whose net force is off the patch's resultant by more than this share of
# its |traction| integral gets the difference as a uniform traction (``_divergence_gap``)
GAP_TOLERANCE = 1e-9


def thin_solid_warning(surface, h: float) -> list[str]:
    """A warning when the solid bounded by the closed ``surface`` is thin for cells of ``h`` [m]."""
    if not surface.closed:
        return []
    cells = thickness(surface) / h
    if cells >= THIN_CELLS:
        return []
    return [f"the solid is thin for this grid: twice its volume over its surface area (a plate's thickness, half a "
            f"square bar's width) is {cells:.2g} cells of h = {h:.4g} m; below {THIN_CELLS:g} the staggered "
            "method's displacements can be off by 5-30%: refine the grid (grid.resolution, grid.cell_size) or use "
            "method.kind 'dg' with method.degree 2"]


def _joined_cause(exc: SolverError, joined: list[str]) -> SolverError:
    """``exc`` with the joined-bodies warning as its likely cause (``exc`` itself when there is none):
    bodies joined through single cells or edges are held by almost nothing there."""
    if not joined:
        return exc
    said = str(exc).split("; the tolerance may")[0]  # not the tolerance's fault here
    return SolverError(f"{said}; here {joined[0].split(':')[0]}, which joins them through single cells or edges that "
                       "hold almost nothing: refine the grid until each gap spans more than a cell, or use method.kind "
                       "'dg'", exc.reason)


@dataclass
class StaggeredElasticity(StaggeredFields):
    """The method on one geometry: built once (level, prescribed DOFs, loads, rigid-mode checks,
    multigrid), then solved as often as an analysis needs (``solve``; ``set_time_step`` for
    backward Euler) and turned into fields (``fields``). Units SI; ``rtol``, ``max_iterations``
    from solver settings; ``warnings`` collects what the user should know about the setup."""

    fractions: InitVar[VolumeFractions]  # read while the fine level is built, not kept
    surface: Surface
    material: Material
    prescribed: list[Prescribed] = field(default_factory=list)
    surface_loads: list[SurfaceLoad] = field(default_factory=list)
    body_force: np.ndarray | PointFunction | None = None  # [d] or callable, [N/m^3]
    rtol: float = 1e-8
    max_iterations: int = 5000
    warnings: list[str] = field(default_factory=list)
    progress: Setup | None = field(default=None, repr=False)  # hears of the setup's parts
    dynamic: bool = True  # False: no backward-Euler steps will come, so no mass is ever needed
    # a dynamic job's backward-Euler step [s]: the multigrid is built for it at once (set_time_step
    # would build its smoothers and coarsest factor a second time), and since every solve carries the
    # mass, which holds a body no boundary holds, such a body's loads need not balance (it accelerates)
    time_step: float | None = None
    # "direct": the whole problem factorised (sparse Cholesky), "iterative": multigrid-preconditioned
    # CG, "auto": direct on small grids (``problem.solves_directly``)
    solver: str = "auto"

    def __post_init__(self, fractions: VolumeFractions) -> None:
        if self.solver not in ("auto", "direct", "iterative"):
            raise VoxelasticError(f"method.solver: 'auto', 'direct' or 'iterative', got {self.solver!r}")
        say = self.progress or no_progress
        say("surface quadrature", 0.0)
        grid = fractions.grid
        self.grid, self.dim = grid, grid.dim
        lam, mu = self.material.lame
        self.patches = hold_patches(exclusive_holds(self.prescribed, self.surface), self.surface)
        # pieces up to h across (surface_quadrature halves its spacing): the surface loads' h / 2 made
        # 466k points on the bundled cantilever's clamp at resolution 128 (its thin strips split 4^6-fold)
        self.hold = self.patches.quadrature(2 * grid.spacing) if self.patches is not None else None
        self._load_points = {}
        for load in self.surface_loads:
            if load.form != "divergence":
                # one point per facet and box of the lattice: the spread times a facet's traction is
                # linear there (the degree-5 rule's 7 points on the cut pieces were 2.8x those of the
                # subdivided pieces: 104 M on a whole sphere at h = 1/128, 62 s; one point per cut
                # triangle 5.9 M on 3/4 of a sphere at h = 1/96, where a box's share is 0.8 M)
                x, w, n = patch_quadrature(self.surface, load.region, grid.spacing, name=load.name,
                                           lattice=np.asarray(grid.origin, dtype=float), centroids=True)
                t = tractions(x, n, name=load.name, traction=load.traction, pressure=load.pressure, stress=load.stress)
                self._load_points[id(load)] = (x, w, t, n)
        # Ghost samples (engine/staggered/ghosts.py) beyond the surface where loads act, and where holds
        # act in 2D only: the annulus held on its circles needs them to converge; in 3D they changed no
        # error on the clamped sphere but cost multigrid its convergence (docs/design-notes.md,
        # "Boundaries on the surface patch")
        acting = [(x, n) for x, _, _, n in self._load_points.values()]
        if self.hold is not None and self.dim == 2:
            acting.append((self.hold.points, self.hold.normals))
        ghosts = None
        if acting:
            points, normals = (np.concatenate(v) for v in zip(*acting))
            ghosts = sampling.stencil_samples(grid, points, normals)
        say("operator", 0.1)
        self.level = level = make_fine_level(fractions, lam, mu, ghosts=ghosts)
        lay = level.layout
        # (a, position) of every active DOF, in the smallest integer types that hold them (int64
        # spent 16 bytes per unknown on the pair); grid indices come from the layout when asked for
        comp, pos = np.nonzero(level.active[:, :lay.count * lay.tile_size])
        self.dof_comp, self.dof_pos = comp.astype(np.int8), pos.astype(np.int32)
        del comp, pos
        points = self.sample_points()
        # displacement boundaries act on their surface patches, weakly (Nitsche): every active DOF is free
        say("boundaries", 0.3)
        self.surface_terms = held.surface_operator(level, self.hold, self.patches) if self.hold is not None else None
        self._flat = flat_layers.moved_weights(level, self._acted_cells())
        bulk = flat_layers.correction(level, self._flat)
        if bulk is not None:
            self.surface_terms = with_bulk(self.surface_terms, bulk, level.size)
        level.set_surface(self.surface_terms, self.patches)
        self.warnings += check_holds(self.prescribed, self.surface)
        self.warnings += held.locking_warning(self.patches, self.hold, self.surface_terms, lam, mu)
        self.warnings += thin_solid_warning(self.surface, grid.spacing)
        self.warnings += partial_layer_warning(level, np.unique(np.concatenate([p for p, _ in self._flat])))
        joined = joined_bodies_warning(self.surface, level, grid)
        self.warnings += joined + close_bodies_warning(level)
        self.dof_body = dof_bodies(level, self.dof_comp, self.dof_pos)  # [DOFs] body label (1, 2, ...)
        self.modes = self._floating_modes(points)
        self.loads = self._load_vector(points)
        if self.modes and self.time_step is None:
            check_balance(points, self.dof_comp, self.loads[self.dof_comp, self.dof_pos],
                          [(dofs, q) for dofs, q, _ in self.modes])
            free = sum(q.shape[1] for _, q, _ in self.modes)
            self.warnings.append(
                f"{free} rigid-body mode(s) are not held by any displacement boundary; the loads balance, so the "
                "solution is the one with no rigid motion (orthogonal to those modes)"
            )
        del points  # setup only (24 bytes per unknown: 0.46 GiB at 256^3), gone before the multigrid's arrays
        self.dof_body = None  # setup only (the loads' moment couples and the modes), 4 bytes per unknown
        # no warning for the control volumes raised to MIN_FRACTION (level.slivers): it bounds the
        # conditioning, adds at most that share of a cell's energy and asks nothing of the user
        # a one-level hierarchy is the fine level's factorisation: CG then stops after one step
        if self.time_step is not None:
            level.set_shift(1.0 / self.time_step**2, self.material.density)
        try:
            self.multigrid = Multigrid(level, max_levels=1 if solves_directly(grid, self.solver) else 12,
                                       progress=lambda part, share: say(part, 0.5 + 0.5 * share))
        except SolverError as e:
            # bodies joined through a cell or an edge hold each other by a hinge (a core in a cavity
            # 2.4 cells wide, touching its wall by one edge's shear term)
            raise (_joined_cause(e, joined) if e.reason == "singular" else e) from None
        self.space = _Space(level)
        if not self.dynamic:
            # the face fractions weigh the mass and the rigid modes' projection only: a static or
            # quasi-static run keeps them for a free body alone (10 bytes per unknown on the fine level)
            for lv in self.multigrid.levels[0 if not self.modes else 1:]:
                lv.vf_host = None

    # ------------------------------------------------------------------ setup
    def sample_points(self) -> np.ndarray:
        """Sample point [DOFs, d] [m] of every active DOF (``dof_comp``, ``dof_pos``): origin + h (I +
        1/2 - e_a / 2), made in place (temporaries of [DOFs, d] cost seconds at 20 M DOFs)."""
        n, d = len(self.dof_pos), self.dim
        points = np.empty((n, d))
        # the DOFs are numbered in (component, position) order: component a's are one run of rows
        # (a fancy index over all 20 M DOFs of the 256^3 shell took 0.2-0.9 s, this 0.04-0.1 s)
        ends = np.searchsorted(self.dof_comp, np.arange(d + 1))
        origin = np.asarray(self.grid.origin, dtype=np.float64)
        # a block of rows at a time: the grid indices and their temporaries stay small (over all
        # rows at once they were [DOFs, d] arrays of fresh memory, 0.7-1.1 s on the 256^3 shell)
        for start in range(0, n, POINT_ROWS):
            block = points[start:start + POINT_ROWS]
            block[:] = self.level.layout.index_of(self.dof_pos[start:start + POINT_ROWS])
            block += 0.5
            for a in range(d):
                block[max(ends[a] - start, 0):max(ends[a + 1] - start, 0), a] -= 0.5
            block *= self.grid.spacing
            block += origin
        return points

    def _load_vector(self, points: np.ndarray) -> np.ndarray:
        """Consistent nodal forces [d, size] [N] of body force and surface loads (not scaled)."""
        level, grid, d = self.level, self.grid, self.dim
        f = np.zeros((d, level.size))
        if self.body_force is not None:
            pts, a, p = points, self.dof_comp, self.dof_pos
            if callable(self.body_force):
                b = evaluate(self.body_force, pts, (d,), "loads: the body force")[np.arange(len(pts)), a]
                f[a, p] += grid.spacing**d * level.vf_host[a, p] * b
            else:
                # a constant force: whole rows at once (face fractions vanish off the active DOFs)
                g = np.asarray(self.body_force, dtype=float)
                for k in range(d):
                    f[k] += (grid.spacing**d * g[k]) * (level.vf_host[k] * level.active[k])
        # each body's surface loads keep their net torque (sampling: a held bar pulled off its axis
        # bends; a body held by nothing must be loaded in balance), all its loads with one couple; the
        # labels cost 4 bytes per sample, so only jobs with such loads make them
        pieces = []
        for load in self.surface_loads:
            if load.form == "divergence":
                before = f.sum(axis=1)
                self._divergence_load(load, f)
                gap = self._divergence_gap(load, f.sum(axis=1) - before)
                if gap is None:
                    continue
                pts, w, t, normals = gap
            else:
                pts, w, t, normals = self._load_points[id(load)]
            pieces.append((pts, w, t, normals, load.name))
        if pieces:
            spread = sampling.point_loads(grid, pieces, self._active_lookup, self._body_lookup())
            for a, (index, force) in enumerate(spread):
                np.add.at(f[a], self.level.layout.positions(index), force)
        f += flat_layers.end_loads(level, self._flat, list(self._load_points.values()))
        if not np.all(np.isfinite(f)):
            raise BoundaryError("loads: the load vector is not finite (check loads.gravity and the traction values)")
        return f

    def _acted_cells(self) -> list[np.ndarray]:
        """Per axis a: layout positions of the cells holding surface normal to a that a load or a hold
        acts on."""
        parts = [(x, n) for x, _, _, n in self._load_points.values()]
        if self.hold is not None:
            parts.append((self.hold.points, self.hold.normals))
        for load in self.surface_loads:
            if load.form == "divergence":
                x, _, n = patch_quadrature(self.surface, load.region, self.grid.spacing, name=load.name)
                parts.append((x, n))
        if not parts:
            return [np.zeros(0, dtype=np.int64)] * self.dim
        x, n = (np.concatenate(v) for v in zip(*parts))
        return [flat_layers.face_cells(self.level, x, n, a) for a in range(self.dim)]

    def _divergence_gap(self, load: SurfaceLoad, net: np.ndarray):
        """What the divergence form of ``load`` (its net force ``net`` [d] [N]) misses of the patch's
        resultant, as a uniform traction on the patch: (points [Q, d], weights [Q], traction [Q, d],
        normals [Q, d]), or None when it misses nothing. The form reads the stress through whole
        rows, so a row that sees the patch and a free surface at once (a body one or two cells thick)
        lost part of its force: 640 of a pressure's 800 N on a plate 1.6 cells thick, a sphere's cap
        3.8% short at 6 cells across. A closed patch's resultant is zero in both and gets nothing."""
        d, h = self.dim, self.grid.spacing
        pieces, _ = select_patch(load.region, self.surface.vertices[self.surface.faces], load.name)
        pieces = pieces.reshape(-1, d, d)
        if load.pressure is not None:  # -p sum(area n) over the patch: exact without a quadrature
            vectors = area_vectors(pieces)
            exact = -float(load.pressure) * vectors.sum(axis=0)
            scale = abs(load.pressure) * np.linalg.norm(vectors, axis=1).sum()
        else:
            x, w, n = surface_quadrature(pieces, h)
            t = tractions(x, n, name=load.name, stress=load.stress)
            exact, scale = (w[:, None] * t).sum(axis=0), (w * np.linalg.norm(t, axis=1)).sum()
        if np.linalg.norm(exact - net) <= GAP_TOLERANCE * scale:
            return None
        # the gap is a uniform traction: one point per facet and lattice box spreads it with the
        # same measure and first moments as the degree-5 rule on every cut piece
        x, w, n = surface_quadrature(pieces, h, centroids=True, lattice=np.asarray(self.grid.origin, dtype=float))
        if w.sum() <= 0:
            return None
        return x, w, np.broadcast_to((exact - net) / w.sum(), (len(w), d)), n

    def _divergence_load(self, load: SurfaceLoad, f: np.ndarray) -> None:
        """Add to ``f`` [d, size] the work of sigma n on the surface written as a volume integral
        (thesis eq. 4.16): int_Omega sigma : grad u + div(sigma) . u, discretised with the
        operator's own weights and the staggered divergence. It equals the operator's residual of a
        constant stress exactly, so the discrete traction and the discrete energy agree cell by
        cell. A row's terms see all the surface crossing its control volumes, so each row's force is
        scaled by its share of ``load``'s patch (``shares.py``): 1 where the row sees the patch
        alone, 0 off it. Of the rows that see the patch only those where a fraction their terms weigh
        is below 1 get it (elsewhere the terms cancel): the stress field is evaluated there alone,
        CHUNK rows at a time: over the whole index box, the ball's stress field at h = 1/128 came as
        several [17 M, 3, 3] arrays at once."""
        level, grid, d, h = self.level, self.grid, self.dim, self.grid.spacing
        if load.pressure is not None:
            stress_field = lambda x: np.broadcast_to(-float(load.pressure) * np.eye(d), (len(x), d, d))  # noqa: E731
        elif load.stress is not None:  # a callable, or a constant [d, d] (broadcast by ``evaluate``)
            given = load.stress if callable(load.stress) else (lambda x, s=np.asarray(load.stress, dtype=float): s)
            stress_field = lambda x: evaluate(given, x, (d, d), f"{load.name}: the stress")  # noqa: E731
        else:
            raise BoundaryError(f"{load.name}: the divergence form needs a pressure or a stress field (a callable)")
        lay = level.layout
        box = np.asarray(lay.box)
        origin = np.asarray(grid.origin, dtype=float)
        eye = np.eye(d, dtype=np.int64)
        shares = patch_shares(self.surface, load, grid, lay)

        def at(values: np.ndarray, index: np.ndarray) -> np.ndarray:
            """values [size] at grid indices [N, d]; 0 outside the kept tiles."""
            pos = lay.positions(index)
            return np.where(pos >= 0, values[np.maximum(pos, 0)], 0.0)

        def stress(index: np.ndarray, offset: np.ndarray, i: int, j: int) -> np.ndarray:
            """sigma_ij [N] at the samples of offset kind ``offset`` at ``index`` [N, d]; 0 outside the box."""
            inside = np.all((index >= 0) & (index < box), axis=1)
            x = origin + h * (index + 0.5 - 0.5 * offset)
            return np.where(inside, np.asarray(stress_field(x), dtype=float)[:, i, j], 0.0)

        cell = np.zeros(d, dtype=np.int64)
        for a in range(d):
            sides = [(q, pair[1] if pair[0] == a else pair[0]) for q, pair in enumerate(axis_pairs(d)) if a in pair]
            pos, share = shares[a]
            on = level.active[a, pos]
            pos, share = pos[on], share[on]
            index = lay.index_of(pos).astype(np.int64)
            # row (a, I) weighs vc(I), vc(I - e_a), vf_a(I) and, per pair (a, j), ve(I), ve(I + e_j)
            weights = [level.vc_host[pos], at(level.vc_host, index - eye[a]), level.vf_host[a, pos]]
            for q, j in sides:
                weights += [level.ve_host[q, pos], at(level.ve_host[q], index + eye[j])]
            cut = np.zeros(len(pos), dtype=bool)
            for w in weights:
                cut |= w != 1.0
            pos, index, share, weights = pos[cut], index[cut], share[cut], [w[cut] for w in weights]
            for start in range(0, len(pos), CHUNK):
                rows = slice(start, start + CHUNK)
                here, vc, vc_dn, vf = index[rows], weights[0][rows], weights[1][rows], weights[2][rows]
                s_here, s_dn = stress(here, cell, a, a), stress(here - eye[a], cell, a, a)
                value = vc_dn * s_dn - vc * s_here - vf * (s_dn - s_here)
                for k, (_, j) in enumerate(sides):
                    ve, ve_up = weights[3 + 2 * k][rows], weights[4 + 2 * k][rows]
                    edge = eye[a] + eye[j]
                    s_ab, s_up = stress(here, edge, a, j), stress(here + eye[j], edge, a, j)
                    value += ve * s_ab - ve_up * s_up - vf * (s_ab - s_up)
                f[a, pos[rows]] += h ** (d - 1) * share[rows] * value
        f += flat_layers.load(level, self._flat, stress_field, lambda a, p: _share_at(shares[a], p))

    def _active_lookup(self, a: int, index: np.ndarray) -> np.ndarray:
        pos = self.level.layout.positions(index)
        return (pos >= 0) & self.level.active[a, np.maximum(pos, 0)]

    def _body_lookup(self) -> Callable[[int, np.ndarray], np.ndarray]:
        """lookup(a, index [M, d]) -> int [M]: the body label (1, 2, ...) of samples, 0 where no
        unknown is."""
        labels = np.zeros((self.dim, self.level.size), dtype=np.int32)
        labels[self.dof_comp, self.dof_pos] = self.dof_body
        layout = self.level.layout

        def lookup(a: int, index: np.ndarray) -> np.ndarray:
            pos = layout.positions(index)
            return np.where(pos >= 0, labels[a, np.maximum(pos, 0)], 0)

        return lookup

    def _floating_modes(self, points: np.ndarray) -> list:
        """Rigid modes of each body not held by prescribed DOFs: (DOF numbers, basis over them, flat
        positions a * size + p of those DOFs)."""
        body = self.dof_body
        fixed = np.zeros(len(body), dtype=bool)
        held = None
        if self.surface_terms is not None:
            at = self._surface_dofs()
            m = self.surface_terms.hold_mass.tocoo()
            held = sp.csr_matrix((m.data, (at[m.row], at[m.col])), shape=(len(body),) * 2)
        out = []
        for dofs, q in free_modes(points, self.dof_comp, fixed, body, held=held):
            flat = self.dof_comp[dofs].astype(np.int64) * self.level.size + self.dof_pos[dofs]
            out.append((dofs, q, flat))
        return out

    def _surface_dofs(self) -> np.ndarray:
        """DOF numbers (into dof_comp / dof_pos) of the surface terms' DOFs, in their order."""
        keys = self.dof_comp.astype(np.int64) * self.level.size + self.dof_pos
        mine = self.surface_terms.comp.astype(np.int64) * self.level.size + self.surface_terms.pos
        return np.searchsorted(keys, mine)  # the DOFs are numbered in (component, position) order

    # ------------------------------------------------------------------ solve
    def set_time_step(self, dt: float | None) -> None:
        """Backward Euler with step dt [s] adds M / dt^2 to the operator; None goes back to statics."""
        shift = 0.0 if dt is None else 1.0 / dt**2
        if shift == self.level.shift:  # the step it was built for (``time_step``)
            return
        self.level.set_shift(shift, self.material.density)
        self.multigrid.update()

    def solve(self, load_scale: float = 1.0, value_scale: float = 1.0, x0: np.ndarray | None = None,
              inertia: np.ndarray | None = None, on_iteration: Callable[[int, float], None] | None = None) -> State:
        """u minimising the energy with loads and prescribed values scaled; ``inertia``: the
        predicted displacement u^k + dt v^k [d, size] of a backward-Euler step (after set_time_step)."""
        t0 = time.perf_counter()
        level = self.level
        # one host vector, updated in place and dropped before CG allocates its own (209 MB at 256^3)
        rhs = load_scale * self.loads
        if value_scale != 0.0 and self.surface_terms is not None:
            st = self.surface_terms  # the prescribed values' load lives on the surface DOFs only
            np.add.at(rhs, (st.comp, st.pos), value_scale * st.rhs)
        if inertia is not None:
            rhs += level.shift * level.mass.to_numpy() * inertia
        rhs *= level.free
        if self._removes_rigid_motion():
            rhs = self._project(rhs)
        b = device_array(rhs)
        del rhs

        def start():
            return device_array(x0 * level.free if x0 is not None else np.zeros(level.free.shape))

        x = start()
        try:
            try:
                _, stats = self._cg(self.multigrid.precondition).solve(b, x, on_iteration)
            except SolverError as exc:
                if exc.reason in ("cap", "precision"):
                    # the cap is the user's setting and the precision the storage's: Jacobi would
                    # only need more iterations to reach the same limit (at 256^3 in f32: 200 more)
                    raise
                # the V-cycle failed (lost definiteness, stagnated): plain Jacobi-PCG is slower but robust
                x = start()
                _, stats = self._cg(self._jacobi).solve(b, x, on_iteration)
                # said only once it is true: a fallback that fails too raises its own error below
                self.warnings.append(f"multigrid-preconditioned CG failed ({exc}); solved with Jacobi-preconditioned CG")
        except SolverError as exc:
            # bodies joined through a point or an edge of the grid are nearly free: the solve stalls
            # (two bodies touching at a point: "stagnated at relative residual 1.53") for no fault of the tolerance
            joined = [w for w in self.warnings if JOINED in w]
            if exc.reason == "precision" and self.modes and level.shift != 0.0:
                # K u of a body moving rigidly by far more than it deforms rounds off at (c dt / h)^2 of
                # eps relative to the loads, c the pressure wave's speed
                raise SolverError(f"{exc}; here a body the displacement boundaries leave free to move rigidly moves "
                                  "by far more than it deforms in one time step, and that motion's rounding sets the "
                                  "floor: a smaller analysis.time_step lowers it with its square", exc.reason) from None
            raise (_joined_cause(exc, joined) if exc.reason != "cap" else exc) from None
        # a true residual the restarts left above rtol (within the solver's slack) goes in the report
        self.warnings.extend(w for w in stats.warnings if w not in self.warnings)
        u = x.to_numpy().astype(np.float64, copy=False)
        if self._removes_rigid_motion():
            u = self._without_rigid_motion(self._project(u))
        u = u * level.free
        return State(u, stats, time.perf_counter() - t0, load_scale=load_scale, value_scale=value_scale)

    def _cg(self, inner: Callable) -> PCG:
        """CG on the operator, preconditioned by ``inner`` (then off the free rigid modes)."""
        return PCG(self.space, self.level.apply, self._preconditioner(inner), rtol=self.rtol,
                   max_iterations=self.max_iterations, iterate=pcg)

    def _jacobi(self, r, z) -> None:
        kernels.scaled(self.dim, r, self.level.dinv, 1.0, z)

    def _preconditioner(self, inner: Callable):
        """``inner`` followed by the projection off the free rigid modes, when there are any."""
        if not self._removes_rigid_motion():
            return inner

        def projected(r, z) -> None:
            inner(r, z)
            z.from_numpy(self._project(z.to_numpy()).astype(self.level.dtype))

        return projected

    def _removes_rigid_motion(self) -> bool:
        """Whether solves work off the free bodies' rigid modes: in statics they are the operator's
        null space; a backward-Euler step's mass holds them, and removing them would stop a free
        body from moving as its loads and momentum say."""
        return bool(self.modes) and self.level.shift == 0.0

    def _without_rigid_motion(self, u: np.ndarray) -> np.ndarray:
        """u [d, size] less each free body's rigid motion in the material's sense (weighted by face
        fractions): CG works orthogonal to the modes over every sample, ghost samples outside the
        material included, which would leave the material a small rigid shift."""
        flat = u.reshape(-1).copy()
        weight = self.level.vf_host.reshape(-1)
        for _, q, pos in self.modes:
            w = weight[pos]
            gram = np.einsum("ni,n,nj->ij", q, w, q)  # no [n, modes] temporary (20 M DOFs: 1 GiB)
            flat[pos] -= q @ np.linalg.lstsq(gram, q.T @ (w * flat[pos]), rcond=None)[0]
        return flat.reshape(u.shape)

    def _project(self, v: np.ndarray) -> np.ndarray:
        flat = v.reshape(-1).copy()
        for _, q, pos in self.modes:
            flat[pos] -= q @ (q.T @ flat[pos])
        return flat.reshape(v.shape)


class _Space:
    """Vector algebra of the CG solver on one level's arrays."""

    def __init__(self, level: Level) -> None:
        self.level = level

    def zeros(self):
        return self.level.zeros()

    def dot(self, x, y) -> float:
        return kernels.dot(self.level.dim, x, y)

    def axpy(self, alpha: float, x, y) -> None:
        kernels.axpy(self.level.dim, alpha, x, y)

    def xpby(self, x, beta: float, y) -> None:
        kernels.xpby(self.level.dim, x, beta, y)

    def copy(self, src, dst) -> None:
        kernels.copy(self.level.dim, src, dst)

    def finite(self, x) -> bool:
        return kernels.count_nonfinite(self.level.dim, x) == 0


def _share_at(shares: tuple[np.ndarray, np.ndarray], pos: np.ndarray) -> np.ndarray:
    """The patch share [M] of rows at layout positions ``pos`` (0 for rows that do not see the patch)."""
    where, share = shares
    if not len(where):
        return np.zeros(len(pos))
    order = np.argsort(where)
    where, share = where[order], share[order]
    i = np.minimum(np.searchsorted(where, pos), len(where) - 1)
    return np.where(where[i] == pos, share[i], 0.0)
