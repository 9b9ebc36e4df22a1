"""Exact volume fractions: totals to round-off, closed forms for boxes, sparse storage."""

import itertools

import numpy as np
import pytest
import trimesh

from engine.errors import GridError
from engine.geometry.fractions import control_offsets, volume_fractions
from engine.grid import Grid, make_grid
from tests.conftest import polygon_surface_2d, surface_of


def shell_surface(outer=1.0, inner=0.55):
    a = trimesh.creation.icosphere(subdivisions=3, radius=outer)
    b = trimesh.creation.icosphere(subdivisions=3, radius=inner)
    b.invert()
    return surface_of(trimesh.util.concatenate([a, b]))


def rotated_box():
    m = trimesh.creation.box(extents=[1.0, 0.4, 0.25])
    rot = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])
    rot[:3, 3] = [0.11, -0.07, 0.03]
    m.apply_transform(rot)
    return surface_of(m)


def torus():
    return surface_of(trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=48, minor_sections=24))


@pytest.mark.parametrize("make", [shell_surface, torus, rotated_box], ids=["shell", "torus", "rotated_box"])
@pytest.mark.parametrize("resolution", [7, 24])
def test_subcells_and_every_control_volume_sum_to_the_mesh_volume(make, resolution):
    surface = make()
    exact = surface.enclosed_volume()
    grid = make_grid(*surface.bounds, resolution=resolution, padding=1)
    vf = volume_fractions(surface, grid, keep_subcells=True)
    assert vf.warnings == []
    sub = vf.subcells.sum() * (grid.spacing / 2) ** 3
    assert abs(sub - exact) / exact < 1e-10
    # each sub-cell lies in exactly one control volume of each kind
    for s, cv in vf.control.items():
        assert abs(cv.sum() * grid.spacing**3 - exact) / exact < 1e-10, s
        dense = cv.dense()
        assert dense.shape == tuple(n + o for n, o in zip(grid.shape, s))
        assert dense.min() >= 0.0 and dense.max() <= 1.0


def overlap_1d(a, b, lo, hi):
    return np.clip(np.minimum(b, hi) - np.maximum(a, lo), 0.0, None) / (hi - lo)


def box_fractions(grid, lower, upper, offset):
    """Closed form: product over axes of the 1D overlap of [lower, upper] with each control interval."""
    factors = []
    for axis, s in enumerate(offset):
        n = grid.shape[axis] + s
        start = grid.origin[axis] + grid.spacing * (np.arange(n) - 0.5 * s)
        factors.append(overlap_1d(lower[axis], upper[axis], start, start + grid.spacing))
    out = factors[0]
    for f in factors[1:]:
        out = np.multiply.outer(out, f)
    return out


@pytest.mark.parametrize("dim", [2, 3])
def test_axis_aligned_box_gives_the_exact_fractions(dim):
    lower = np.array([0.137, -0.213, 0.051])[:dim]
    upper = np.array([0.871, 0.302, 0.447])[:dim]
    if dim == 3:
        surface = surface_of(trimesh.creation.box(bounds=[lower, upper]))
    else:
        surface = polygon_surface_2d([lower, [upper[0], lower[1]], upper, [lower[0], upper[1]]])
    grid = Grid(origin=(-0.05, -0.31, -0.02)[:dim], spacing=0.0937, shape=(11, 8, 7)[:dim])
    vf = volume_fractions(surface, grid)
    assert set(vf.control) == set(control_offsets(dim))
    for s in control_offsets(dim):
        np.testing.assert_allclose(vf.dense(s), box_fractions(grid, lower, upper, s), rtol=0, atol=1e-13)


def test_sub_cell_offsets_keep_the_total_exact():
    base = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    grid = Grid(origin=(-1.0, -1.0, -1.0), spacing=0.125, shape=(16, 16, 16))
    exact = surface_of(base).enclosed_volume()
    totals = []
    for k in range(16):
        shift = np.array([k, (7 * k) % 16, (11 * k) % 16]) / 16 * grid.spacing
        moved = surface_of(base.copy().apply_translation(shift))
        vf = volume_fractions(moved, grid, keep_subcells=True)
        totals.append(vf.subcells.sum() * (grid.spacing / 2) ** 3)
    assert np.max(np.abs(np.array(totals) - exact)) / exact < 1e-12


def test_2d_annulus_area_and_orientation():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    outer = np.stack([0.8 * np.cos(t), 0.8 * np.sin(t)], axis=1)
    inner = np.stack([0.325 * np.cos(t), 0.325 * np.sin(t)], axis=1)[::-1]  # hole: clockwise
    surface = polygon_surface_2d(outer, inner)
    exact = surface.enclosed_volume()
    grid = make_grid(*surface.bounds, resolution=64, padding=1)
    vf = volume_fractions(surface, grid, keep_subcells=True)
    assert abs(vf.subcells.sum() * (grid.spacing / 2) ** 2 - exact) / exact < 1e-12
    cells = vf.dense()
    centre = np.array(grid.shape) // 2
    assert cells[tuple(centre)] == 0.0  # inside the hole
    assert cells[centre[0] + int(0.55 / grid.spacing), centre[1]] == 1.0  # in the ring
    for s, cv in vf.control.items():
        assert abs(cv.sum() * grid.spacing**2 - exact) / exact < 1e-12, s


def test_only_tiles_touching_material_are_stored():
    surface = surface_of(trimesh.creation.icosphere(subdivisions=2, radius=0.1))
    grid = Grid(origin=(-1.0, -1.0, -1.0), spacing=0.02, shape=(100, 100, 100))
    vf = volume_fractions(surface, grid)
    cells = vf.cells
    assert len(cells.coords) <= 8  # the ball spans 10 cells: at most 2 tiles per axis
    assert cells.nbytes < 0.01 * 8 * grid.num_cells


def test_geometry_outside_the_grid_is_an_error():
    surface = surface_of(trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]]))
    grid = Grid(origin=(0.1, 0.0, 0.0), spacing=0.25, shape=(4, 4, 4))
    with pytest.raises(GridError, match="extends outside the grid"):
        volume_fractions(surface, grid)


def test_overlapping_shells_are_reported():
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[0.5, 0.25, 0.25], [1.5, 0.75, 0.75]])
    surface = surface_of(trimesh.util.concatenate([a, b]))
    grid = make_grid(*surface.bounds, cell_size=0.25)
    vf = volume_fractions(surface, grid)
    assert any("overlapping" in w for w in vf.warnings)
    # the union is still right where the overlap is cell-aligned
    assert abs(vf.solid_volume() - (1.0 + 0.25 * 0.5)) < 1e-12


def test_block_sparse_lookup_matches_dense():
    surface = rotated_box()
    grid = make_grid(*surface.bounds, resolution=20)
    vf = volume_fractions(surface, grid)
    for s in [(0, 0, 0), (1, 0, 0), (0, 1, 1)]:
        cv = vf.control[s]
        dense = cv.dense()
        idx = np.array(list(itertools.product(*[range(-1, n + 1) for n in dense.shape])))
        expect = np.zeros(len(idx))
        inside = np.all((idx >= 0) & (idx < np.array(dense.shape)), axis=1)
        expect[inside] = dense[tuple(idx[inside].T)]
        np.testing.assert_array_equal(cv.lookup(idx), expect)
        index, value = cv.nonzero()
        np.testing.assert_array_equal(dense[tuple(index.T)], value)
        assert np.count_nonzero(dense) == len(value)
