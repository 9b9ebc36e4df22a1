"""Staggered sampling: multilinear stencils, masked interpolation, surface quadrature, consistent loads."""

import itertools
import math

import numpy as np
import pytest
import trimesh

from engine.errors import VoxelasticError
from engine.grid import Grid
from engine.regions import Ball, Halfspaces
from engine.boundary import boundary_tractions, surface_quadrature
from engine.subdivision import lattice_pieces, subdivided
from engine.staggered.sampling import _torque_couple, interpolate, stencil, surface_loads
from tests.conftest import polygon_surface_2d, surface_of

GRIDS = {
    2: Grid(origin=(-0.7, 0.3), spacing=0.25, shape=(7, 5)),
    3: Grid(origin=(-0.7, 0.3, -0.2), spacing=0.25, shape=(5, 4, 6)),
}


def sample_positions(grid, a):
    """Positions [n+1..., d] of every component-a sample of the index box."""
    box = np.asarray(grid.shape) + 1
    index = np.stack(np.meshgrid(*[np.arange(n) for n in box], indexing="ij"), axis=-1).reshape(-1, grid.dim)
    return grid.sample_points(index, np.eye(grid.dim)[a]).reshape(*box, grid.dim)


def affine_field(grid, rng):
    """Random affine u(x) = c + G x, its dense staggered samples per component, and u itself."""
    d = grid.dim
    c, g = rng.normal(size=d), rng.normal(size=(d, d))
    samples = [sample_positions(grid, a) @ g[a] + c[a] for a in range(d)]
    return samples, lambda x: x @ g.T + c


def interior_points(grid, rng, n):
    """Random points at least h from the grid's edge (their stencils lie in the index box)."""
    lo = np.asarray(grid.origin) + grid.spacing
    return lo + rng.random((n, grid.dim)) * (grid.upper - grid.spacing - lo)


def dense_lookup(samples, masks=None):
    def lookup(a, index):
        assert np.all(index >= 0) and np.all(index < samples[a].shape), "lookup called outside the index box"
        at = tuple(index.T)
        return samples[a][at], (np.ones(len(index), bool) if masks is None else masks[a][at])

    return lookup


@pytest.mark.parametrize("d", [2, 3])
def test_stencil_reproduces_affine_fields_exactly(d, rng):
    grid = GRIDS[d]
    samples, u = affine_field(grid, rng)
    points = interior_points(grid, rng, 200)
    for a in range(d):
        index, weights = stencil(grid, points, a)
        assert index.shape == (200, 2**d, d) and weights.shape == (200, 2**d)
        assert np.all(weights >= 0)
        np.testing.assert_allclose(weights.sum(axis=1), 1.0, rtol=0, atol=1e-14)
        value = (weights * samples[a][tuple(np.moveaxis(index, -1, 0))]).sum(axis=1)
        np.testing.assert_allclose(value, u(points)[:, a], rtol=0, atol=1e-12)
    np.testing.assert_allclose(interpolate(grid, points, dense_lookup(samples)), u(points), rtol=0, atol=1e-12)


def test_stencil_at_a_sample_is_that_sample_and_may_leave_the_box():
    grid = GRIDS[3]
    at = grid.sample_points(np.array([[2, 1, 3]]), (0, 1, 0))  # component-1 sample (2, 1, 3)
    index, weights = stencil(grid, at, 1)
    np.testing.assert_array_equal(index[0, np.argmax(weights[0])], [2, 1, 3])
    assert weights.max() == pytest.approx(1.0, abs=1e-14)
    corner, _ = stencil(grid, np.asarray(grid.origin)[None] + 0.1 * grid.spacing, 0)
    assert corner.min() == -1  # within h/2 of the grid's edge: callers treat index -1 as inactive


