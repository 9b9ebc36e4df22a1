"""Open surfaces: volume fractions from the generalized winding number (engine.geometry.winding_fill).

Closed forms used: removing a planar piece (facet, polygon side, a flat disk) from a closed shape
leaves its solid {w >= 1/2} unchanged, since the missing piece subtends less than a half-space from
every point off its plane; a closed surface flagged open has no rim, so its fractions are the
exact scan's; removing several disjoint facets changes the solid only where their solid angles add.
"""

import re

import numpy as np
import pytest
import trimesh

from engine.errors import GeometryError
from engine.geometry.fractions import control_offsets, slab_tiles, volume_fractions
from engine.geometry.surface import Surface
from engine.geometry import winding_fill
from engine.geometry.winding import winding_number
from engine.geometry.winding_fill import _least_work, _probe, close_holes, halfspace_fraction, winding_slabs
from engine.grid import Grid, make_grid
from tests.conftest import polygon_surface_2d


def icosphere():
    m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    return np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)


def far_apart_faces(vertices, faces, count):
    """Indices of ``count`` faces sharing no vertex (disjoint, planar holes)."""
    chosen, used = [], set()
    for i in np.random.default_rng(5).permutation(len(faces)):
        if not used & set(faces[i]):
            chosen.append(i)
            used |= set(faces[i])
        if len(chosen) == count:
            break
    return np.array(chosen)


def counts(warning):
    """(linearised, sampled) sub-cell counts stated in the warning line."""
    lin = int(re.search(r"(\d+) sub-cells from the linearised", warning).group(1))
    sampled = int(re.search(r"and (\d+) sampled", warning).group(1))
    return lin, sampled


def test_winding_number_is_the_direct_sum_over_facets(rng):
    vertices, faces = icosphere()
    holes = far_apart_faces(vertices, faces, 4)
    open_faces = np.delete(faces, holes, axis=0)
    surface = Surface(vertices, open_faces, closed=False)
    closure = close_holes(surface, make_grid(*surface.bounds, resolution=20))
    near = vertices[faces[holes]].mean(axis=1)[:, None, :] * rng.uniform(0.8, 1.2, (4, 300, 1))
    points = np.concatenate([rng.uniform(-1.1, 1.1, (3000, 3)), near.reshape(-1, 3)])
    direct = winding_number(vertices, open_faces, points)
    assert np.abs(closure.winding_number(points) - direct).max() < 1e-12
    assert direct.min() < 0.2 and direct.max() > 0.8  # both sides of 1/2 are exercised

    arc = np.stack([np.cos(np.linspace(0.3, 5.5, 30)), np.sin(np.linspace(0.3, 5.5, 30))], axis=1)
    segments = np.stack([np.arange(29), np.arange(1, 30)], axis=1)
    surface_2d = Surface(arc, segments, closed=False)
    closure_2d = close_holes(surface_2d, make_grid(*surface_2d.bounds, resolution=20))
    points_2d = rng.uniform(-1.1, 1.1, (5000, 2))
    assert np.abs(closure_2d.winding_number(points_2d) - winding_number(arc, segments, points_2d)).max() < 1e-12


def test_closed_surface_flagged_open_gives_the_exact_scan():
    vertices, faces = icosphere()
    grid = make_grid(vertices.min(0), vertices.max(0), resolution=32)
    exact = volume_fractions(Surface(vertices, faces, closed=True), grid)
    flagged = volume_fractions(Surface(vertices, faces, closed=False), grid)
    assert flagged.warnings == []  # no rim: nothing approximated
    assert abs(flagged.solid_volume() - exact.solid_volume()) < 1e-12 * exact.solid_volume()
    for s in control_offsets(3):
        assert np.abs(flagged.dense(s) - exact.dense(s)).max() < 1e-12
    cells = flagged.dense()
    radius = np.linalg.norm(grid.sample_points(np.argwhere(cells >= 0)), axis=1).reshape(cells.shape)
    # deep inside: 1 up to the scan's prefix-sum round-off; outside: exactly 0
    assert np.abs(cells[radius < 0.85] - 1.0).max() < 1e-14 and np.all(cells[radius > 1.05] == 0.0)


