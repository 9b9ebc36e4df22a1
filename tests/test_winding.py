"""Generalized winding number (engine.geometry.winding) against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import engine.geometry.winding as winding
from engine.geometry.winding import inside, winding_number, winding_number_fast


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3)  # 1280 faces, inscribed in radius 1


def test_closed_sphere_is_one_inside_and_zero_outside(sphere):
    rng = np.random.default_rng(0)
    points = rng.uniform(-1.5, 1.5, (400, 3))
    r = np.linalg.norm(points, axis=1)
    # Keep off the discretised surface, which lies between the in- and circumradius.
    points, r = points[(r < 0.98) | (r > 1.0)], r[(r < 0.98) | (r > 1.0)]
    w = winding_number(sphere.vertices, sphere.faces, points)
    np.testing.assert_allclose(w, (r < 0.98).astype(float), rtol=0, atol=1e-10)
    np.testing.assert_array_equal(inside(sphere.vertices, sphere.faces, points), r < 0.98)
    # Reversed faces: -1 inside.
    w = winding_number(sphere.vertices, sphere.faces[:, ::-1], points[r < 0.98])
    np.testing.assert_allclose(w, -1.0, rtol=0, atol=1e-10)


def test_nested_shells_count_twice():
    outer = trimesh.creation.icosphere(subdivisions=2, radius=2.0)
    inner = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    vertices = np.vstack([outer.vertices, inner.vertices])
    faces = np.vstack([outer.faces, inner.faces + len(outer.vertices)])
    w = winding_number(vertices, faces, np.array([[0.0, 0.0, 0.1], [1.5, 0.0, 0.0], [3.0, 0.0, 0.0]]))
    np.testing.assert_allclose(w, [2.0, 1.0, 0.0], rtol=0, atol=1e-12)


def test_single_triangle_and_square_solid_angles():
    # The octant triangle seen from the origin covers 1/8 of the sphere; from below its plane
    # (behind its normal (1,1,1)) the sign is positive.
    octant = np.eye(3)
    assert winding_number(octant, [[0, 1, 2]], np.zeros((1, 3)))[0] == pytest.approx(1 / 8, rel=1e-14)
    # A 2 x 2 square at distance d above its centre: Omega = 4 atan(a b / (2 d sqrt(4 d^2 + a^2 + b^2))).
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]])
    faces = [[0, 1, 2], [0, 2, 3]]
    d = np.array([0.1, 1.0, 7.0])
    # The points lie in front of the normal +z: negative.
    expected = -4 * np.arctan(4 / (2 * d * np.sqrt(4 * d**2 + 8))) / (4 * np.pi)
    np.testing.assert_allclose(winding_number(square, faces, np.c_[0 * d, 0 * d, d]), expected, rtol=1e-13)
    assert expected[1] == pytest.approx(-1 / 6, rel=1e-14)  # a cube face seen from the cube's centre


def test_points_on_a_face_get_one_half():
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    on_face = np.array([[0.2, 0.1, 1.0], [1.0, -0.3, 0.45], [-0.6, -1.0, 0.2]])
    w = winding_number(box.vertices, box.faces, on_face)
    np.testing.assert_allclose(w, 0.5, rtol=0, atol=1e-14)
    assert inside(box.vertices, box.faces, on_face).all()


def test_square_in_2d():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    segments = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    points = np.array([[0.5, 0.5], [0.01, 0.99], [1.5, 0.5], [-3.0, 7.0], [0.5, 0.0], [1.0, 0.3]])
    w = winding_number(square, segments, points)
    np.testing.assert_allclose(w, [1, 1, 0, 0, 0.5, 0.5], rtol=0, atol=1e-15)
    w = winding_number(square, segments[:, ::-1], points[:2])
    np.testing.assert_allclose(w, -1.0, rtol=0, atol=1e-15)
    # One segment seen from a point: the angle it subtends / 2 pi.
    assert winding_number(square, segments[:1], np.array([[0.5, 0.5]]))[0] == pytest.approx(0.25, rel=1e-14)


def test_blocking_does_not_change_the_result(sphere, monkeypatch):
    points = np.random.default_rng(3).uniform(-1.2, 1.2, (37, 3))
    reference = winding_number(sphere.vertices, sphere.faces, points)
    monkeypatch.setattr(winding, "_BLOCK_PAIRS", 301)  # ragged blocks over faces and points
    w = winding_number(sphere.vertices, sphere.faces, points)
    np.testing.assert_allclose(w, reference, rtol=0, atol=1e-13)
    monkeypatch.setattr(winding, "_BLOCK_PAIRS", 5000)  # several points per block
    w = winding_number(sphere.vertices, sphere.faces, points)
    np.testing.assert_allclose(w, reference, rtol=0, atol=1e-13)


def test_shapes_are_checked():
    assert winding_number(np.eye(3), np.zeros((0, 3), dtype=int), np.zeros((2, 3))).tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match=r"faces must have shape \[k, 3\]"):
        winding_number(np.eye(3), [[0, 1]], np.zeros((1, 3)))
    with pytest.raises(ValueError, match=r"points must have shape \[n, 2\]"):
        winding_number(np.eye(2), [[0, 1]], np.zeros((1, 3)))


# --- Hierarchical fast winding number (winding_number_fast) and the fast path of inside ---


def _probes(mesh: trimesh.Trimesh, n: int, seed: int) -> np.ndarray:
    """Points of every kind [~3.25 n, 3]: uniform in the enlarged bounding box, exactly on faces,
    within 1e-9 of the surface on either side, and exactly on vertices."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    box = rng.uniform(lo - 0.3 * (hi - lo), hi + 0.3 * (hi - lo), (n, 3))
    on_face, face = trimesh.sample.sample_surface(mesh, n, seed=seed)
    near = on_face + 1e-9 * rng.choice([-1.0, 1.0], (n, 1)) * mesh.face_normals[face]
    corner = mesh.vertices[rng.integers(0, len(mesh.vertices), n // 4)]
    return np.vstack([box, on_face, near, corner])


@pytest.fixture(scope="module")
def fine_sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=4)  # 5120 faces


@pytest.fixture(scope="module")
def torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=48, minor_sections=24)


