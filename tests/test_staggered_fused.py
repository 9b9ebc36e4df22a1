"""The staggered solver's fused and listed kernels against the plain ones: the gathered
restriction, operator passes over a list of positions (the boundary band), the fused residual,
Chebyshev and power-iteration modes, the layout's flat helpers and the body labels."""

import functools

import numpy as np
import pytest
import gstaichi as ti
import trimesh

from engine.boundary import Prescribed
from engine.geometry.fractions import volume_fractions
from engine.grid import make_grid
from engine.regions import Halfspaces
from engine.runtime import init
from engine.staggered import kernels as kn
from engine.staggered.multigrid import Multigrid, boundary_band
from engine.staggered import multigrid
from engine.staggered.nitsche import hold_patches, make_surface_operator
from engine.staggered.operator import device_array, dof_bodies, make_coarse_level, make_fine_level
from tests.conftest import polygon_surface_2d, surface_of

LAM, MU = 1.3, 0.7


@pytest.fixture(scope="module", autouse=True)
def runtime():
    init("cpu", "f64")


@functools.lru_cache
def shape(d):
    """(surface, its volume fractions): an ellipse in 2D, a sphere in 3D."""
    if d == 2:
        th = np.linspace(0, 2 * np.pi, 200, endpoint=False)
        surf = polygon_surface_2d(np.stack([np.cos(th), 0.7 * np.sin(th)], axis=1))
        return surf, volume_fractions(surf, make_grid(*surf.bounds, resolution=40))
    surf = surface_of(trimesh.creation.icosphere(3, radius=1.0))
    return surf, volume_fractions(surf, make_grid(*surf.bounds, resolution=18))


def fractions(d):
    return shape(d)[1]


def kept(lev, v):
    """v with the zero tile cleared (no kernel writes there; random test data must not either)."""
    v = np.array(v)
    v[..., lev.layout.count * lev.layout.tile_size :] = 0.0
    return v


def clamped(d):
    lev = make_fine_level(fractions(d), LAM, MU)
    idx = lev.layout.indices()
    low = np.zeros(lev.size, dtype=bool)
    low[: len(idx)] = idx[:, d - 1] < 5
    lev.set_free(lev.active & ~low[None])
    return lev


@pytest.mark.parametrize("kind", [kn.LINEAR, kn.FACE])
@pytest.mark.parametrize("d", [2, 3])
def test_gathered_restriction_equals_the_scatter(d, kind, rng):
    fine = make_fine_level(fractions(d), LAM, MU)
    coarse = make_coarse_level(fine)
    f = kept(fine, rng.standard_normal((d, fine.size)))
    want = coarse.zeros()
    kn.fill(d, want, 0.0)
    kn.restrict_add(d, kind, ti.f64, fine.coords, device_array(fine.layout.parents(coarse.layout)),
                    coarse.layout.count, device_array(f), want)
    mask = kept(coarse, rng.random((d, coarse.size)))
    got = coarse.zeros()
    kn.restrict(d, kind, coarse.coords, device_array(coarse.layout.children(fine.layout)), device_array(mask),
                device_array(f), got)
    want = want.to_numpy() * mask
    assert np.abs(want).max() > 1.0
    np.testing.assert_allclose(got.to_numpy(), want, rtol=0, atol=1e-13 * np.abs(want).max())