def test_interpolate_renormalises_over_active_samples_and_gives_nan_without_any():
    grid = GRIDS[2]
    samples = [np.arange(8 * 6, dtype=float).reshape(8, 6)] * 2
    # The point halfway between component-0 samples (2,1), (3,1), (2,2), (3,2): weights 1/4 each.
    point = 0.25 * sum(grid.sample_points(np.array([i]), (1, 0))[0] for i in ((2, 1), (3, 1), (2, 2), (3, 2)))
    masks = [np.ones((8, 6), bool), np.zeros((8, 6), bool)]
    masks[0][3, 2] = False
    value = interpolate(grid, point[None], dense_lookup(samples, masks))[0]
    assert value[0] == pytest.approx((samples[0][2, 1] + samples[0][3, 1] + samples[0][2, 2]) / 3, abs=1e-13)
    assert math.isnan(value[1])


@pytest.mark.parametrize("d", [2, 3])
def test_interpolate_reproduces_constants_on_any_active_subset(d, rng):
    grid = GRIDS[d]
    box = tuple(np.asarray(grid.shape) + 1)
    constant = rng.normal(size=d)
    samples = [np.full(box, constant[a]) for a in range(d)]
    masks = [rng.random(box) < 0.4 for _ in range(d)]
    # Points everywhere, including within h/2 of the edge (stencil indices -1 are never looked up).
    points = np.asarray(grid.origin) + rng.random((400, d)) * (grid.upper - np.asarray(grid.origin))
    value = interpolate(grid, points, dense_lookup(samples, masks))
    for a in range(d):
        index, weights = stencil(grid, points, a)
        inside = np.all((index >= 0) & (index < np.asarray(box)), axis=2)
        active = np.zeros_like(inside)
        active[inside] = masks[a][tuple(index[inside].T)]
        some = (active & (weights > 0)).any(axis=1)
        assert some.sum() > 100 and (~some).sum() > 0
        np.testing.assert_allclose(value[some, a], constant[a], rtol=1e-14)
        assert np.all(np.isnan(value[~some, a]))


def test_quadrature_of_an_icosphere_is_exact_for_area_normals_and_volume():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    facets = mesh.vertices[mesh.faces]
    longest = np.linalg.norm(facets - np.roll(facets, 1, axis=1), axis=2).max(axis=1)
    assert longest.min() > 0.6 * longest.max()
    points, weights, normals = surface_quadrature(facets, spacing=1.01 * longest.max())
    assert len(weights) == 7 * 4 * len(facets)  # every facet longer than h/2, its quarters not
    assert weights.sum() == pytest.approx(mesh.area, rel=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=0, atol=1e-14)
    np.testing.assert_allclose((weights[:, None] * normals).sum(axis=0), 0.0, atol=1e-13)
    flux = (weights * np.einsum("qi,qi->q", points, normals)).sum()
    assert flux == pytest.approx(3 * mesh.volume, rel=1e-12)  # divergence theorem, div x = 3
    assert np.all(np.einsum("qi,qi->q", points, normals) > 0)  # outward on a convex body around 0


def test_triangle_rule_is_exact_to_degree_five_with_and_without_subdivision():
    ref = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    for spacing in (10.0, 0.1):  # the raw rule, and 4^5 pieces
        points, weights, normals = surface_quadrature(ref, spacing)
        x, y = points[:, 0], points[:, 1]
        assert (weights * x**2).sum() == pytest.approx(1 / 12, rel=1e-13)  # 2! / 4!
        assert (weights * x**3 * y**2).sum() == pytest.approx(1 / 420, rel=1e-12)  # 3! 2! / 7!
        np.testing.assert_allclose(normals, np.broadcast_to([0.0, 0.0, 1.0], normals.shape), atol=1e-15)
    # A general triangle in space: integral of x^2 = A/6 (sum x_i^2 + sum_{i<j} x_i x_j).
    tri = np.array([[[0.3, -0.2, 1.0], [1.7, 0.4, 0.2], [-0.5, 1.1, 0.6]]])
    points, weights, _ = surface_quadrature(tri, 100.0)
    xs = tri[0, :, 0]
    area = 0.5 * np.linalg.norm(np.cross(tri[0, 1] - tri[0, 0], tri[0, 2] - tri[0, 0]))
    exact = area / 6 * ((xs**2).sum() + xs[0] * xs[1] + xs[1] * xs[2] + xs[2] * xs[0])
    assert (weights * points[:, 0] ** 2).sum() == pytest.approx(exact, rel=1e-13)


