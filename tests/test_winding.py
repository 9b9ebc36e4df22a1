"""Generalized winding number (engine.geometry.winding) against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import engine.geometry.winding as winding
from engine.geometry.winding import inside, winding_number


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