@pytest.mark.parametrize("name", ["fine_sphere", "torus"])
def test_fast_winding_number_agrees_with_exact(name, request):
    mesh = request.getfixturevalue(name)
    points = _probes(mesh, 200, seed=4)
    exact = winding_number(mesh.vertices, mesh.faces, points)
    # Measured max |fast - exact| at beta = 2: 2.1e-3 (sphere), 5.4e-3 (torus, near its centre).
    fast = winding_number_fast(mesh.vertices, mesh.faces, points)
    np.testing.assert_allclose(fast, exact, rtol=0, atol=1e-2)
    # The far-field error falls like beta^-3: measured 1.1e-4 and 1.3e-4 at beta = 4.
    fast = winding_number_fast(mesh.vertices, mesh.faces, points, beta=4.0, leaf_faces=8)
    np.testing.assert_allclose(fast, exact, rtol=0, atol=3e-4)


def test_fast_winding_number_small_and_degenerate_meshes(sphere):
    # Degenerate triangles (a repeated corner, a sliver) and a mesh smaller than one leaf.
    faces = np.vstack([sphere.faces, [[0, 0, 1], [2, 2, 2]]])
    points = _probes(sphere, 50, seed=5)
    exact = winding_number(sphere.vertices, faces, points)
    fast = winding_number_fast(sphere.vertices, faces, points)
    np.testing.assert_allclose(fast, exact, rtol=0, atol=2e-3)
    octant, triangle = np.eye(3), [[0, 1, 2]]
    points = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.2, 0.3, 0.5]])
    fast = winding_number_fast(octant, triangle, points)  # one leaf: exact
    np.testing.assert_allclose(fast, winding_number(octant, triangle, points), rtol=0, atol=1e-15)


def test_fast_winding_number_arguments():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    segments = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    assert winding_number_fast(square, segments, np.array([[0.5, 0.5]])).tolist() == [1.0]  # 2D: exact
    no_faces = np.zeros((0, 3), dtype=int)
    assert winding_number_fast(np.eye(3), no_faces, np.zeros((2, 3))).tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match="beta must exceed 1"):
        winding_number_fast(np.eye(3), [[0, 1, 2]], np.zeros((1, 3)), beta=1.0)
    with pytest.raises(ValueError, match="leaf_faces must be at least 2"):
        winding_number_fast(np.eye(3), [[0, 1, 2]], np.zeros((1, 3)), leaf_faces=1)