def test_slivers_are_cut_into_pieces_linear_in_their_length_with_area_and_orientation_kept():
    # CAD booleans' slivers, 1 m long: a needle (a hole's vertex pair to a plate's corner) and a flat
    # cap; quartering them to edges of 1 cm made 4^7 = 16,384 pieces each (the square of length over edge)
    needle = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.004, 0.0]]
    cap = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.003, 0.0]]
    rng = np.random.default_rng(5)
    soup = rng.normal(size=(50, 3, 3))  # and triangles of every shape, in space
    cases = [(np.array([needle]), 0.01), (np.array([cap]), 0.01), (np.array([needle, cap]) @ _rotation(rng), 0.01),
             (soup, 0.2)]
    for facets, longest in cases:
        area, normals = [np.concatenate(v) for v in zip(*(_area_normal(f) for f in facets))]
        pieces = subdivided(facets, longest)
        edges = np.linalg.norm(pieces - np.roll(pieces, 1, axis=1), axis=2)
        assert edges.max() <= longest
        if len(facets) <= 2:
            assert len(pieces) <= len(facets) * 4 * 1.0 / longest, len(pieces)
        if len(facets) == 1:  # every piece faces as its facet does
            cross = np.cross(pieces[:, 1] - pieces[:, 0], pieces[:, 2] - pieces[:, 0])
            np.testing.assert_allclose(cross / np.linalg.norm(cross, axis=1)[:, None],
                                       np.broadcast_to(normals[0], cross.shape), atol=1e-9)
        points, weights, piece_normals = surface_quadrature(facets, 2 * longest)
        assert weights.sum() == pytest.approx(area.sum(), rel=1e-12)
        # every piece keeps its facet's outward normal: the area vectors add up facet by facet
        np.testing.assert_allclose((weights[:, None] * piece_normals).sum(axis=0), (area[:, None] * normals).sum(axis=0),
                                   rtol=0, atol=1e-11 * area.sum())
        whole, w_whole, _ = surface_quadrature(facets, 100.0)  # unsplit: the degree-5 rule is exact for x^3
        assert (weights * points[:, 0] ** 3).sum() == pytest.approx((w_whole * whole[:, 0] ** 3).sum(), rel=1e-10, abs=1e-14)


@pytest.mark.parametrize("d", [2, 3])
def test_lattice_pieces_lie_in_one_box_each_with_measure_and_orientation_kept(d):
    """Facets cut at the planes h/2 apart (the staggered loads' spread is polynomial between them):
    every piece in one box of the lattice, the area vectors and a cubic moment kept."""
    rng = np.random.default_rng(3)
    origin, step = np.array([-1.03, -0.97, -1.011])[:d], 0.05
    needle = [[[0.0, 0.0], [1.0, 0.004]]] if d == 2 else [[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.004, 0.0]]]
    facets = [rng.normal(size=(40, d, d)) * 0.3, np.array(needle)]
    for f in facets:
        pieces = lattice_pieces(f, origin, step)
        unit = (pieces - origin) / step
        box = np.floor(unit.mean(axis=1))
        assert (unit >= box[:, None] - 1e-9).all() and (unit <= box[:, None] + 1 + 1e-9).all()
        points, weights, normals = surface_quadrature(f, 2 * step, lattice=origin)
        whole, w_whole, n_whole = surface_quadrature(f, 100.0)
        assert weights.sum() == pytest.approx(w_whole.sum(), rel=1e-12)
        np.testing.assert_allclose((weights[:, None] * normals).sum(0), (w_whole[:, None] * n_whole).sum(0),
                                   rtol=0, atol=1e-12 * w_whole.sum())
        cubic = (w_whole * whole[:, 0] ** 3).sum()
        assert (weights * points[:, 0] ** 3).sum() == pytest.approx(cubic, rel=1e-10, abs=1e-13)


