"""Taichi staggered operator: apply vs the reference assembly, tiles, coarse levels, transfers, multigrid PCG."""

import functools
import itertools

import numpy as np
import gstaichi as ti
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import trimesh

from engine.geometry.fractions import volume_fractions
from engine.grid import axis_pairs as pairs, make_grid
from engine.runtime import device_array, init
from engine.solvers.cg import pcg
from engine.staggered import assembly
from engine.staggered import kernels as kn
from engine.staggered.layout import TILE
from engine.staggered.multigrid import Multigrid
from engine.staggered import multigrid
from engine.staggered.operator import make_coarse_level, make_fine_level, weights
from tests.conftest import polygon_surface_2d, surface_of

LAM, MU = 1.3, 0.7


@pytest.fixture(scope="module", autouse=True)
def runtime():
    init("cpu", "f64")


# --- geometry and the map between layout positions and assembly DOF ids -------------------------


@functools.lru_cache
def ellipse(resolution):
    th = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    surf = polygon_surface_2d(np.stack([np.cos(th), 0.7 * np.sin(th)], axis=1))
    return volume_fractions(surf, make_grid(*surf.bounds, resolution=resolution))


@functools.lru_cache
def sphere(resolution):
    surf = surface_of(trimesh.creation.icosphere(3, radius=1.0))
    return volume_fractions(surf, make_grid(*surf.bounds, resolution=resolution))


@functools.lru_cache
def square(resolution):
    surf = polygon_surface_2d(np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [0.0, 3.0]]))
    return volume_fractions(surf, make_grid(*surf.bounds, resolution=resolution))


def cube(resolution):
    surf = surface_of(trimesh.creation.box(extents=(2.0, 2.0, 2.0)))
    return volume_fractions(surf, make_grid(*surf.bounds, resolution=resolution))


FRACTIONS = {2: lambda: ellipse(20), 3: lambda: sphere(10)}


class Reference:
    """The scipy assembly of a level's fractions, and its DOF ids <-> layout positions."""

    def __init__(self, lev, cell, edges):
        d = lev.dim
        self.shape = tuple(n - 1 for n in cell.shape)
        self.cell = cell
        self.edges = assembly.supported_edges(cell, edges)
        self.K = assembly.stiffness(cell, self.edges, lev.spacing, LAM, MU).tocsr()
        self.act = assembly.active_dofs(cell)
        n = assembly.dof_count(self.shape)
        self.comp = assembly.dof_components(self.shape)
        box = assembly.box_shape(self.shape)
        idx = np.stack(np.unravel_index(np.arange(n) % np.prod(box), box), axis=1)
        self.pos = lev.layout.positions(idx)
        self.d, self.size = d, lev.size

    @classmethod
    def of_fractions(cls, lev, fractions):
        """The exact fractions as the level weighs them (round-off snapped to 1, slivers raised)."""
        cell, _, edges = assembly.box_fractions(fractions)
        return cls(lev, weights(cell), {p: weights(v) for p, v in edges.items()})

    @classmethod
    def of_level(cls, lev):
        """From the level's own (e.g. coarse) fractions."""
        lay = lev.layout
        return cls(lev, lay.dense(lev.vc_host), {p: lay.dense(lev.ve_host[q]) for q, p in enumerate(pairs(lev.dim))})

    def to_layout(self, u, on):
        x = np.zeros((self.d, self.size))
        x[self.comp[on], self.pos[on]] = u[on]
        return x

    def from_layout(self, x, on):
        u = np.zeros(len(self.comp))
        u[on] = x[self.comp[on], self.pos[on]]
        return u


def apply(lev, x):
    y = lev.zeros()
    lev.apply(device_array(x), y)
    return y.to_numpy()


