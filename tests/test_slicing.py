"""Hex slicing for DG: exact pieces, interfaces and boundary of solids cut by the grid."""

from __future__ import annotations

import itertools
import subprocess
import sys

import manifold3d
import numpy as np
import pytest
import trimesh

from engine.errors import GeometryError
from engine.geometry import bisection
from engine.geometry.moments import (
    box_moments,
    cell_face_moments,
    cell_moments,
    interval_moments,
    monomial_exponents,
    shift_moments,
    volume_moments,
)
from engine.geometry.slicing import CutCells, slice_cells
from engine.geometry.surface import Surface
from engine.grid import Grid, make_grid

DEGREE = 4


def _surface(solid) -> Surface:
    if isinstance(solid, manifold3d.Manifold):
        mesh = solid.to_mesh64()
        return Surface(np.array(mesh.vert_properties[:, :3]), np.array(mesh.tri_verts, dtype=np.int64))
    return Surface(np.asarray(solid.vertices, dtype=float), np.asarray(solid.faces, dtype=np.int64))


def _box(lower, upper) -> manifold3d.Manifold:
    lower = np.asarray(lower, dtype=float)
    return manifold3d.Manifold.cube(np.asarray(upper, dtype=float) - lower).translate(lower)


def _boundary_area(cut: CutCells) -> float:
    t = cut.boundary_triangles
    return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


def _check_invariants(cut: CutCells) -> None:
    assert cut.exponents.shape == (35, 3) and cut.moments.shape == (cut.num_pieces, 35)
    assert np.all(np.diff(cut.boundary_piece) >= 0)
    assert np.all(cut.face_area > 0) and np.all(cut.volume > 0)
    np.testing.assert_allclose(cut.volume, cut.moments[:, 0] * cut.grid.spacing**3, rtol=1e-15)
    assert np.all(cut.moments[cut.full] == cell_moments(DEGREE))
    # Interfaces join face neighbours: the plus piece's cell is the minus piece's cell + e_axis.
    step = cut.piece_cell[cut.face_plus] - cut.piece_cell[cut.face_minus]
    np.testing.assert_array_equal(step, np.eye(3, dtype=int)[cut.face_axis])
    assert cut.closure_error() < 1e-12


def test_box_in_general_position_gives_exact_pieces():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(6, 5, 4))
    lower, upper = np.array([0.3, 1.2, 0.5]), np.array([4.6, 3.5, 2.25])
    cut = slice_cells(_surface(_box(lower, upper)), grid, DEGREE)
    _check_invariants(cut)
    ranges = [range(int(np.floor(lower[a])), int(np.ceil(upper[a]))) for a in range(3)]
    cells = list(itertools.product(*ranges))
    assert cut.num_pieces == len(cells) == 5 * 3 * 3
    assert cut.warnings == []
    for p, cell in enumerate(cells):  # C order, as the pieces are sorted by linear cell index
        assert tuple(cut.piece_cell[p]) == cell
        lo = np.maximum(lower, cell) - (np.asarray(cell) + 0.5)
        hi = np.minimum(upper, np.asarray(cell) + 1) - (np.asarray(cell) + 0.5)
        ref = box_moments(lo, hi, DEGREE)
        assert cut.full[p] == bool(np.all(hi - lo == 1.0))
        np.testing.assert_allclose(cut.moments[p], ref, rtol=0, atol=1e-13)
        assert cut.volume[p] == pytest.approx(np.prod(hi - lo), rel=1e-13)
    assert cut.full.sum() == 3 * 1 * 1
    assert _boundary_area(cut) == pytest.approx(2 * (4.3 * 2.3 + 4.3 * 1.75 + 2.3 * 1.75), rel=1e-13)
    # Interfaces: 4 x-planes x 3 x 3 + 5 x 2 x 3 + 5 x 3 x 2 cell faces, areas = overlap rectangles.
    assert cut.num_faces == 4 * 9 + 2 * 15 + 2 * 15
    full_full = cut.full[cut.face_minus] & cut.full[cut.face_plus]
    assert full_full.sum() == 2 and np.all(cut.face_area[full_full] == 1.0)
    np.testing.assert_array_equal(cut.face_moments[full_full], cell_face_moments(DEGREE)[cut.face_axis[full_full]])
    x_faces = cut.face_axis == 0
    assert cut.face_area[x_faces].sum() == pytest.approx(4 * 2.3 * 1.75, rel=1e-13)