@pytest.mark.parametrize("d", [2, 3])
def test_lattice_centroids_are_one_point_per_facet_and_box_with_its_measure_and_first_moments(d):
    rng = np.random.default_rng(8)
    origin, step = np.array([-1.03, -0.97, -1.011])[:d], 0.05
    facets = rng.normal(size=(30, d, d)) * 0.3
    pieces, parent = lattice_pieces(facets, origin, step, parents=True)
    points, weights, normals = surface_quadrature(facets, 2 * step, lattice=origin, centroids=True)
    each, w_each, n_each = surface_quadrature(pieces, 100.0, centroids=True)  # every cut piece a point
    if d == 3:
        measure = 0.5 * np.linalg.norm(np.cross(pieces[:, 1] - pieces[:, 0], pieces[:, 2] - pieces[:, 0]), axis=1)
    else:
        measure = np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1)
    parent = parent[measure > 0]  # the quadrature drops pieces of no measure
    assert len(parent) == len(each)
    box, box_each = (np.floor((x - origin) / step).astype(np.int64) for x in (points, each))
    # a point per (facet, box) holding a piece: in 3D the cuts leave a part as several triangles
    groups = np.unique(np.column_stack([parent, box_each]), axis=0)
    assert len(points) == len(groups) and (len(points) < len(each) if d == 3 else len(points) == len(each))
    for key in np.unique(box, axis=0):
        mine, theirs = (box == key).all(axis=1), (box_each == key).all(axis=1)
        assert weights[mine].sum() == pytest.approx(w_each[theirs].sum(), rel=1e-12)
        np.testing.assert_allclose((weights[mine, None] * points[mine]).sum(0),
                                   (w_each[theirs, None] * each[theirs]).sum(0), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose((weights[mine, None] * normals[mine]).sum(0),
                                   (w_each[theirs, None] * n_each[theirs]).sum(0), rtol=1e-12, atol=1e-15)


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))  # proper: orientation kept


def _area_normal(facet: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cross = np.cross(facet[1] - facet[0], facet[2] - facet[0])
    return np.array([0.5 * np.linalg.norm(cross)]), (cross / np.linalg.norm(cross))[None]


def test_segment_rule_lengths_normals_and_degree():
    square = polygon_surface_2d(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]))
    points, weights, normals = surface_quadrature(square.vertices[square.faces], spacing=0.3)
    assert weights.sum() == pytest.approx(6.0, rel=1e-14)
    np.testing.assert_allclose((weights[:, None] * normals).sum(axis=0), 0.0, atol=1e-14)
    assert (weights * np.einsum("qi,qi->q", points, normals)).sum() == pytest.approx(2 * 2.0, rel=1e-14)
    bottom = points[:, 1] == 0.0
    np.testing.assert_allclose(normals[bottom], np.broadcast_to([0.0, -1.0], normals[bottom].shape))
    assert weights[bottom].max() == pytest.approx(4 / 9 * 2.0 / 16, rel=1e-14)  # 2 m halved to <= h/2
    seg = np.array([[[0.0, 0.0], [1.0, 0.0]]])
    points, weights, _ = surface_quadrature(seg, 10.0)
    assert (weights * points[:, 0] ** 5).sum() == pytest.approx(1 / 6, rel=1e-14)


@pytest.mark.parametrize("d", [2, 3])
def test_surface_loads_are_the_transpose_of_the_stencil(d, rng):
    grid = GRIDS[d]
    samples, u = affine_field(grid, rng)
    points = interior_points(grid, rng, 300)
    weights = rng.random(300) * 0.01
    tractions = rng.normal(size=(300, d)) * 1e3
    loads = surface_loads(grid, points, weights, tractions)
    work = sum((f * samples[a][tuple(index.T)]).sum() for a, (index, f) in enumerate(loads))
    direct = (weights * np.einsum("qi,qi->q", tractions, u(points))).sum()
    assert work == pytest.approx(direct, rel=1e-12)
    for index, f in loads:
        assert len(np.unique(index, axis=0)) == len(index) < 300 * 2**d  # shared samples are summed
    constant = np.broadcast_to(rng.normal(size=d), (300, d))
    for a, (_, f) in enumerate(surface_loads(grid, points, weights, constant)):
        assert f.sum() == pytest.approx(constant[0, a] * weights.sum(), rel=1e-13)


