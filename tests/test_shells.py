"""Overlapping shells are united at load time (engine.geometry.shells via loading)."""

from __future__ import annotations

import itertools

import manifold3d
import numpy as np
import pytest
import trimesh

from engine.geometry.fractions import volume_fractions
from engine.geometry.loading import mesh_surface
from engine.geometry.topology import shells as _shells
from engine.geometry.shells import _Shells, box_pairs, unite_overlapping_shells
from engine.geometry.slicing import slice_cells
from engine.geometry.surface import Surface
from engine.geometry.winding import winding_number
from engine.grid import Grid, make_grid


def _box(lower, upper) -> trimesh.Trimesh:
    return trimesh.creation.box(bounds=[lower, upper])


def _combine(*meshes: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertices [m, 3] and faces [k, 3] of the meshes side by side, each as given."""
    vertices, faces, n = [], [], 0
    for mesh in meshes:
        vertices.append(np.asarray(mesh.vertices, dtype=float))
        faces.append(np.asarray(mesh.faces, dtype=np.int64) + n)
        n += len(mesh.vertices)
    return np.concatenate(vertices), np.concatenate(faces)


def _manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    return manifold3d.Manifold(manifold3d.Mesh64(
        vert_properties=np.array(mesh.vertices, dtype=np.float64),
        tri_verts=np.array(mesh.faces, dtype=np.uint64),
    ))


def _assert_closed(surface: Surface) -> None:
    """Every directed edge a->b is matched by exactly one b->a: closed, consistently oriented."""
    ends = surface.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    directed = {tuple(e) for e in ends.tolist()}
    assert len(directed) == len(ends)  # no directed edge twice
    assert all((b, a) in directed for a, b in directed)
    assert surface.closed


TWO_BOXES = (_box([0, 0, 0], [1, 1, 1]), _box([0.5, 0.25, 0.25], [1.5, 0.75, 0.75]))


def test_two_overlapping_boxes_load_as_their_union_for_fractions_and_slicing():
    vertices, faces = _combine(*TWO_BOXES)
    surface = mesh_surface(vertices, faces)
    assert surface.warnings == [
        "united 2 overlapping shells (overlap volume 0.125 m^3; enclosed volume 1.25 -> 1.125 m^3);"
        " vertex numbering differs from the input"
    ]
    assert abs(surface.enclosed_volume() - 1.125) < 1e-12
    _assert_closed(surface)
    # A grid in general position, so that the grid planes cut the boxes' faces.
    grid = Grid(origin=(-0.13, -0.11, -0.07), spacing=0.23, shape=(9, 6, 6))
    fractions = volume_fractions(surface, grid)
    assert fractions.warnings == []
    assert abs(fractions.solid_volume() - 1.125) < 1e-12
    cut = slice_cells(surface, grid, 2, workers=1)
    assert abs(cut.volume.sum() - 1.125) < 1e-12
    assert cut.closure_error() < 1e-12
    # Without the union, the scan conversion counts the overlap twice and says so.
    raw = volume_fractions(Surface(vertices, faces), grid)
    assert "overlapping or self-intersecting shells" in raw.warnings[0]
    assert abs(raw.solid_volume() - 1.125) > 1e-3


def test_three_mutually_overlapping_spheres_give_the_manifold_union():
    spheres = [trimesh.creation.icosphere(subdivisions=2).apply_translation(c)
               for c in ([0, 0, 0], [1.0, 0, 0], [0.5, 0.8, 0.1])]
    surface = mesh_surface(*_combine(*spheres))
    solids = [_manifold(s) for s in spheres]
    union = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add).volume()
    # The same volume by inclusion-exclusion from pairwise and triple intersections.
    pairs = sum((a ^ b).volume() for a, b in itertools.combinations(solids, 2))
    triple = (solids[0] ^ solids[1] ^ solids[2]).volume()
    assert union == pytest.approx(sum(s.volume for s in spheres) - pairs + triple, rel=1e-12)
    assert abs(surface.enclosed_volume() - union) < 1e-12 * union
    assert surface.warnings[0].startswith(f"united 3 overlapping shells (overlap volume {pairs:.6g} m^3;")
    _assert_closed(surface)
    assert _shell_count(surface) == 1
    grid = make_grid(*surface.bounds, resolution=12)
    fractions = volume_fractions(surface, grid)
    assert fractions.warnings == []
    assert abs(fractions.solid_volume() - union) < 1e-10 * union


def _shell_count(surface: Surface) -> int:
    return int(_shells(surface.faces, len(surface.vertices))[0])


def test_hollow_sphere_is_returned_unchanged():
    outer = trimesh.creation.icosphere(subdivisions=3)  # 1280 + 1280 faces: the fast "apart" path
    inner = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    inner.invert()
    vertices, faces = _combine(outer, inner)
    surface = mesh_surface(vertices, faces)
    assert surface.warnings == []
    np.testing.assert_array_equal(surface.vertices, vertices)
    np.testing.assert_array_equal(surface.faces, faces)
    assert unite_overlapping_shells(surface, _shells(faces, len(vertices))[1]) is surface


def test_shells_whose_boxes_overlap_but_not_their_solids_are_unchanged():
    # Unit spheres 2.08 apart along the diagonal: the boxes overlap by 0.8 on every axis.
    a = trimesh.creation.icosphere(subdivisions=2)
    b = trimesh.creation.icosphere(subdivisions=2).apply_translation([1.2, 1.2, 1.2])
    touching = (_box([0, 0, 0], [1, 1, 1]), _box([1, 0.25, 0.25], [2, 0.75, 0.75]))  # share a face part
    for meshes in ((a, b), touching):
        vertices, faces = _combine(*meshes)
        surface = mesh_surface(vertices, faces)
        assert surface.warnings == []
        np.testing.assert_array_equal(surface.faces, faces)


# Solid A = [0, 4]^3 with cavities and islands, all given outward (loading orients by nesting).
CAVITY_CASES = {
    # cavity [0.5, 3.5]^3 with two overlapping islands in it: 64 - 27 + (1 + 0.25 - 0.125)
    "overlapping islands stay in their cavity": (
        [_box([0.5] * 3, [3.5] * 3), _box([1, 1, 1], [2, 2, 2]), _box([1.5, 1.25, 1.25], [2.5, 1.75, 1.75])],
        64 - 27 + 1.125, [(0.7, 0.7, 0.7), (3.2, 2, 2)], [(0.2, 2, 2), (1.2, 1.2, 1.2), (2.2, 1.5, 1.5)],
    ),
    # two overlapping cavities make one void: 64 - (1 + 0.25 - 0.125)
    "overlapping cavities make one void": (
        [_box([1, 1, 1], [2, 2, 2]), _box([1.5, 1.25, 1.25], [2.5, 1.75, 1.75])],
        64 - 1.125, [(1.2, 1.2, 1.2), (2.2, 1.5, 1.5)], [(0.5, 0.5, 0.5), (2.7, 1.5, 1.5)],
    ),
    # a cavity, and a second solid overlapping A but not the cavity: 64 - 1 + 3 - 1
    "a second solid overlapping the solid keeps the cavity": (
        [_box([1, 1, 1], [2, 2, 2]), _box([3, 2.5, 2.5], [6, 3.5, 3.5])],
        64 - 1 + 3 - 1, [(1.5, 1.5, 1.5)], [(3.5, 3, 3), (5.5, 3, 3), (0.5, 1.5, 1.5)],
    ),
}


@pytest.mark.parametrize("case", list(CAVITY_CASES))
def test_nesting_is_respected_when_shells_overlap(case):
    inner, expected, void, material = CAVITY_CASES[case]
    surface = mesh_surface(*_combine(_box([0, 0, 0], [4, 4, 4]), *inner))
    assert abs(surface.enclosed_volume() - expected) < 1e-12 * expected
    assert surface.warnings[-1].startswith("united ")
    _assert_closed(surface)
    w = winding_number(surface.vertices, surface.faces, np.array(void + material))
    np.testing.assert_allclose(w, [0.0] * len(void) + [1.0] * len(material), atol=1e-9)


def test_a_box_pushed_into_a_sphere_is_united_though_loading_took_it_for_a_cavity():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    box = _box([0.6, -0.3, -0.3], [0.97, 0.3, 0.3])  # crosses the sphere, inside its bounding box
    vertices, faces = _combine(sphere, box)
    assert np.all(box.bounds[0] >= sphere.bounds[0]) and np.all(box.bounds[1] <= sphere.bounds[1])
    surface = mesh_surface(vertices, faces)
    # Loading's nesting probe (a point on the box's largest face) lies inside the sphere.
    assert surface.warnings[0].startswith("inverted 1 of 2 shells")
    assert surface.warnings[2] == (
        "took 1 shells that loading oriented as cavities as solids and 0 solids as cavities: their"
        " surfaces cross others, so their nesting was decided by exact containment"
    )
    union = (_manifold(sphere) + _manifold(box)).volume()
    assert union > sphere.volume + 1e-3  # the corners stick out
    assert abs(surface.enclosed_volume() - union) < 1e-12
    _assert_closed(surface)


def test_two_thousand_disjoint_boxes_are_unchanged_and_one_overlap_rebuilds_only_its_pair():
    corners = np.stack(np.meshgrid(np.arange(20), np.arange(10), np.arange(10), indexing="ij"), -1)
    boxes = [_box(c, c + 0.5) for c in corners.reshape(-1, 3).astype(float)]
    vertices, faces = _combine(*boxes)
    surface = mesh_surface(vertices, faces)
    assert surface.warnings == []
    np.testing.assert_array_equal(surface.faces, faces)
    # One more box, overlapping box 0 = [0, 0.5]^3 by 0.25^3: only that pair is rebuilt.
    vertices, faces = _combine(*boxes, _box([0.25] * 3, [0.75] * 3))
    surface = mesh_surface(vertices, faces)
    assert surface.warnings == [
        "united 2 overlapping shells (overlap volume 0.015625 m^3; enclosed volume 0.25 ->"
        " 0.234375 m^3); vertex numbering differs from the input"
    ]
    np.testing.assert_array_equal(surface.faces[: 1999 * 12], faces[12 : 2000 * 12] - 8)
    np.testing.assert_array_equal(surface.vertices[: 1999 * 8], vertices[8 : 2000 * 8])
    assert abs(surface.enclosed_volume() - (2000 * 0.125 - 0.125 + 0.234375)) < 1e-10
    _assert_closed(surface)


def test_box_pairs_match_all_pairs(rng):
    lower = rng.uniform(0, 10, size=(400, 3))
    upper = lower + rng.uniform(0, 1.5, size=(400, 3))
    upper[7] = lower[7]  # a point
    lower[9], upper[9] = upper[3], upper[3] + 1  # touches box 3 at a corner
    i, j = box_pairs(lower, upper)
    meet = np.all((lower[:, None] <= upper[None]) & (lower[None] <= upper[:, None]), axis=2)
    expected = np.argwhere(np.triu(meet, 1))
    assert len(expected) > 100
    np.testing.assert_array_equal(np.stack([i, j], axis=1), expected)
    assert [len(a) for a in box_pairs(lower[:1], upper[:1])] == [0, 0]


@pytest.mark.parametrize(
    ("radius", "offset", "meet"),
    [(0.5, 0.0, False), (0.97, 0.0, True), (0.6, 0.3, True), (0.3, 1.0, True), (0.3, 1.5, False)],
)
def test_apart_never_misses_triangle_boxes_that_meet(radius, offset, meet):
    # The fast path that skips manifold3d for nested shells may only say "apart" when no
    # triangle bounding box of one shell meets one of the other's (brute force here).
    outer = trimesh.creation.icosphere(subdivisions=2)
    inner = trimesh.creation.icosphere(subdivisions=2, radius=radius).apply_translation([offset, 0.1, 0])
    vertices, faces = _combine(outer, inner)
    shells = _Shells(Surface(vertices, faces), np.repeat([0, 1], [len(outer.faces), len(inner.faces)]), 2)
    lo, hi = shells.tri_lower, shells.tri_upper
    a, b = shells.members
    assert np.all((lo[a][:, None] <= hi[b][None]) & (lo[b][None] <= hi[a][:, None]), axis=2).any() == meet
    assert shells.apart(0, 1) == (not meet)


def _union_of_bodies(solid: tuple, cavities: list, others: list) -> float:
    """Exact volume of (solid - cavities) + others for axis-aligned boxes (lower, upper), on the
    grid of all their coordinates: the reference the boolean result must match."""
    boxes = [solid, *cavities, *others]
    axes = [np.unique([b[s][a] for b in boxes for s in (0, 1)]) for a in range(3)]
    centre = np.stack(np.meshgrid(*[(x[1:] + x[:-1]) / 2 for x in axes], indexing="ij"), -1)
    size = np.multiply.outer(np.multiply.outer(*[np.diff(x) for x in axes[:2]]), np.diff(axes[2]))

    def inside(box):
        return np.all((centre > box[0]) & (centre < box[1]), axis=-1)

    body = inside(solid) & ~np.any([inside(c) for c in cavities], axis=0)
    return float(size[body | np.any([inside(o) for o in others], axis=0)].sum())


def test_random_boxes_match_the_exact_union_of_bodies(rng):
    solid = (np.zeros(3), np.full(3, 4.0))
    tested = 0
    for _ in range(8):
        cavities = [np.sort(rng.uniform(0.2, 3.8, size=(2, 3)), axis=0) for _ in range(3)]
        others = []
        while len(others) < 3:  # solids crossing the big box's surface, not inside each other
            lower = rng.uniform(-1, 4, size=3)
            box = (lower, lower + rng.uniform(0.5, 2.5, size=3))
            crosses = np.any(box[0] < 0) or np.any(box[1] > 4)
            if crosses and np.all(box[0] < 4) and np.all(box[1] > 0):
                others.append(box)
        if any(np.all(a[0] <= b[0]) and np.all(b[1] <= a[1]) for group in (cavities, others)
               for a, b in itertools.permutations(group, 2)):
            continue  # nested: an island in a cavity, or a cavity in a solid, not what is tested
        tested += 1
        meshes = [_box(*b) for b in (solid, *cavities, *others)]
        surface = mesh_surface(*_combine(*meshes))
        expected = _union_of_bodies(solid, cavities, others)
        assert abs(surface.enclosed_volume() - expected) < 1e-12 * expected
        assert surface.warnings[-1].startswith("united ")
        _assert_closed(surface)
    assert tested >= 5


def test_a_pipe_through_the_wall_of_a_hollow_sphere_keeps_its_end_in_the_cavity():
    # Union of bodies: (outer - cavity) + pipe, so the pipe's end stays inside the void. The
    # outer and cavity spheres (2560 faces) take the fast "apart" path and are nested by the
    # winding number; the pipe crosses both.
    outer = trimesh.creation.icosphere(subdivisions=3)
    cavity = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    pipe = _box([0.3, -0.1, -0.1], [1.4, 0.1, 0.1])
    expected = ((_manifold(outer) - _manifold(cavity)) + _manifold(pipe)).volume()
    cavity.invert()
    surface = mesh_surface(*_combine(outer, cavity, pipe))
    assert surface.warnings[-1].startswith("united 3 overlapping shells")
    assert abs(surface.enclosed_volume() - expected) < 1e-12 * expected
    _assert_closed(surface)
    w = winding_number(surface.vertices, surface.faces, np.array([[0.0, 0.0, 0.0], [0.35, 0, 0], [1.3, 0, 0]]))
    np.testing.assert_allclose(w, [0.0, 1.0, 1.0], atol=1e-9)