def test_icosphere_pieces_sum_to_the_mesh():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    surface = _surface(sphere)
    mesh_volume = sphere.volume
    for n, origin in ((8, (-1.07, -1.11, -1.13)), (13, (-1.2, -1.05, -1.17))):
        h = 2.3 / n
        grid = Grid(origin=origin, spacing=h, shape=(n, n, n))
        stats: dict = {}
        cut = slice_cells(surface, grid, DEGREE, stats=stats)
        _check_invariants(cut)
        assert cut.warnings == [] and stats["faces_resolved_2d"] == 0  # both sides matched directly
        assert abs(cut.volume.sum() / mesh_volume - 1) < 1e-12
        # Moments of all pieces, moved to one centre, equal the whole mesh's moments there.
        centre = np.array([0.1, -0.2, 0.05])
        moved = shift_moments(cut.moments, DEGREE, (centre - cut.piece_centers()) / h).sum(axis=0)
        whole = volume_moments(sphere.vertices, sphere.faces, DEGREE, centre, h)
        np.testing.assert_allclose(moved, whole, rtol=0, atol=1e-10 * np.abs(whole).max())
        assert _boundary_area(cut) == pytest.approx(sphere.area, rel=1e-12)
        full_full = cut.full[cut.face_minus] & cut.full[cut.face_plus]
        assert full_full.any() and np.all(cut.face_area[full_full] == h**2)
        # Every grid face inside the sphere is an interface: a full cell has 6 neighbours.
        neighbours = np.bincount(np.r_[cut.face_minus, cut.face_plus], minlength=cut.num_pieces)
        assert np.all(neighbours[cut.full] == 6)
        assert not np.any(np.isin(np.flatnonzero(cut.full), cut.boundary_piece))


def test_two_thin_plates_in_one_cell_row_stay_apart():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(6, 6, 5))
    # Both plates lie in the cell layer z in [2, 3], 0.3 h apart, across a 4 x 4 block of cells.
    lower_plate, upper_plate = _box([1.25, 1.25, 2.1], [4.75, 4.75, 2.3]), _box([1.25, 1.25, 2.6], [4.75, 4.75, 2.8])
    stats: dict = {}
    cut = slice_cells(_surface(lower_plate + upper_plate), grid, DEGREE, stats=stats)
    _check_invariants(cut)
    assert stats["faces_resolved_2d"] == 0  # two components per side, paired by their moments
    assert cut.num_pieces == 2 * 16 and not cut.full.any()
    counts = np.unique(grid.linear_index(cut.piece_cell), return_counts=True)[1]
    assert np.all(counts == 2)
    z_centroid = cut.moments[:, 3] / cut.moments[:, 0]  # xi_z of each piece's centroid
    upper = z_centroid > 0
    assert upper.sum() == 16
    # Interfaces only along each plate (x and y faces), never across the 0.3 h gap.
    assert np.all(upper[cut.face_minus] == upper[cut.face_plus]) and not np.any(cut.face_axis == 2)
    assert cut.num_faces == 2 * (3 * 4 + 4 * 3)
    np.testing.assert_allclose(np.sort(np.unique(np.round(cut.face_area, 12))), [0.15, 0.2])
    assert cut.volume.sum() == pytest.approx(2 * 3.5 * 3.5 * 0.2, rel=1e-13)


def test_box_on_grid_planes_exposes_full_cell_faces():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=0.5, shape=(6, 6, 6))
    cut = slice_cells(_surface(_box([0.5, 0.5, 1.0], [2.0, 1.5, 1.5])), grid, DEGREE)
    _check_invariants(cut)
    assert cut.num_pieces == 3 * 2 * 1 and cut.full.all() and cut.warnings == []
    assert cut.num_faces == 2 * 2 + 3 * 1
    assert _boundary_area(cut) == pytest.approx(2 * (1.5 * 1.0 + 1.5 * 0.5 + 1.0 * 0.5), rel=1e-14)
    assert len(cut.boundary_triangles) == 2 * (2 * 3 + 2 * 6 + 2 * 2)  # two triangles per exposed cell face