@pytest.mark.parametrize("d", [2, 3])
def test_masked_surface_loads_are_the_transpose_of_interpolate(d, rng):
    grid = GRIDS[d]
    box = tuple(np.asarray(grid.shape) + 1)
    samples, _ = affine_field(grid, rng)
    masks = [rng.random(box) < 0.7 for _ in range(d)]
    points = interior_points(grid, rng, 300)
    weights, tractions = rng.random(300), rng.normal(size=(300, d))
    u_h = interpolate(grid, points, dense_lookup(samples, masks))
    carried = ~np.isnan(u_h).any(axis=1)
    points, weights, tractions, u_h = points[carried], weights[carried], tractions[carried], u_h[carried]
    loads = surface_loads(grid, points, weights, tractions, lambda a, index: masks[a][tuple(index.T)])
    for a, (index, f) in enumerate(loads):
        assert masks[a][tuple(index.T)].all()
        assert f.sum() == pytest.approx((weights * tractions[:, a]).sum(), rel=1e-12)  # no force lost
    work = sum((f * samples[a][tuple(index.T)]).sum() for a, (index, f) in enumerate(loads))
    assert work == pytest.approx((weights * np.einsum("qi,qi->q", tractions, u_h)).sum(), rel=1e-12)
    nothing = [np.zeros(box, bool)] * d
    with pytest.raises(VoxelasticError, match="rim load: 1 surface quadrature points"):
        inactive = lambda a, i: nothing[a][tuple(i.T)]  # noqa: E731
        surface_loads(grid, points[:1], weights[:1], tractions[:1], inactive, name="rim load")


def resultant(grid, loads):
    """Net force [d] [N] and moment [pairs] [N m] (about the origin, planes (k, l), k < l) of
    per-component sample loads, each force acting at its sample."""
    d = grid.dim
    force = np.array([f.sum() for _, f in loads])
    first = np.array([[(f * grid.sample_points(i, np.eye(d)[a])[:, b]).sum() for b in range(d)]
                      for a, (i, f) in enumerate(loads)])  # first[a, b] = sum f_a x_b
    return force, np.array([first[l, k] - first[k, l] for k, l in itertools.combinations(range(d), 2)])


def quadrature_resultant(points, weights, tractions):
    """The same of the quadrature's point forces."""
    d = points.shape[1]
    f = weights[:, None] * tractions
    first = f.T @ points
    return f.sum(axis=0), np.array([first[l, k] - first[k, l] for k, l in itertools.combinations(range(d), 2)])


def activity(surface, grid):
    """active(a, index [M, d]) -> bool [M] of the staggered method on ``surface``: a face sample is
    active where a cell on either side holds solid."""
    from engine.geometry.fractions import volume_fractions

    d = grid.dim
    solid = np.zeros(tuple(np.asarray(grid.shape) + 2), dtype=bool)  # empty cells beyond either end
    solid[tuple(slice(1, n + 1) for n in grid.shape)] = volume_fractions(surface, grid).dense() > 0
    # face I of component a lies between cells I - e_a and I (shifted by one here)
    box = tuple(slice(1, n + 2) for n in grid.shape)
    dense = [solid[box] | solid[tuple(slice(0, n + 1) if k == a else slice(1, n + 2) for k, n in enumerate(grid.shape))]
             for a in range(d)]
    return lambda a, index: dense[a][tuple(index.T)]