@pytest.mark.parametrize("d", [2, 3])
def test_layout_flat_and_shifted(d, rng):
    lay = make_fine_level(fractions(d), LAM, MU).layout
    dense = rng.standard_normal(lay.box)
    flat = lay.flat(dense)
    np.testing.assert_array_equal(lay.dense(flat), np.where(lay.dense(np.ones(lay.size)) > 0, dense, 0.0))
    idx = lay.indices()
    pos = rng.choice(len(idx), 500, replace=False)
    for a in range(d):
        for step in (-1, 1):
            moved = idx[pos].copy()
            moved[:, a] += step
            want = lay.positions(moved)
            got = lay.shifted(pos, a, step)
            in_box = want >= 0
            np.testing.assert_array_equal(got[in_box], want[in_box])
            # beyond the box: a position in its (kept) tile, whose values are zero, or the zero tile
            tiles = moved[~in_box] // 8
            on_grid = np.all((tiles >= 0) & (tiles < np.asarray(lay.tile_map.shape)), axis=1)
            tile_of = np.full(len(tiles), lay.count)
            tile_of[on_grid] = lay.tile_map[tuple(tiles[on_grid].T)]
            np.testing.assert_array_equal(got[~in_box] // lay.tile_size, tile_of)


@pytest.mark.parametrize("d", [2, 3])
def test_listed_passes_equal_the_full_ones_at_their_positions(d, rng):
    lev = clamped(d)
    part = boundary_band(lev)
    assert part is not None
    x = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    full, listed = lev.zeros(), lev.zeros()
    kn.fill(d, listed, 0.0)
    lev.apply(device_array(x), full)
    lev.apply(device_array(x), listed, part)
    on = part.update.to_numpy()
    assert 0 < len(on) < lev.layout.count * lev.layout.tile_size
    np.testing.assert_array_equal(listed.to_numpy()[:, on], full.to_numpy()[:, on])
    off = np.ones(lev.size, dtype=bool)
    off[on] = False
    assert not np.any(listed.to_numpy()[:, off])
    # a Chebyshev step over the part, with the level's own D^-1, moves only the band's DOFs, by
    # c2 D^-1 (b - A x) at the part's positions
    b = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    xs, step = device_array(x), lev.zeros()
    lev.chebyshev_step(xs, device_array(b), step, lev.dinv, 0.0, 0.3, part)
    band = np.zeros(lev.size)
    band[on] = 1.0
    want = x + 0.3 * band * lev.dinv.to_numpy() * (b - full.to_numpy())
    np.testing.assert_allclose(xs.to_numpy(), want, rtol=0, atol=1e-12 * np.abs(want).max())


def held(d):
    """A level whose surface below x_{d-1} = -0.4 is held by the Nitsche terms (every DOF free)."""
    surf, fr = shape(d)
    lev = make_fine_level(fr, LAM, MU)
    base = Prescribed(Halfspaces(np.eye(d)[d - 1 : d], np.array([-0.4])), (0.0,) * d, "base")
    patches = hold_patches([base], surf)
    lev.set_surface(make_surface_operator(lev, patches.quadrature(2 * lev.spacing)), patches)
    return lev


@pytest.mark.parametrize("d", [2, 3])
def test_every_mode_adds_the_surface_terms_at_their_dofs(d, rng):
    """With a hold, each mode of the divergence pass (over all positions and over the band's list)
    equals the plain operator plus S x = (mass - flux stress - (flux stress)^T) x on the hold's DOFs."""
    lev = held(d)
    sf = lev.surface
    assert len(sf.comp) > 0
    x = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    b = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    s0 = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    sx = np.zeros((d, lev.size))
    sx[sf.comp, sf.pos] = sf.matrix() @ x[sf.comp, sf.pos]
    plain = make_fine_level(fractions(d), LAM, MU)  # the same level without the hold
    np.testing.assert_array_equal(plain.free, lev.free)
    ax = plain.zeros()
    plain.apply(device_array(x), ax)
    ax = ax.to_numpy() + sx * lev.free
    assert np.abs(sx).max() > 1e-3 * np.abs(ax).max()  # the hold's terms are not negligible here
    tol = 1e-12 * (np.abs(ax).max() + np.abs(b).max())
    y = lev.zeros()
    lev.apply(device_array(x), y)
    np.testing.assert_allclose(y.to_numpy(), ax, rtol=0, atol=tol)
    lev.residual(device_array(x), device_array(b), y)
    np.testing.assert_allclose(y.to_numpy(), b - ax, rtol=0, atol=tol)
    dinv = lev.dinv.to_numpy()
    part = boundary_band(lev)
    on = np.zeros(lev.size)
    on[part.update.to_numpy()] = 1.0
    assert np.any(on[sf.pos] == 0) and np.any(on[sf.pos] == 1)  # the band holds some of the hold's DOFs
    for listed, where in ((None, 1.0), (part, on)):
        xs, step = device_array(x), device_array(s0)
        lev.chebyshev_step(xs, device_array(b), step, lev.dinv, 0.4, 0.7, listed)
        want = np.where(where * lev.free > 0, 0.4 * s0 + 0.7 * dinv * (b - ax), s0)
        np.testing.assert_allclose(step.to_numpy(), want, rtol=0, atol=1e-12 * np.abs(want).max())
        moved = np.where(where * lev.free > 0, want, 0.0)
        np.testing.assert_allclose(xs.to_numpy(), x + moved, rtol=0, atol=1e-12 * np.abs(x + moved).max())


@pytest.mark.parametrize("d", [2, 3])
def test_fused_modes_equal_their_unfused_sums(d, rng):
    lev = clamped(d)
    x = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    b = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    s0 = kept(lev, rng.standard_normal((d, lev.size)) * lev.free)
    ax = lev.zeros()
    lev.apply(device_array(x), ax)
    ax = ax.to_numpy()
    scale = np.abs(ax).max() + np.abs(b).max()
    r = lev.zeros()
    lev.residual(device_array(x), device_array(b), r)
    np.testing.assert_allclose(r.to_numpy(), b - ax, rtol=0, atol=1e-13 * scale)
    dinv = lev.dinv.to_numpy()
    xs, step = device_array(x), device_array(s0)
    lev.chebyshev_step(xs, device_array(b), step, lev.dinv, 0.4, 0.7)
    want_step = 0.4 * s0 + 0.7 * dinv * (b - ax)
    np.testing.assert_allclose(step.to_numpy(), want_step, rtol=0, atol=1e-13 * np.abs(want_step).max())
    np.testing.assert_allclose(xs.to_numpy(), x + want_step, rtol=0, atol=1e-13 * np.abs(x + want_step).max())


def test_body_labels_of_two_bodies_and_their_faces():
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[1.5, 0, 0], [2.5, 1, 1]])
    surf = surface_of(trimesh.util.concatenate([a, b]))
    lev = make_fine_level(volume_fractions(surf, make_grid(*surf.bounds, resolution=20)), LAM, MU)
    comp, pos = np.nonzero(lev.active[:, : lev.layout.count * lev.layout.tile_size])
    body = dof_bodies(lev, comp, pos)
    assert set(np.unique(body)) == {1, 2}
    x = lev.layout.indices()[pos, 0] * lev.spacing + np.asarray(fractions_origin(surf))[0]
    assert np.all(body[x < 1.2] == body[np.argmin(x)]) and np.all(body[x > 1.3] != body[np.argmin(x)])