class Space:
    """engine.solvers.cg.Space over [d, size] Taichi arrays of one level."""

    def __init__(self, lev):
        self.lev = lev

    def zeros(self):
        return self.lev.zeros()

    def dot(self, x, y):
        return kn.dot(self.lev.dim, x, y)

    def axpy(self, a, x, y):
        kn.axpy(self.lev.dim, a, x, y)

    def xpby(self, x, b, y):
        kn.xpby(self.lev.dim, x, b, y)

    def copy(self, a, b):
        kn.copy(self.lev.dim, a, b)

    def finite(self, x):
        return kn.count_nonfinite(self.lev.dim, x) == 0


def dof_points(lev, origin):
    """Positions [d, size, d] of every layout position of kept tiles (the zero tile: far away)."""
    d = lev.dim
    idx = lev.layout.indices()
    pts = (idx[None] + 0.5 - 0.5 * np.eye(d)[:, None, :]) * lev.spacing + np.asarray(origin)
    out = np.full((d, lev.size, d), 1e9)
    out[:, : len(idx)] = pts
    return out


# --- a. apply against the assembly -----------------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_apply_equals_reference_stiffness_and_active_dofs_match(d, rng):
    fr = FRACTIONS[d]()
    lev = make_fine_level(fr, LAM, MU)
    ref = Reference.of_fractions(lev, fr)
    act = ref.act
    # every active DOF lies in a kept tile, the level's active flags are those of the assembly
    assert act.sum() > 300 and np.all(ref.pos[act] >= 0)
    kept = ref.pos >= 0
    np.testing.assert_array_equal(lev.active[ref.comp[kept], ref.pos[kept]], act[kept])
    assert lev.active.sum() == act.sum()
    # the pruned edge weights are supported_edges of the exact ones
    for q, p in enumerate(pairs(d)):
        np.testing.assert_array_equal(lev.layout.dense(lev.ve_host[q], ref.cell.shape), ref.edges[p])
    np.testing.assert_array_equal(lev.layout.dense(lev.vc_host, ref.cell.shape), ref.cell)
    for _ in range(2):
        u = rng.standard_normal(len(act)) * act
        want = ref.K @ u
        got = ref.from_layout(apply(lev, ref.to_layout(u, act)), act)
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
    # nothing leaks to inactive positions
    y = apply(lev, ref.to_layout(u, act))
    assert not np.any(y[~lev.active])


# --- b. tiles -------------------------------------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_layout_dense_round_trip(d, rng):
    lay = make_fine_level(FRACTIONS[d](), LAM, MU).layout
    flat = rng.standard_normal(lay.size)
    flat[lay.count * lay.tile_size :] = 0.0  # the zero tile
    dense = lay.dense(flat)
    assert dense.shape == lay.box
    idx = lay.indices()
    inside = np.all(idx < np.asarray(lay.box), axis=1)
    np.testing.assert_array_equal(dense[tuple(idx[inside].T)], flat[: len(idx)][inside])
    back = np.zeros_like(flat)
    at = lay.positions(np.indices(lay.box).reshape(d, -1).T)
    back[at[at >= 0]] = dense.reshape(-1)[at >= 0]
    np.testing.assert_array_equal(back[: len(idx)][inside], flat[: len(idx)][inside])
    # positions of untouched tiles and outside the box are -1
    assert lay.positions(np.full((1, d), -1))[0] == -1 and lay.positions(np.asarray([lay.box]))[0] == -1
    assert np.sum(at >= 0) == inside.sum() and not np.any(dense.reshape(-1)[at < 0])
    if d == 2:  # the ellipse leaves corner tiles of the box untouched (in 3D at this size all are kept)
        assert lay.count < np.prod(lay.tile_map.shape) and np.prod(lay.box) > inside.sum()