def rotated_bodies(d):
    """Two boxes (3D) / rectangles (2D) rotated off the grid axes, apart: (grid, surface)."""
    pieces = []
    for shift in (0.0, 1.1):
        if d == 3:
            mesh = trimesh.creation.box(bounds=[[0, 0, 0], [0.9, 0.4, 0.3]])
            mesh.apply_transform(trimesh.transformations.rotation_matrix(0.5, [1, 2, 3]))
            mesh.apply_translation([0.43 + shift, 0.31, 0.27])
            pieces.append(mesh)
        else:
            c, s_ = math.cos(0.5), math.sin(0.5)
            pieces.append(np.array([[0, 0], [0.9, 0], [0.9, 0.4], [0, 0.4]]) @ np.array([[c, s_], [-s_, c]])
                          + [0.43 + shift, 0.31])
    surface = surface_of(trimesh.util.concatenate(pieces)) if d == 3 else polygon_surface_2d(*pieces)
    return Grid(origin=(-0.5,) * d, spacing=0.1, shape=(33,) + (22,) * (d - 1)), surface


@pytest.mark.parametrize("d", [2, 3])
def test_loads_on_free_rotated_bodies_keep_the_quadratures_force_and_moment(d):
    grid, surface = rotated_bodies(d)
    active = activity(surface, grid)
    split = 1.0  # the bodies lie on either side of x = 1.0

    def bodies(a, index):
        return np.where(active(a, index), 1 + (grid.sample_points(index, np.eye(d)[a])[:, 0] > split), 0)

    # pressure -1 Pa: the traction is the unit outward normal
    points, weights, normals = boundary_tractions(surface, Ball(np.full(d, 0.5), 10.0), grid.spacing, pressure=-1.0,
                                                  name="all")
    rng = np.random.default_rng(5)
    tractions = rng.normal(size=(len(points), d)) * 1e3 + points @ rng.normal(size=(d, d)) * 1e3
    scale = np.abs(weights[:, None] * tractions).sum()  # [N]; the bodies lie within 2 m of the origin
    for body in (points[:, 0] <= split, points[:, 0] > split):
        want_force, want_moment = quadrature_resultant(points[body], weights[body], tractions[body])
        # renormalising over the active samples keeps the force, not the moment ...
        plain = surface_loads(grid, points[body], weights[body], tractions[body], active)
        force, moment = resultant(grid, plain)
        np.testing.assert_allclose(force, want_force, rtol=0, atol=1e-12 * scale)
        assert np.abs(moment - want_moment).max() > 1e-4 * scale * grid.spacing
        # ... the couple on a free body restores it, each body's for itself
        loads = surface_loads(grid, points, weights, np.where(body[:, None], tractions, 0.0), active, bodies=bodies)
        force, moment = resultant(grid, loads)
        np.testing.assert_allclose(force, want_force, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(moment, want_moment, rtol=0, atol=2e-12 * scale)
        for a, (index, f) in enumerate(loads):
            assert active(a, index).all()
    # balanced on the surface (a pressure all around), balanced on the samples
    loads = surface_loads(grid, points, weights, -2.5e3 * normals, active, bodies=bodies)
    force, moment = resultant(grid, loads)
    total = 2.5e3 * weights.sum()
    assert np.abs(force).max() < 1e-12 * total and np.abs(moment).max() < 2e-12 * total


@pytest.mark.parametrize("d", [2, 3])
def test_the_torque_couple_is_the_least_forces_with_that_torque_and_no_net_force(d):
    rng = np.random.default_rng(11)
    rooms = [(rng.integers(-4, 5, size=(n, d)).astype(float), rng.uniform(0.1, 2.0, n)) for n in (30, 0, 25)[:d]]
    t = rng.normal(size=(d, d))
    torque = t - t.T
    forces = _torque_couple(rooms, torque)
    pairs = list(itertools.combinations(range(d), 2))
    for f, (x, room) in zip(forces, rooms):
        assert f.shape == room.shape and abs(f.sum()) < 1e-12 * np.abs(torque).max()
    got = [(forces[a] * rooms[a][0][:, b]).sum() - (forces[b] * rooms[b][0][:, a]).sum() for a, b in pairs]
    np.testing.assert_allclose(got, [-torque[a, b] for a, b in pairs], atol=1e-12 * np.abs(torque).max())
    # the same constraints solved as a weighted least-norm problem over all the forces at once
    offsets = np.cumsum([0] + [len(r) for _, r in rooms])
    rows = []
    for a in range(d):  # no net force per component
        row = np.zeros(offsets[-1])
        row[offsets[a]:offsets[a + 1]] = 1.0
        rows.append(row)
    for a, b in pairs:
        row = np.zeros(offsets[-1])
        row[offsets[a]:offsets[a + 1]] = rooms[a][0][:, b]
        row[offsets[b]:offsets[b + 1]] = -rooms[b][0][:, a]
        rows.append(row)
    c = np.array(rows)
    w = np.concatenate([r for _, r in rooms])
    want = np.concatenate([np.zeros(d), [-torque[a, b] for a, b in pairs]])
    least = w * (c.T @ np.linalg.lstsq((c * w) @ c.T, want, rcond=None)[0])
    np.testing.assert_allclose(np.concatenate(forces), least, atol=1e-10 * np.abs(least).max())


def test_a_symmetric_load_on_a_grid_aligned_face_gets_no_couple():
    # faces on grid planes, a uniform pull on a whole end face: the renormalised weights already
    # give the exact moment, so the loads are those of a body that is held (T times each sample's
    # control-volume face area, which the operator turns into exactly uniform stress). 0.4 x 0.2:
    # the quadrature's pieces have their edges on the samples' lattice lines, so the rule
    # integrates the stencil exactly.
    grid = Grid(origin=(-0.2, -0.2, -0.2), spacing=0.1, shape=(11, 8, 7))
    surface = surface_of(trimesh.creation.box(bounds=[[0.0, 0.0, 0.0], [0.6, 0.4, 0.2]]))
    active = activity(surface, grid)
    end = Halfspaces(np.array([[-1.0, 0.0, 0.0]]), np.array([-0.6]))  # x >= 0.6: side faces meet it in zero area
    points, weights, t = boundary_tractions(surface, end, grid.spacing, traction=[50.0, 0.0, 0.0], name="pull")
    bodies = lambda a, index: active(a, index).astype(np.int64)  # noqa: E731
    (index, f), *_ = surface_loads(grid, points, weights, t, active, bodies=bodies)
    (held_index, held_f), *_ = surface_loads(grid, points, weights, t, active)
    np.testing.assert_array_equal(index, held_index)
    np.testing.assert_array_equal(f, held_f)
    face = index[:, 0] == 8  # x = 0.6
    assert face.sum() == 4 * 2
    np.testing.assert_allclose(f[face], 50.0 * 0.1 * 0.1, rtol=1e-12)
    # behind the face only round-off: (0.6 + 0.2) / 0.1 is 7.999999999999999 in floating point
    assert np.abs(f[~face]).max(initial=0.0) < 1e-12 * 50.0 * 0.4 * 0.2


def test_pressure_on_a_sphere_balances_and_on_a_cap_gives_the_projected_area():
    radius, p = 0.8, 2.5e3
    sphere = surface_of(trimesh.creation.icosphere(subdivisions=5, radius=radius))
    everything = Ball(np.zeros(3), 2.0)
    _, weights, t = boundary_tractions(sphere, everything, 0.1, pressure=p, name="all around")
    total_area = weights.sum()
    np.testing.assert_allclose((weights[:, None] * t).sum(axis=0), 0.0, atol=1e-12 * p * total_area)
    upper = Halfspaces(np.array([[0.0, 0.0, -1.0]]), np.array([0.0]))
    points, weights, t = boundary_tractions(sphere, upper, 0.1, pressure=p, name="lid")
    assert points[:, 2].min() >= 0.0
    force = (weights[:, None] * t).sum(axis=0)
    assert np.linalg.norm(force) == pytest.approx(p * math.pi * radius**2, rel=1e-3)
    assert force[2] < 0 and np.abs(force[:2]).max() < 1e-12 * p  # pushes into the upper cap
    # A constant traction sums to itself times the cap's area.
    _, w2, t2 = boundary_tractions(sphere, upper, 0.1, traction=[1.0, -2.0, 3.0], name="lid")
    np.testing.assert_allclose((w2[:, None] * t2).sum(axis=0), np.array([1.0, -2.0, 3.0]) * weights.sum(), rtol=1e-13)


def test_pressure_on_a_half_circle_in_2d():
    radius, p, n = 0.5, 7.0, 2000
    angle = 2 * np.pi * np.arange(n) / n
    circle = polygon_surface_2d(radius * np.stack([np.cos(angle), np.sin(angle)], axis=1))
    upper = Halfspaces(np.array([[0.0, -1.0]]), np.array([0.0]))
    _, weights, t = boundary_tractions(circle, upper, 0.05, pressure=p, name="top")
    force = (weights[:, None] * t).sum(axis=0)
    assert force[1] == pytest.approx(-p * 2 * radius, rel=1e-12)  # vertices at +-r: chord exactly 2r
    assert abs(force[0]) < 1e-12


def test_stress_loads_obey_the_divergence_theorem():
    # sigma(x) = x_0 I has div sigma = e_0, so the closed-surface integral of sigma n is volume * e_0.
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.3)
    ball = surface_of(mesh)
    stress = lambda x: x[:, 0, None, None] * np.eye(3)  # noqa: E731
    _, weights, t = boundary_tractions(ball, Ball(np.zeros(3), 5.0), 0.2, stress=stress, name="manufactured")
    np.testing.assert_allclose((weights[:, None] * t).sum(axis=0), [mesh.volume, 0.0, 0.0], atol=1e-12)
    points, weights, t_callable = boundary_tractions(
        ball, Ball(np.zeros(3), 5.0), 0.2, traction=lambda x: x[:, 0, None] * np.array([1.0, 0.0, 0.0]), name="x"
    )
    np.testing.assert_allclose(t_callable[:, 0], points[:, 0])
    sigma = np.array([[1.0, 2.0, 0.0], [2.0, -1.0, 0.5], [0.0, 0.5, 3.0]])
    _, _, t_const = boundary_tractions(ball, Ball(np.zeros(3), 5.0), 0.2, stress=sigma, name="const")
    _, _, normals = surface_quadrature(ball.vertices[ball.faces], 0.2)
    np.testing.assert_allclose(t_const, normals @ sigma.T, atol=1e-15)
    _, _, t_p = boundary_tractions(ball, Ball(np.zeros(3), 5.0), 0.2, pressure=4.0, name="p")
    np.testing.assert_allclose(t_p, -4.0 * normals, atol=1e-15)