def test_round_off_slivers_of_a_cube_on_grid_planes_are_dropped_without_a_warning():
    """A unit cube whose faces lie on grid planes leaves pieces of round-off (8 since the cut runs in
    cell units, 13 of 5.4e-18 m^3 in all before); they used to be a warning, "dropped 13 sliver pieces
    below 1e-12 h^3", that asked nothing of anyone."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    box.apply_translation((0.5, 0.5, 0.5))
    grid = make_grid(np.zeros(3), np.ones(3), resolution=6, padding=1)  # as a job's grid.resolution 6 makes it
    h = grid.spacing
    stats = {}
    cut = slice_cells(_surface(box), grid, DEGREE, stats=stats)
    assert cut.warnings == []
    assert stats["dropped"] == 8 and 0 < stats["dropped_volume"] < 8e-12 * h**3
    assert cut.volume.sum() == pytest.approx(1.0, rel=1e-14)


def test_surface_partly_in_a_grid_plane_splits_the_face():
    # An L-shaped solid: the top of the lower slab (z = 2) is a grid plane; over x in [1.7, 3.5]
    # it is surface, over x in [0.5, 1.7] it is shared with the upper block.
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(5, 5, 5))
    solid = _box([0.5, 0.5, 1.0], [3.5, 3.5, 2.0]) + _box([0.5, 0.5, 2.0], [1.7, 3.5, 3.0])
    stats: dict = {}
    cut = slice_cells(_surface(solid), grid, DEGREE, stats=stats)
    _check_invariants(cut)
    assert stats["faces_resolved_2d"] == 4  # z = 2 above cells x = 1, y = 0..3: part interface, part surface
    assert cut.volume.sum() == pytest.approx(3 * 3 * 1 + 1.2 * 3 * 1, rel=1e-13)
    assert _boundary_area(cut) == pytest.approx(solid.surface_area(), rel=1e-13)
    assert cut.full.sum() == 4  # cells (1..2, 1..2, 1) of the slab
    z_faces = cut.face_axis == 2
    assert cut.face_area[z_faces].sum() == pytest.approx(1.2 * 3, rel=1e-13)
    # The z-interface above full cell (1, 1, 1) covers x in [1, 1.7]: area 0.7, xi_x in [-1/2, 0.2].
    above = z_faces & np.all(cut.piece_cell[cut.face_minus] == [1, 1, 1], axis=1)
    assert above.sum() == 1
    assert cut.face_area[above][0] == pytest.approx(0.7, rel=1e-13)
    exps = cut.exponents
    mx, my = interval_moments(-0.5, 0.2, DEGREE), interval_moments(-0.5, 0.5, DEGREE)
    ref = mx[exps[:, 0]] * my[exps[:, 1]] * 0.5 ** exps[:, 2]
    np.testing.assert_allclose(cut.face_moments[above][0], ref, rtol=0, atol=1e-13)
    surface_of_full = np.isin(cut.boundary_piece, np.flatnonzero(cut.full))
    assert surface_of_full.any()


def test_void_inside_one_cell_stays_with_its_piece():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(6, 6, 6))
    void = manifold3d.Manifold.sphere(0.3, 24).translate([2.5, 2.5, 2.5])
    solid = _box([1, 1, 1], [5, 5, 5]) - void
    cut = slice_cells(_surface(solid), grid, DEGREE)
    _check_invariants(cut)
    assert cut.num_pieces == 64 and cut.full.sum() == 63
    holed = np.flatnonzero(~cut.full)
    assert tuple(cut.piece_cell[holed[0]]) == (2, 2, 2)
    assert cut.volume[holed[0]] == pytest.approx(1 - void.volume(), rel=1e-13)
    assert _boundary_area(cut) == pytest.approx(solid.surface_area(), rel=1e-13)


def test_hollow_sphere_inner_shell_bounds_the_pieces():
    outer = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=2, radius=0.55)
    vertices = np.concatenate([outer.vertices, inner.vertices])
    faces = np.concatenate([outer.faces, inner.faces[:, ::-1] + len(outer.vertices)])  # inner faces inward
    grid = Grid(origin=(-1.1, -1.1, -1.1), spacing=0.22, shape=(10, 10, 10))
    cut = slice_cells(Surface(vertices, faces), grid, DEGREE)
    _check_invariants(cut)
    assert abs(cut.volume.sum() / (outer.volume - inner.volume) - 1) < 1e-12
    assert _boundary_area(cut) == pytest.approx(outer.area + inner.area, rel=1e-12)
    centres = cut.piece_centers()
    assert not np.any(cut.full & (np.linalg.norm(centres, axis=1) < 0.55 - 0.22 * np.sqrt(3) / 2))


def test_two_bodies_in_one_cell_are_two_pieces():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(3, 3, 3))
    a = manifold3d.Manifold.sphere(0.2, 16).translate([1.3, 1.3, 1.3])
    b = manifold3d.Manifold.sphere(0.15, 16).translate([1.7, 1.7, 1.7])
    cut = slice_cells(_surface(a + b), grid, DEGREE)
    _check_invariants(cut)
    assert cut.num_pieces == 2 and cut.num_faces == 0
    np.testing.assert_array_equal(cut.piece_cell, [[1, 1, 1], [1, 1, 1]])
    np.testing.assert_allclose(cut.volume, [a.volume(), b.volume()], rtol=1e-13)  # largest first


def test_translating_a_box_keeps_its_volume():
    grid = Grid(origin=(-1.0, -1.0, -1.0), spacing=0.25, shape=(12, 12, 12))
    for shift in ((0.0, 0.0, 0.0), (0.01, 0.13, 0.07), (0.125, 0.2, 0.249), (1 / 3, 1 / 7, 1 / 11)):
        solid = _box([-0.61, -0.43, -0.52], [0.57, 0.34, 0.46]).translate(shift)
        cut = slice_cells(_surface(solid), grid, DEGREE)
        assert abs(cut.volume.sum() / (1.18 * 0.77 * 0.98) - 1) < 1e-12
        assert cut.closure_error() < 1e-12


def test_surface_outside_the_grid_is_clipped_with_a_warning():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(3, 3, 3))
    cut = slice_cells(_surface(_box([1.5, 1.5, 1.5], [3.5, 2.5, 2.5])), grid, DEGREE)
    assert cut.volume.sum() == pytest.approx(1.5, rel=1e-13)
    assert cut.warnings == ["the surface extends outside the grid; 25% of its volume outside the grid box was dropped"]
    assert cut.closure_error() < 1e-12  # the cut at the grid's edge is boundary


_FIELDS = ("piece_cell", "full", "volume", "moments", "face_minus", "face_plus", "face_axis", "face_area",
           "face_moments", "boundary_piece", "boundary_triangles")


def _assert_identical(a: CutCells, b: CutCells) -> None:
    for name in _FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_parallel_workers_give_the_same_pieces_bit_for_bit():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    grid = Grid(origin=(-1.1, -1.1, -1.1), spacing=0.2, shape=(11, 11, 11))
    serial = slice_cells(_surface(sphere), grid, DEGREE, workers=1)
    stats: dict = {}
    parallel = slice_cells(_surface(sphere), grid, DEGREE, workers=2, stats=stats)
    assert stats["workers"] == 2
    _assert_identical(parallel, serial)


def test_work_stealing_in_small_batches_gives_the_same_pieces(monkeypatch):
    # The first cut (at the vertices' mean) passes through the dense little sphere, so the worker
    # with the box has far more to cut: the other one runs dry early and takes parts from it.
    monkeypatch.setattr(bisection, "DIGEST_TRIANGLES", 400)  # many small digests too
    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    solid = _box([0.1, 0.2, 0.15], [2.1, 1.9, 1.85]) + manifold3d.Manifold(manifold3d.Mesh64(
        vert_properties=np.asarray(ball.vertices + [3.0, 1.0, 1.0]), tri_verts=np.asarray(ball.faces, dtype=np.uint64)))
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=0.125, shape=(32, 16, 16))
    procs = bisection.start_workers(2)
    try:
        digests, info = bisection.bisect_pieces(solid, grid, DEGREE, 1e-12, procs)
    finally:
        bisection.stop_workers(procs)
    assert info["workers"] == 2 and info["parts_moved"] >= 1 and len(digests) > 10
    serial = slice_cells(_surface(solid), grid, DEGREE, workers=1)
    _check_invariants(serial)
    assert abs(serial.volume.sum() / solid.volume() - 1) < 1e-12
    _assert_identical(slice_cells(_surface(solid), grid, DEGREE, workers=2), serial)


def test_a_failing_worker_leaves_the_bisection_to_the_caller(monkeypatch):
    def dying_workers(count):  # interpreters that exit at once: their pipes break
        return [subprocess.Popen([sys.executable, "-c", "import sys; sys.exit(3)"], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE) for _ in range(count)]

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    grid = Grid(origin=(-1.1, -1.1, -1.1), spacing=0.4, shape=(6, 6, 6))
    serial = slice_cells(_surface(sphere), grid, DEGREE, workers=1)
    monkeypatch.setattr("engine.geometry.slicing.start_workers", dying_workers)
    stats: dict = {}
    cut = slice_cells(_surface(sphere), grid, DEGREE, workers=2, stats=stats)
    assert stats["workers"] == 1
    _assert_identical(cut, serial)


def test_digest_of_a_half_cell():
    # The lower half of cell (1, 0, 2): five faces on the cell's planes, the top one is surface.
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=0.5, shape=(3, 3, 3))
    half = _box([0.5, 0.0, 1.0], [1.0, 0.5, 1.25])
    mesh = half.to_mesh64()
    cut = bisection._Cut()
    cut.cells.append((1, 0, 2))
    cut.meshes.append((np.array(mesh.vert_properties[:, :3]), np.array(mesh.tri_verts, dtype=np.int64)))
    d = bisection.digest(cut, grid, DEGREE)
    np.testing.assert_allclose(d["moments"][0], box_moments([-0.5, -0.5, -0.5], [0.5, 0.5, 0.0], DEGREE),
                               rtol=0, atol=1e-15)
    assert sorted(d["comp_kind"]) == [0, 1, 2, 3, 4]  # x low/high, y low/high, z low
    assert np.all(d["comp_piece"] == 0) and len(d["plane_comp"]) == 10 and len(d["surf_piece"]) == 2
    np.testing.assert_allclose(d["surf_xyz"][:, :, 2], 1.25)
    mx = interval_moments(-0.5, 0.5, DEGREE)
    exps = monomial_exponents(3, DEGREE)
    z_low = d["comp_moments"][list(d["comp_kind"]).index(4)]
    np.testing.assert_allclose(z_low, mx[exps[:, 0]] * mx[exps[:, 1]] * (-0.5) ** exps[:, 2], rtol=0, atol=1e-15)


def test_edge_components_join_triangles_sharing_an_edge_within_a_group():
    # 0-1 share edge (1, 2); 2 shares edge (1, 2) too but is in another group; 3 touches 0 at a
    # vertex only; 4 shares edge (3, 5) with 3.
    vid = np.array([[0, 1, 2], [2, 1, 4], [1, 2, 9], [0, 3, 5], [5, 3, 7]])
    group = np.array([0, 0, 1, 0, 0])
    np.testing.assert_array_equal(bisection._edge_components(vid, group), [0, 0, 1, 2, 2])
    chain = np.array([[i, i + 1, i + 2] for i in range(200)])[::-1]  # a strip, numbered backwards
    np.testing.assert_array_equal(bisection._edge_components(chain, np.zeros(200, int)), np.zeros(200))


def test_bad_surfaces_are_reported():
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=1.0, shape=(3, 3, 3))
    box = trimesh.creation.box(bounds=[[0.5, 0.5, 0.5], [2.5, 2.5, 2.5]])
    open_box = Surface(np.asarray(box.vertices), np.asarray(box.faces), closed=False)
    with pytest.raises(GeometryError, match="the surface is not closed; hex slicing needs a watertight mesh"):
        slice_cells(open_box, grid)
    holed = Surface(np.asarray(box.vertices), np.asarray(box.faces[:-1]))
    with pytest.raises(GeometryError, match=r"not an oriented 2-manifold \(manifold3d: NotManifold\)"):
        slice_cells(holed, grid)
    inverted = Surface(np.asarray(box.vertices), np.asarray(box.faces[:, ::-1]))
    with pytest.raises(GeometryError, match="encloses no volume .* is it inside out"):
        slice_cells(inverted, grid)
    with pytest.raises(GeometryError, match=r"face vertex indices must be integers in \[0, 8\)"):
        slice_cells(Surface(np.asarray(box.vertices), np.asarray(box.faces) + 1), grid)
    with pytest.raises(GeometryError, match="needs a 3D grid, got a 2D grid"):
        slice_cells(_surface(box), Grid(origin=(0.0, 0.0), spacing=1.0, shape=(3, 3)))
    with pytest.raises(GeometryError, match="degree must be an integer >= 0, got -2"):
        slice_cells(_surface(box), grid, -2)


@pytest.mark.parametrize("size", [1e-11, 1e-30, 1e30])
def test_a_part_of_any_size_slices_into_the_same_pieces(size):
    # manifold3d's splits lose solids of about 1e-12 in size: a 1e-11 m part came out with no
    # piece at all (and the DG setup raised an IndexError); the cut now runs in cell units
    box = trimesh.creation.box(extents=(1.0, 0.5, 0.25))
    unit = slice_cells(_surface(box), make_grid(*box.bounds, resolution=6, padding=1), DEGREE)
    box.apply_scale(size)
    cut = slice_cells(_surface(box), make_grid(*box.bounds, resolution=6, padding=1), DEGREE)
    _check_invariants(cut)
    assert cut.num_pieces == unit.num_pieces and cut.num_faces == unit.num_faces
    assert cut.volume.sum() == pytest.approx(0.125 * size**3, rel=1e-12)
    np.testing.assert_allclose(cut.moments, unit.moments, atol=1e-12)
    assert _boundary_area(cut) == pytest.approx(_boundary_area(unit) * size**2, rel=1e-12)  # (its triangulation may differ)