@pytest.mark.parametrize("d,resolution", [(2, 30), (3, 20)])
def test_full_tiles_take_the_constant_path_with_the_same_result(d, resolution, rng):
    fr = square(resolution) if d == 2 else cube(resolution)
    lev = make_fine_level(fr, LAM, MU)
    # the solid occupies cells 1 .. resolution, so tiles 1 .. (resolution + 1) // 8 - 1 per axis are full
    inner = (resolution + 1) // TILE - 1
    assert lev.full_tiles == inner**d > 0
    full = np.asarray(lev.full.to_numpy(), dtype=bool)
    assert np.all(np.all((lev.layout.coords[full] >= 1) & (lev.layout.coords[full] <= inner), axis=1))
    ref = Reference.of_fractions(lev, fr)
    u = rng.standard_normal(len(ref.act)) * ref.act
    x = ref.to_layout(u, ref.act)
    fast = apply(lev, x)
    lev.full = device_array(np.zeros(lev.layout.count, dtype=np.int32))
    general = apply(lev, x)
    np.testing.assert_array_equal(fast, general)  # weights of exactly 1 make the two paths bitwise equal
    want = ref.K @ u
    assert np.abs(ref.from_layout(fast, ref.act) - want).max() <= 1e-12 * np.abs(want).max()


# --- c. coarse levels -------------------------------------------------------------------------------


def coarse_means(fine_cell, coarse_box, shift):
    """mean over o in {0,1}^d of fine_cell[2 J - 2 - shift + o] for every J of coarse_box (zero outside)."""
    d = fine_cell.ndim
    pad = 4
    big = np.pad(fine_cell, [(pad, 2 * n + pad - m) for n, m in zip(coarse_box, fine_cell.shape)])
    J = np.indices(coarse_box).reshape(d, -1).T
    out = np.zeros(len(J))
    for o in itertools.product((0, 1), repeat=d):
        at = 2 * J - 2 - np.asarray(shift) + np.asarray(o) + pad
        out += big[tuple(at.T)]
    return (out / 2**d).reshape(coarse_box)