def fractions_origin(surf):
    return make_grid(*surf.bounds, resolution=20).origin


def test_the_cycle_is_symmetric_with_the_listed_band(rng, monkeypatch):
    """The V-cycle with the band as a list of positions is still symmetric to round-off."""
    monkeypatch.setattr(multigrid, "MAX_CUT_SHARE", 1.0)
    lev = clamped(3)
    mg = Multigrid(lev)
    assert len(mg.levels) >= 2 and all(band is not None for band in mg.bands)

    def cycle(v):
        out = lev.zeros()
        mg.precondition(device_array(v), out)
        return out.to_numpy()

    v = kept(lev, rng.standard_normal((3, lev.size)) * lev.free)
    w = kept(lev, rng.standard_normal((3, lev.size)) * lev.free)
    assert np.sum(v * cycle(w)) == pytest.approx(np.sum(w * cycle(v)), rel=1e-11)


def test_the_cpu_level_keeps_one_copy_of_its_fractions_and_a_byte_mask():
    """On the CPU backend in f64 the kernels read the host fractions themselves (no device copy
    beside them: 32 bytes per position) and the free-DOF mask takes one byte per DOF; in f32 the
    kernels get their own single-precision copy."""
    lev = make_fine_level(fractions(3), LAM, MU)
    assert lev.vc is lev.vc_host and lev.ve is lev.ve_host
    assert lev.mask.dtype == ti.i8
    np.testing.assert_array_equal(lev.mask.to_numpy(), lev.free)
    single = make_fine_level(fractions(3), LAM, MU, dtype=np.float32)
    assert single.vc.dtype == ti.f32 and single.ve.dtype == ti.f32
    np.testing.assert_array_equal(single.vc.to_numpy(), single.vc_host.astype(np.float32))