def test_sphere_with_holes_keeps_the_sphere_volume():
    vertices, faces = icosphere()
    grid = make_grid(vertices.min(0), vertices.max(0), resolution=32)
    holes = far_apart_faces(vertices, faces, 5)
    vf = volume_fractions(Surface(vertices, np.delete(faces, holes, axis=0), closed=False), grid)
    exact = volume_fractions(Surface(vertices, faces), grid).solid_volume()
    cells = vf.dense()
    assert np.isfinite(cells).all() and cells.min() >= 0.0 and cells.max() <= 1.0
    # the solid differs from the closed sphere only where several holes' solid angles add up
    assert abs(vf.solid_volume() - exact) < 2e-4 * exact
    assert len(vf.warnings) == 1
    assert vf.warnings[0].startswith("surface is open (15 boundary edges, 5 hole(s))")
    assert "(first-order accurate, not exact)" in vf.warnings[0]
    assert counts(vf.warnings[0])[1] > 0


def test_flipped_facet_is_closed_like_a_hole():
    vertices, faces = icosphere()
    grid = make_grid(vertices.min(0), vertices.max(0), resolution=24)
    flipped = faces.copy()
    flipped[7] = flipped[7, ::-1]
    vf = volume_fractions(Surface(vertices, flipped, closed=False), grid)
    exact = volume_fractions(Surface(vertices, faces), grid).solid_volume()
    # w drops by 2 w_facet near the flipped facet: a lens of it is lost, nothing else
    assert 0 < exact - vf.solid_volume() < 1e-4 * exact
    assert vf.warnings[0].startswith("surface is open (3 boundary edges, 1 hole(s))")


@pytest.mark.parametrize("missing", [(0, 0, 1), (-1, 0, 0), (0, 1, 0)], ids=["top", "side_x", "side_y"])
def test_box_with_a_missing_face_is_the_box_exactly(missing):
    # every face on a half-integer sub-cell plane: the sampled and linearised sub-cells are exact
    # too (probe points lie on the cap, which is parallel to the scan axis for the side faces)
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=0.1, shape=(12, 12, 12))
    box = trimesh.creation.box(bounds=[[0.225, 0.275, 0.325], [0.875, 0.925, 0.875]])
    vertices, faces = np.asarray(box.vertices), np.asarray(box.faces, dtype=np.int64)
    normal = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    kept = faces[normal @ np.array(missing, dtype=float) <= 0]
    assert len(kept) == 10
    vf = volume_fractions(Surface(vertices, kept, closed=False), grid)
    exact = volume_fractions(Surface(vertices, faces), grid)
    assert abs(vf.solid_volume() - 0.65 * 0.65 * 0.55) < 1e-14
    for s in control_offsets(3):
        assert np.abs(vf.dense(s) - exact.dense(s)).max() < 1e-12
    linearised, sampled = counts(vf.warnings[0])
    assert linearised > 0 and sampled > 0  # all four paths ran