@pytest.mark.parametrize("d", [2, 3])
def test_coarse_fractions_are_means_of_fine_cells(d, rng):
    fine = make_fine_level(FRACTIONS[d](), LAM, MU)
    coarse = make_coarse_level(fine)
    assert coarse.spacing == 2 * fine.spacing
    vol_f = fine.vc_host.sum() * fine.spacing**d
    vol_c = coarse.vc_host.sum() * coarse.spacing**d
    assert vol_c == pytest.approx(vol_f, rel=1e-13)
    box_c = coarse.layout.box
    # ceil(fine cells / 2) coarse cells, one more of padding on each side, plus the index layer
    assert box_c == tuple(-(-(n - 1) // 2) + 2 + 1 for n in fine.layout.box)
    cell_f = fine.layout.dense(fine.vc_host)
    eye = np.eye(d, dtype=int)
    cell_c = coarse.layout.dense(coarse.vc_host)
    np.testing.assert_allclose(cell_c, coarse_means(cell_f, box_c, np.zeros(d, int)), rtol=0, atol=1e-15)
    for a in range(d):
        np.testing.assert_allclose(coarse.layout.dense(coarse.vf_host[a]), coarse_means(cell_f, box_c, eye[a]),
                                   rtol=0, atol=1e-15)
    raw = {(a, b): coarse_means(cell_f, box_c, eye[a] + eye[b]) for a, b in pairs(d)}
    kept = assembly.supported_edges(cell_c, raw)
    for q, p in enumerate(pairs(d)):
        np.testing.assert_allclose(coarse.layout.dense(coarse.ve_host[q]), kept[p], rtol=0, atol=1e-15)
    # by hand: the fullest cut coarse cell J from its 2^d fine cells, and its low a-face from the 2^d
    # fine cells straddling it (fine layers 2 J_a - 3, 2 J_a - 2 along a)
    J = np.unravel_index(np.argmax(cell_c * (cell_c < 1)), box_c)
    cells = [cell_f[tuple(2 * np.asarray(J) - 2 + np.asarray(o))] for o in itertools.product((0, 1), repeat=d)]
    assert 0 < cell_c[J] < 1 and cell_c[J] == pytest.approx(sum(cells) / 2**d, rel=1e-15)
    for a in range(d):
        lo = 2 * np.asarray(J) - 2 - eye[a]
        straddle = [cell_f[tuple(lo + np.asarray(o))] for o in itertools.product((0, 1), repeat=d)]
        assert coarse.layout.dense(coarse.vf_host[a])[J] == pytest.approx(sum(straddle) / 2**d, rel=1e-15)
    # and the coarse level is the reference assembly of its own fractions
    ref = Reference.of_level(coarse)
    u = rng.standard_normal(len(ref.act)) * ref.act
    want = ref.K @ u
    got = ref.from_layout(apply(coarse, ref.to_layout(u, ref.act)), ref.act)
    assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()


# --- d. transfers -------------------------------------------------------------------------------------


def ones(lev):
    return device_array(np.ones((lev.dim, lev.size)))


def prolong(fine, coarse, c, kind=kn.LINEAR):
    """P c on the fine level (all-ones mask)."""
    x = fine.zeros()
    kn.fill(fine.dim, x, 0.0)
    parents = device_array(fine.layout.parents(coarse.layout))
    kn.prolong_add(fine.dim, kind, fine.coords, parents, ones(fine), device_array(c), x)
    return x.to_numpy()


def restrict(fine, coarse, f, kind=kn.LINEAR):
    """P^T f on the coarse level, the coarse zero tile included (where it lands is part of the check)."""
    out = coarse.zeros()
    kn.fill(coarse.dim, out, 0.0)
    kn.restrict_add(fine.dim, kind, ti.f64, fine.coords, device_array(fine.layout.parents(coarse.layout)),
                    coarse.layout.count, device_array(f), out)
    return out.to_numpy()


@pytest.mark.parametrize("d", [2, 3])
def test_prolongation_reproduces_affine_fields(d, rng):
    fr = FRACTIONS[d]()
    fine = make_fine_level(fr, LAM, MU)
    coarse = make_coarse_level(fine)
    origin_f = np.asarray(fr.grid.origin)
    origin_c = origin_f - coarse.spacing
    g, c0 = rng.standard_normal((d, d)), rng.standard_normal(d)

    def affine(lev, origin):
        pts = dof_points(lev, origin)
        u = np.stack([pts[a] @ g[a] + c0[a] for a in range(d)])
        u[:, lev.layout.count * lev.layout.tile_size :] = 0.0
        return u

    got = prolong(fine, coarse, affine(coarse, origin_c))
    want = affine(fine, origin_f)
    # interior: every coarse index within one of (I + 2) // 2 is in a kept coarse tile
    idx = fine.layout.indices()
    base = (idx + 2) // 2
    reach = np.all([coarse.layout.positions(base + np.asarray(o)) >= 0
                    for o in itertools.product((-1, 0, 1), repeat=d)], axis=0)
    assert reach.sum() > 0.4 * len(idx)
    n = len(idx)
    err = np.abs(got[:, :n][:, reach] - want[:, :n][:, reach]).max()
    assert err <= 1e-13 * np.abs(want[:, :n]).max()
    # a constant field on the coarse level gives the same constant on the fine one (weights sum to 1)
    const = prolong(fine, coarse, np.where(affine(coarse, origin_c) != 0, 1.0, 0.0))
    np.testing.assert_allclose(const[:, :n][:, reach], 1.0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("d", [2, 3])
def test_face_prolongation_keeps_the_divergence_of_every_fine_cell(d, rng):
    """FACE: div(P c) in fine cell I is div(c) in its coarse cell (I + 2) // 2, for any c (what the
    patch smoothing near incompressibility needs: the coarse lambda energy is the fine one's);
    LINEAR does not keep it. Constants are reproduced where the coarse samples are kept."""
    fine = make_fine_level(FRACTIONS[d](), LAM, MU)
    coarse = make_coarse_level(fine)
    c = rng.standard_normal((d, coarse.size))
    c[:, coarse.layout.count * coarse.layout.tile_size :] = 0.0

    def divergence(lev, u):
        dense = lev.layout.dense(u)
        return sum(np.roll(dense[a], -1, axis=a) - dense[a] for a in range(d)) / lev.spacing

    solid = np.argwhere(fine.layout.dense(fine.vc_host) > 0)
    parent = tuple(((solid + 2) // 2).T)
    want = divergence(coarse, c)[parent]
    for kind, close in ((kn.FACE, True), (kn.LINEAR, False)):
        got = divergence(fine, prolong(fine, coarse, c, kind))[tuple(solid.T)]
        assert np.allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max()) == close
    n = fine.layout.count * fine.layout.tile_size
    const = prolong(fine, coarse, np.where(coarse.active, 1.0, 0.0), kn.FACE)
    np.testing.assert_allclose(const[:, :n][fine.active[:, :n]], 1.0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("kind", [kn.LINEAR, kn.FACE])
@pytest.mark.parametrize("d", [2, 3])
def test_restriction_is_the_transpose_of_prolongation(d, kind, rng):
    fine = make_fine_level(FRACTIONS[d](), LAM, MU)
    coarse = make_coarse_level(fine)
    zero_c = slice(coarse.layout.count * coarse.layout.tile_size, None)

    def random(lev):
        v = rng.standard_normal((d, lev.size))
        v[:, lev.layout.count * lev.layout.tile_size :] = 0.0
        return v

    for _ in range(3):
        f, c = random(fine), random(coarse)
        lhs = np.sum(restrict(fine, coarse, f, kind) * c)
        rhs = np.sum(f * prolong(fine, coarse, c, kind))
        assert lhs == pytest.approx(rhs, rel=1e-12) and abs(lhs) > 1.0
    # a fine vector on the active DOFs restricts into kept coarse tiles only: the zero tile stays zero
    r = restrict(fine, coarse, random(fine) * fine.active, kind)
    assert not np.any(r[:, zero_c]) and np.any(r)
    # with the level masks (as in the V-cycle): <M_c P^T M_f f, M_c c> = <M_f f, M_f P M_c c>
    f, c = random(fine) * fine.active, random(coarse) * coarse.active
    lhs = np.sum(restrict(fine, coarse, f, kind) * coarse.active * c)
    rhs = np.sum(f * fine.active * prolong(fine, coarse, c * coarse.active, kind))
    assert lhs == pytest.approx(rhs, rel=1e-12)


# --- e. multigrid-preconditioned CG ---------------------------------------------------------------


def clamped(d, fr, below):
    lev = make_fine_level(fr, LAM, MU)
    pts = dof_points(lev, fr.grid.origin)
    lev.set_free(lev.active & ~(pts[..., d - 1] < below))
    return lev


def solve_and_compare(lev, fr, rng, levels):
    """CG with the V-cycle to rtol 1e-8 against spsolve of the reference K on the free DOFs; the
    V-cycle is symmetric and positive. Returns the CG iteration count."""
    d = lev.dim
    mg = Multigrid(lev)
    assert len(mg.levels) >= levels
    ref = Reference.of_fractions(lev, fr)
    free = ref.from_layout(lev.free.astype(float), ref.act).astype(bool)
    assert 0 < (ref.act & ~free).sum() < 0.2 * ref.act.sum()
    f = rng.standard_normal(len(free)) * free
    b = lev.zeros()
    b.from_numpy(ref.to_layout(f, free))
    x = lev.zeros()
    stats = pcg(Space(lev), lev.apply, mg.precondition, b, x, rtol=1e-8, max_iterations=200)
    assert stats.residual <= 1e-8
    want = np.zeros(len(free))
    want[free] = spla.spsolve(ref.K[free][:, free].tocsc(), f[free])
    got = ref.from_layout(x.to_numpy(), ref.act)
    assert np.abs(got - want).max() <= 1e-7 * np.abs(want).max()
    assert not np.any(x.to_numpy()[~lev.free])

    # the V-cycle is a symmetric positive definite operator on the free DOFs
    def cycle(v):
        out = lev.zeros()
        mg.precondition(device_array(v), out)
        return out.to_numpy()

    for _ in range(3):
        v = rng.standard_normal((d, lev.size)) * lev.free
        w = rng.standard_normal((d, lev.size)) * lev.free
        mv, mw = cycle(v), cycle(w)
        assert np.sum(v * mw) == pytest.approx(np.sum(w * mv), rel=1e-10)
        assert np.sum(v * mv) > 0
    return stats.iterations


def test_multigrid_pcg_on_a_clamped_sphere(rng, monkeypatch):
    monkeypatch.setattr(multigrid, "MAX_CUT_SHARE", 1.0)  # coarsen this small grid anyway
    fr = sphere(18)  # 20^3 cells, ~10^4 free DOFs: two levels
    assert solve_and_compare(clamped(3, fr, -0.6), fr, rng, levels=2) <= 30  # 21 measured


def test_multigrid_pcg_on_a_clamped_ellipse(rng, monkeypatch):
    monkeypatch.setattr(multigrid, "MAX_CUT_SHARE", 1.0)
    fr = ellipse(180)  # ~3.3 10^4 free DOFs: three levels, so the cycle recurses
    assert solve_and_compare(clamped(2, fr, -0.5), fr, rng, levels=3) <= 30  # 17 measured


# --- f. a free body ------------------------------------------------------------------------------


def test_free_body_in_the_complement_of_the_rigid_modes(rng, monkeypatch):
    """No prescribed DOF: K is singular on the rigid modes. A random load orthogonal to them (no net
    force or torque) is solved by CG with the V-cycle's output projected onto their complement; that
    it converges (and the bordered reference system is regular) also says the rigid modes are the
    whole null space: the exact fractions of a sphere leave no mechanism."""
    monkeypatch.setattr(multigrid, "MAX_CUT_SHARE", 1.0)  # a real hierarchy on this small grid
    d = 3
    rigid = d + d * (d - 1) // 2
    fr = sphere(14)
    lev = make_fine_level(fr, LAM, MU)
    mg = Multigrid(lev)
    assert len(mg.levels) >= 2
    assert mg.coarse.factor.n == mg.coarse.n + rigid  # the coarse solve borders the 6 floating modes
    ref = Reference.of_fractions(lev, fr)
    act = ref.act
    q, _ = np.linalg.qr(assembly.rigid_modes(assembly.dof_positions(fr.grid), ref.comp)[act])
    basis = np.stack([ref.to_layout(_full(act, col), act) for col in q.T])  # orthonormal, [6, d, size]
    scale = abs(ref.K).max() * np.abs(basis).max()
    assert max(np.abs(apply(lev, m)).max() for m in basis) <= 1e-13 * scale  # they are in the kernel of Level.apply

    def project(v):
        a = v.to_numpy()
        a -= np.tensordot(np.tensordot(basis, a, axes=([1, 2], [0, 1])), basis, axes=1)
        v.from_numpy(a)

    def precondition(r, z):
        mg.precondition(r, z)
        project(z)

    f = rng.standard_normal(act.sum())
    f -= q @ (q.T @ f)
    b = lev.zeros()
    b.from_numpy(ref.to_layout(_full(act, f), act))
    x = lev.zeros()
    stats = pcg(Space(lev), lev.apply, precondition, b, x, rtol=1e-9, max_iterations=200)
    assert stats.residual <= 1e-9 and stats.iterations <= 35  # 25 measured
    # the solution orthogonal to the rigid modes, from the bordered system
    k = ref.K[act][:, act]
    bordered = sp.bmat([[k, sp.csr_matrix(q)], [sp.csr_matrix(q.T), None]]).tocsc()
    want = spla.spsolve(bordered, np.concatenate([f, np.zeros(rigid)]))[: act.sum()]
    got = ref.from_layout(x.to_numpy(), act)[act]
    assert np.abs(q.T @ got).max() <= 1e-10 * np.linalg.norm(got)
    assert np.abs(got - want).max() <= 1e-8 * np.abs(want).max()


def _full(mask, values):
    out = np.zeros(len(mask))
    out[mask] = values
    return out


# --- g. thin features ------------------------------------------------------------------------------


def thin_walled_box(start, h=1 / 16):
    """The stress suite's hollow box, 6 h + 0.3 h wide and 8 h + 0.3 h tall, walls 0.3 h thick, on a
    pinned grid: walls inside one cell layer (``start`` 0.35: 0.35 h .. 0.65 h of it) or across a
    grid plane (0.85); base clamped (z < 0.6 h). Returns (level, fractions)."""
    from engine.grid import Grid
    from verification.parts import hollow_box

    t = 0.3 * h
    mesh = hollow_box((6 * h + t, 6 * h + t, 8 * h + t), t)
    grid = Grid(origin=(-(1 + start) * h,) * 3, spacing=h, shape=(10, 10, 12))
    fr = volume_fractions(surface_of(mesh), grid)
    return clamped(3, fr, 0.6 * h), fr


def free_stiffness(lev):
    """Dense reference K on the level's free DOFs, and those DOFs' (component, position)."""
    ref = Reference.of_level(lev)
    free = ref.from_layout(lev.free.astype(float), ref.act).astype(bool)
    return ref.K[free][:, free].toarray(), ref.comp[free], ref.pos[free]


@pytest.mark.parametrize("start, motions", [(0.35, 101), (0.85, 0)])
def test_walls_inside_one_cell_layer_leave_exactly_the_motions_found(start, motions):
    """Walls 0.3 h thick inside one cell layer: one sample across each wall, the shear terms tying
    its transverse motion to the in-plane samples reach empty layers and are pruned, so K on the
    free DOFs is singular. unheld_groups finds every zero-energy motion (the dense spectrum: 101
    eigenvalues below 1e-12 of the largest, the next 2.2e-4 of it) and each is annihilated by the
    matrix-free operator; the same walls across a grid plane have two samples across and none."""
    from engine.staggered.operator import unheld_groups

    lev, _ = thin_walled_box(start)
    mech = unheld_groups(lev)
    K, comp, pos = free_stiffness(lev)
    w = np.linalg.eigvalsh(K)
    assert mech.count == motions == int(np.sum(w < 1e-12 * w[-1]))
    assert w[motions] > 1e-5 * w[-1]  # the rest of the spectrum is well away from zero
    if not motions:
        return
    assert mech.fill == pytest.approx(0.3)  # the walls fill 30% of their cells
    # the motions are null vectors of Level.apply, independent (disjoint), and span K's null space
    x = np.zeros((3, lev.size))
    x[mech.comp, mech.pos] = mech.sign * (mech.group + 1.0)  # all at once, each scaled differently
    assert np.abs(apply(lev, x)).max() <= 1e-13 * np.abs(K).max() * np.abs(x).max()
    key = {(c, p): k for k, (c, p) in enumerate(zip(comp, pos))}
    V = np.zeros((len(comp), mech.count))
    V[[key[(c, p)] for c, p in zip(mech.comp, mech.pos)], mech.group] = mech.sign
    assert np.linalg.matrix_rank(V) == motions
    null = np.linalg.eigh(K)[1][:, :motions]
    q, _ = np.linalg.qr(V)
    assert np.linalg.svd(q.T @ null, compute_uv=False).min() > 1 - 1e-9


def test_thin_walls_stop_the_setup_with_a_named_error():
    from engine.errors import ThinFeatureError

    lev, _ = thin_walled_box(0.35)
    with pytest.raises(ThinFeatureError) as info:
        Multigrid(lev)
    message = str(info.value)
    assert message.startswith("grid.cell_size: 101 independent motion(s) of displacement samples")
    assert "thinner than a grid cell (h = 0.0625 m)" in message and "at most 30% of their cells" in message
    assert "about 0.0188 m" in message and "method.kind 'dg'" in message
    # where: between the sample positions [m] of the moving samples, inside the box's walls
    lo, hi = (np.array([float(v) for v in part.split(")")[0].split(", ")])
              for part in message.split("lie between (")[1].split(" and (")[:2])
    assert np.all(lo >= -0.0625) and np.all(hi <= 0.0625 * 8.3 + 0.0625)
    # a dynamic job's level has its mass from the start, which would hold the walls' samples each on
    # its own: the stiffness alone is tested, as before
    lev, _ = thin_walled_box(0.35)
    lev.set_shift(1.0 / 1e-3**2, 1000.0)
    with pytest.raises(ThinFeatureError, match=r"^grid.cell_size: 101 independent motion\(s\)"):
        Multigrid(lev)


def finned_block(h=1 / 16):
    """A 1 x 0.5 x 0.5 block with a fin 0.8 h thick (1 x 0.8 h x 0.65) across the fine grid plane
    y = 7 h, inside the coarse layer [6 h, 8 h]; clamped below z = 0.06."""
    from engine.grid import Grid

    t = 0.8 * h
    block = trimesh.creation.box(bounds=[[0, 0, 0], [1, 0.5, 0.5]])
    fin = trimesh.creation.box(bounds=[[0, 7 * h - t / 2, 0.25], [1, 7 * h + t / 2, 0.9]])
    mesh = block.union(fin, engine="manifold")
    grid = Grid(origin=(-2 * h,) * 3, spacing=h, shape=(20, 12, 19))
    fr = volume_fractions(surface_of(mesh), grid)
    return clamped(3, fr, 0.06), fr


def test_thin_motions_of_a_coarse_level_are_bordered_in_its_direct_solve(rng, monkeypatch):
    """A fin the fine grid resolves (two samples across) but the averaged 2h fractions do not: the
    coarsest level has 24 zero-energy motions. Its sparse LU used to fail ('Factor is exactly
    singular', an unnamed RuntimeError on a valid job); bordered with them it is regular and the
    V-cycle preconditions CG to the reference solution (45 iterations measured)."""
    from engine.solvers.cg import SolverError
    from engine.staggered.operator import Mechanisms, unheld_groups

    lev, fr = finned_block()
    assert unheld_groups(lev).count == 0
    mg = Multigrid(lev)
    coarse = mg.levels[1]
    assert len(mg.levels) == 2 and mg.coarse.mechanisms == unheld_groups(coarse).count == 24
    w = np.linalg.eigvalsh(free_stiffness(coarse)[0])
    assert int(np.sum(w < 1e-12 * w[-1])) == 24  # all of the coarse operator's null space
    assert solve_and_compare(lev, fr, rng, levels=2) <= 80
    # without the bordering the coarse factorisation is singular: a named error, not a RuntimeError
    none = np.zeros(0, dtype=np.int64)
    monkeypatch.setattr(multigrid, "unheld_groups", lambda level: Mechanisms(none, none, none, none, 0, 0.0))
    with pytest.raises(SolverError, match=r"coarsest multigrid level \(488 unknowns .* is singular") as info:
        Multigrid(lev)
    assert info.value.reason == "singular"


@pytest.mark.parametrize("d", [2, 3])
def test_whole_array_shift_matches_the_layout_lookup(d, rng):
    from engine.staggered.operator import _shift_up

    lev = make_fine_level(FRACTIONS[d](), LAM, MU)
    lay = lev.layout
    v = rng.random(lev.size)
    v[-lay.tile_size:] = 0.0  # the zero tile reads zero
    pos = np.arange(lay.count * lay.tile_size)
    for axis in range(d):
        assert np.array_equal(_shift_up(lay, v, axis)[: len(pos)], v[lay.shifted(pos, axis, 1)])