def test_boundary_conditions_that_select_nothing_or_are_ambiguous_are_errors():
    sphere = surface_of(trimesh.creation.icosphere(subdivisions=1))
    far = Ball(np.array([10.0, 0.0, 0.0]), 0.5)
    with pytest.raises(VoxelasticError, match="clamp plate: the region holds no part of the mesh surface"):
        boundary_tractions(sphere, far, 0.1, pressure=1.0, name="clamp plate")
    with pytest.raises(ValueError, match="push: give exactly one of traction, pressure or stress"):
        boundary_tractions(sphere, far, 0.1, pressure=1.0, traction=[0, 0, 1], name="push")
    with pytest.raises(ValueError, match="push.traction: expected"):
        boundary_tractions(sphere, Ball(np.zeros(3), 5.0), 0.1, traction=[0, 1], name="push")


def test_centroid_rule_has_one_point_per_piece_and_exact_first_moments():
    # the divergence form's gap spreads a uniform traction with it (elasticity._divergence_gap)
    tri = np.array([[[0.3, -0.2, 1.0], [1.7, 0.4, 0.2], [-0.5, 1.1, 0.6]]])
    points, weights, normals = surface_quadrature(tri, 0.4, centroids=True)
    full, full_w, _ = surface_quadrature(tri, 0.4)
    assert len(full) == 7 * len(points) and len(points) > 1  # the same subdivided pieces
    assert weights.sum() == pytest.approx(full_w.sum(), rel=1e-14)
    np.testing.assert_allclose(weights @ points, full_w @ full, rtol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=0, atol=1e-14)
    assert (weights * points[:, 0] ** 2).sum() != pytest.approx((full_w * full[:, 0] ** 2).sum(), rel=1e-6)