def test_square_with_a_missing_side_2d():
    grid = Grid(origin=(0.0, 0.0), spacing=0.1, shape=(12, 10))
    lo, hi = np.array([0.225, 0.175]), np.array([0.975, 0.825])  # half-integer sub-cell lines
    square = polygon_surface_2d([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    exact = volume_fractions(square, grid)
    vf = volume_fractions(Surface(square.vertices, square.faces[:3], closed=False), grid)
    assert abs(vf.solid_volume() - 0.75 * 0.65) < 1e-14
    for s in control_offsets(2):
        assert np.abs(vf.dense(s) - exact.dense(s)).max() < 1e-12
    assert vf.warnings[0].startswith("surface is open (2 boundary points, 1 hole(s))")

    # off the sub-cell lines: the cells along the open side are sampled (q = 4: 16 points each)
    shifted = Surface(square.vertices + [0.0123, 0.0071], square.faces, closed=True)
    exact = volume_fractions(shifted, grid).solid_volume()
    vf = volume_fractions(Surface(shifted.vertices, shifted.faces[:3], closed=False), grid)
    # at most half a sampling step (h / 2 / 4 / 2) of error along the open side's length
    assert abs(vf.solid_volume() - exact) <= 0.65 * 0.05 / 8
    assert abs(vf.solid_volume() - exact) > 0  # not the exact scan: it was sampled


def test_arc_is_closed_by_its_chord_2d():
    """{w >= 1/2} of a circular arc is the region between it and its chord (the chord subtends
    less than pi from every point off it); the open side runs obliquely through the sub-cells."""
    angles = np.linspace(-2.0, 2.6, 80)
    arc = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    segments = np.stack([np.arange(79), np.arange(1, 80)], axis=1)
    closed = polygon_surface_2d(arc)
    grid = make_grid(arc.min(0), arc.max(0), resolution=40)
    exact = volume_fractions(closed, grid)
    vf = volume_fractions(Surface(arc, segments, closed=False), grid)
    chord = np.linalg.norm(arc[-1] - arc[0])
    sub = grid.spacing / 2
    assert abs(vf.solid_volume() - exact.solid_volume()) <= chord * sub / 8
    assert np.abs(vf.dense() - exact.dense()).max() < 0.1
    linearised, _ = counts(vf.warnings[0])
    assert linearised > 0


def test_work_beyond_the_budget_is_refused():
    vertices, faces = icosphere()
    grid = make_grid(vertices.min(0), vertices.max(0), resolution=32)
    surface = Surface(vertices, np.delete(faces, far_apart_faces(vertices, faces, 5), axis=0), closed=False)
    tiles = slab_tiles(grid)
    with pytest.raises(GeometryError) as err:
        winding_slabs(surface, grid, tiles, [], max_pairs=1e4)
    assert str(err.value) == (
        "geometry: the open surface (315 faces, 15 boundary edges, 34x34x34 cells) needs about 4.05e+04 "
        "point-facet evaluations of its winding number (lower bound, from the sub-cells its boundary passes "
        "through), more than the limit of 1e+04; close the mesh (fill its holes) or coarsen the grid"
    )
    # above the lower bound but below the real work: refused by a later stage, before it runs
    least = _least_work(close_holes(surface, grid), grid, 2)
    with pytest.raises(GeometryError, match=r"evaluations of its winding number \((certifying|probing|sampling)"):
        winding_slabs(surface, grid, tiles, [], max_pairs=1.01 * least)
    warnings = []
    winding_slabs(surface, grid, tiles, warnings, max_pairs=1e7)
    assert len(warnings) == 1


@pytest.mark.parametrize("case", ["holes", "bowl", "arc"])
def test_least_work_is_a_lower_bound_of_the_charged_work(case, monkeypatch):
    if case == "arc":
        angles = np.linspace(-2.0, 2.6, 80)
        vertices = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        faces = np.stack([np.arange(79), np.arange(1, 80)], axis=1)
    else:
        vertices, faces = icosphere()
        if case == "holes":
            faces = np.delete(faces, far_apart_faces(vertices, faces, 5), axis=0)
        else:
            faces = faces[vertices[faces].mean(axis=1)[:, 2] < 0.2]
    surface = Surface(vertices, faces, closed=False)
    grid = make_grid(*surface.bounds, resolution=24)
    charged = []
    charge = winding_fill._Budget.charge

    def recording(self, stage, pairs):
        charged.append(pairs)
        charge(self, stage, pairs)

    monkeypatch.setattr(winding_fill._Budget, "charge", recording)
    winding_slabs(surface, grid, slab_tiles(grid), [])
    least = _least_work(close_holes(surface, grid), grid, winding_fill.SAMPLES_PER_AXIS[grid.dim])
    assert 0 < least <= sum(charged)


@pytest.mark.parametrize("dim", [2, 3])
def test_gradient_and_bounds_of_the_winding_number(dim, rng):
    if dim == 3:
        vertices, faces = icosphere()
        faces = faces[vertices[faces].mean(axis=1)[:, 2] < 0.6]
    else:
        angles = np.linspace(0.0, 4.5, 40)
        vertices = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        faces = np.stack([np.arange(39), np.arange(1, 40)], axis=1)
    surface = Surface(vertices, faces, closed=False)
    grid = make_grid(*surface.bounds, resolution=12)
    closure = close_holes(surface, grid)
    cells = rng.integers(0, 2 * grid.shape[0], (3000, dim))
    w, grad, spread, curvature = _probe(closure, cells)
    smooth = spread < 1e20
    assert smooth.sum() > 1000
    centres = (cells + 0.5) * closure.unit + closure.origin
    step = 1e-6
    for axis in range(dim):
        shift = step * closure.unit * np.eye(dim)[axis]
        fd = (closure.winding_number(centres + shift) - closure.winding_number(centres - shift)) / (2 * step)
        assert np.abs(fd - grad[:, axis])[smooth].max() < 1e-6
    for _ in range(3):
        offset = rng.uniform(0.0, 1.0, (len(cells), dim))
        w_at = closure.winding_number((cells + offset) * closure.unit + closure.origin)
        assert np.all(np.abs(w_at - w)[smooth] <= spread[smooth])
        linear_error = np.abs(w_at - w - ((offset - 0.5) * grad).sum(axis=1))
        assert np.all(linear_error[smooth] <= curvature[smooth])


def test_halfspace_fraction_closed_forms(rng):
    w = rng.uniform(0.0, 1.0, 50)
    a = rng.uniform(0.1, 3.0, 50)
    along_x = np.stack([a, np.zeros(50), np.zeros(50)], axis=1)
    # w + a (x - 1/2) >= 1/2  <=>  x >= 1/2 - (w - 1/2) / a
    assert np.abs(halfspace_fraction(w, along_x) - np.clip(0.5 + (w - 0.5) / a, 0, 1)).max() < 1e-14
    # w - a (y - 1/2) >= 1/2  <=>  y <= 1/2 + (w - 1/2) / a
    assert np.abs(halfspace_fraction(w, -along_x[:, [2, 0]]) - np.clip(0.5 + (w - 0.5) / a, 0, 1)).max() < 1e-14
    # 2D diagonal: x + y >= 3/2 - w; for w in [1/2, 1] the excluded corner is a triangle
    w = rng.uniform(0.5, 1.0, 50)
    assert np.abs(halfspace_fraction(w, np.ones((50, 2))) - (1 - 0.5 * (1.5 - w) ** 2)).max() < 1e-14
    # general directions against a midpoint lattice (error ~ one lattice cell per unit of boundary)
    grad = rng.normal(size=(40, 3))
    w = rng.uniform(0.0, 1.0, 40)
    m = 60
    lattice = np.stack(np.meshgrid(*[(np.arange(m) + 0.5) / m] * 3, indexing="ij"), -1).reshape(-1, 3)
    share = ((w[None, :] + (lattice - 0.5) @ grad.T) >= 0.5).mean(axis=0)
    assert np.abs(halfspace_fraction(w, grad) - share).max() < 3.0 / m


def test_bowl_is_closed_by_the_disk_over_its_rim():
    """An open spherical bowl (a hole as large as the body): its solid is the bowl closed by the
    flat polygon over its rim, where w = 1/2 crosses the sub-cells, linearised or sampled."""
    sphere = trimesh.creation.uv_sphere(radius=1.0, count=[25, 32])
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    z_rim = np.sort(np.unique(vertices[:, 2]))[13]  # the ring just above the equator
    bowl = faces[np.all(vertices[faces][:, :, 2] <= z_rim, axis=1)]
    # volume relative to the rim's centre, where the flat cap (a fan from it) adds nothing
    corners = vertices[bowl] - [0.0, 0.0, z_rim]
    closed_volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6
    grid = make_grid(vertices.min(0), vertices.max(0), resolution=24)
    vf = volume_fractions(Surface(vertices, bowl, closed=False), grid)
    ring = int(np.isclose(vertices[np.unique(bowl)][:, 2], z_rim).sum())
    disk = ring / 2 * (1 - z_rim**2) * np.sin(2 * np.pi / ring)  # area of the rim, a regular polygon
    # first-order error: at most half a sampling step (q = 2) over the disk
    assert abs(vf.solid_volume() - closed_volume) <= disk * grid.spacing / 2 / 4
    assert vf.warnings[0].startswith(f"surface is open ({ring} boundary edges, 1 hole(s))")
    linearised, sampled = counts(vf.warnings[0])
    assert linearised > 0 and sampled > 0