class _Spy:
    """Wraps a function of (vertices, faces, points), recording how many points each call got."""

    def __init__(self, function):
        self.function, self.calls = function, []

    def __call__(self, vertices, faces, points, **kwargs):
        self.calls.append(len(points))
        return self.function(vertices, faces, points, **kwargs)


def _inside_fast(monkeypatch, vertices, faces, points) -> tuple[np.ndarray, list[int], list[int]]:
    """inside() forced onto the fast path; returns it and the point counts given to the fast and
    the exact winding number."""
    monkeypatch.setattr(winding, "_FAST_MIN_PAIRS", 0)
    fast, exact = _Spy(winding.winding_number_fast), _Spy(winding.winding_number)
    monkeypatch.setattr(winding, "winding_number_fast", fast)
    monkeypatch.setattr(winding, "winding_number", exact)
    result = inside(vertices, faces, points)
    monkeypatch.undo()
    return result, fast.calls, exact.calls


def _lame_shell() -> tuple[np.ndarray, np.ndarray]:
    """A thick spherical shell: outer radius 1 outward, inner radius 1/2 inward (w = 0 in the cavity)."""
    outer = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    vertices = np.vstack([outer.vertices, inner.vertices])
    return vertices, np.vstack([outer.faces, inner.faces[:, ::-1] + len(outer.vertices)])


@pytest.mark.parametrize("name", ["torus", "shell"])
def test_inside_fast_path_decides_like_the_exact_path(name, request, monkeypatch):
    if name == "shell":
        vertices, faces = _lame_shell()
        mesh = trimesh.Trimesh(vertices, faces, process=False)
    else:
        mesh = request.getfixturevalue(name)
        vertices, faces = mesh.vertices, mesh.faces
    points = _probes(mesh, 300, seed=6)
    edges = mesh.vertices[mesh.edges_unique[:100]].mean(axis=1)  # exactly on edges
    points = np.vstack([points, edges])
    expected = winding_number(vertices, faces, points) >= 0.5 - 1e-12
    result, fast_calls, exact_calls = _inside_fast(monkeypatch, vertices, faces, points)
    np.testing.assert_array_equal(result, expected)
    assert fast_calls == [len(points)]
    # Only the points on the surface (1/2 there) are recomputed exactly; those 1e-9 off it are not.
    on_surface = 300 + 300 // 4 + 100
    assert len(exact_calls) == 1 and exact_calls[0] <= on_surface + 20


def test_inside_fast_path_on_an_open_surface(monkeypatch):
    sphere = trimesh.creation.icosphere(subdivisions=3)
    keep = sphere.triangles_center[:, 2] < 0.7  # a hole around the north pole
    vertices, faces = sphere.vertices, sphere.faces[keep]
    rng = np.random.default_rng(7)
    near_hole = rng.uniform([-0.5, -0.5, 0.5], [0.5, 0.5, 1.5], (500, 3))
    points = np.vstack([rng.uniform(-1.3, 1.3, (1500, 3)), near_hole])
    w = winding_number(vertices, faces, points)
    ambiguous = np.abs(w - np.round(w)) > 0.2
    assert ambiguous.sum() > 50  # fractional w near the hole
    result, _, exact_calls = _inside_fast(monkeypatch, vertices, faces, points)
    np.testing.assert_array_equal(result, w >= 0.5 - 1e-12)
    assert exact_calls and ambiguous.sum() <= exact_calls[0] < len(points)


def test_inside_small_cases_stay_exact(sphere, monkeypatch):
    fast = _Spy(winding.winding_number_fast)
    monkeypatch.setattr(winding, "winding_number_fast", fast)
    points = np.random.default_rng(8).uniform(-1.2, 1.2, (1000, 3))  # 1.28 M pairs
    inside(sphere.vertices, sphere.faces, points)
    assert fast.calls == []
