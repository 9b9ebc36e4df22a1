"""Exact polynomial moments: closed forms for boxes, exact rational references for simplices."""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np
import pytest
import trimesh

from engine.errors import GeometryError
from engine.geometry.moments import (
    area_moments,
    box_moments,
    cell_face_moments,
    cell_moments,
    monomial_exponents,
    rescale_moments,
    shift_moments,
    triangle_rule,
    volume_moments,
)

DEGREE = 4
EXPS = monomial_exponents(3, DEGREE)


def _poly_power(linear: dict, power: int) -> dict:
    """(sum_k c_k lambda_k)^power as {exponent tuple: Fraction} over barycentric coordinates."""
    out = {(0,) * len(next(iter(linear))): Fraction(1)}
    for _ in range(power):
        nxt: dict = {}
        for e, c in out.items():
            for f, d in linear.items():
                key = tuple(x + y for x, y in zip(e, f))
                nxt[key] = nxt.get(key, Fraction(0)) + c * d
        out = nxt
    return out


def _simplex_moment(vertices: list[list[Fraction]], alpha: tuple[int, ...], measure: Fraction) -> Fraction:
    """Exact int_S x^alpha over a simplex with ``len(vertices)`` vertices (Dirichlet formula):
    int_S lambda^k = measure * d! prod(k_i!) / (|k| + d)!, d = len(vertices) - 1."""
    d = len(vertices) - 1
    units = [tuple(int(i == k) for i in range(d + 1)) for k in range(d + 1)]
    poly = {(0,) * (d + 1): Fraction(1)}
    for axis, a in enumerate(alpha):
        factor = _poly_power({u: v[axis] for u, v in zip(units, vertices)}, a)
        prod: dict = {}
        for e, c in poly.items():
            for f, g in factor.items():
                key = tuple(x + y for x, y in zip(e, f))
                prod[key] = prod.get(key, Fraction(0)) + c * g
        poly = prod
    total = Fraction(0)
    for k, c in poly.items():
        num = factorial(d)
        for ki in k:
            num *= factorial(ki)
        total += c * Fraction(num, factorial(sum(k) + d))
    return total * measure


def _tet_volume(v: list[list[Fraction]]) -> Fraction:
    a = [[v[i][j] - v[0][j] for j in range(3)] for i in (1, 2, 3)]
    det = (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
           + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
    return abs(det) / 6


def _close(got: np.ndarray, ref: np.ndarray, rtol: float) -> None:
    """Entrywise agreement relative to the largest reference moment (odd moments may vanish)."""
    np.testing.assert_allclose(got, ref, rtol=0, atol=rtol * np.max(np.abs(ref)))


def test_exponent_order_is_graded_then_lexicographic():
    assert EXPS.shape == (35, 3)
    assert EXPS[:10].tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 0, 0], [1, 1, 0], [1, 0, 1],
                                  [0, 2, 0], [0, 1, 1], [0, 0, 2]]
    assert EXPS[-1].tolist() == [0, 0, 4] and EXPS[20].tolist() == [4, 0, 0]
    assert monomial_exponents(2, 2).tolist() == [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    assert len(monomial_exponents(3, 2)) == 10
    with pytest.raises(GeometryError, match="degree must be an integer >= 0, got -1"):
        monomial_exponents(3, -1)


@pytest.mark.parametrize("degree", range(0, 9))
def test_triangle_rule_is_exact(degree):
    points, weights = triangle_rule(degree)
    assert weights.sum() == pytest.approx(0.5, abs=1e-15)
    for i in range(degree + 1):
        for j in range(degree + 1 - i):
            exact = factorial(i) * factorial(j) / factorial(i + j + 2)
            got = np.sum(weights * points[:, 0] ** i * points[:, 1] ** j)
            assert abs(got - exact) <= 2e-15 * exact


def test_cell_reference_closed_form_and_mesh():
    ref = cell_moments(DEGREE)
    by_exp = {tuple(e): v for e, v in zip(EXPS.tolist(), ref)}
    assert by_exp[(0, 0, 0)] == 1.0
    assert by_exp[(2, 0, 0)] == pytest.approx(1 / 12, rel=1e-15)
    assert by_exp[(0, 0, 4)] == pytest.approx(1 / 80, rel=1e-15)
    assert by_exp[(2, 2, 0)] == pytest.approx(1 / 144, rel=1e-15)
    assert by_exp[(1, 0, 0)] == 0 and by_exp[(2, 1, 1)] == 0
    h = 0.37
    cube = trimesh.creation.box(extents=[h, h, h])
    cube.apply_translation([2.0, -1.0, 0.5])
    got = volume_moments(cube.vertices, cube.faces, DEGREE, [2.0, -1.0, 0.5], h)
    _close(got, ref, 1e-13)


def test_axis_aligned_box_any_placement():
    lo, hi = np.array([0.31, -1.27, 0.52]), np.array([2.13, 0.71, 0.94])
    box = trimesh.creation.box(bounds=[lo, hi])
    for centre, scale in (([0.1, 0.2, -0.3], 0.7), ([1.2, -0.3, 0.7], 1.9), ([0.0, 0.0, 0.0], 0.05)):
        c = np.asarray(centre)
        got = volume_moments(box.vertices, box.faces, DEGREE, c, scale)
        _close(got, box_moments((lo - c) / scale, (hi - c) / scale, DEGREE), 1e-12)


def _rational_rotation() -> list[list[Fraction]]:
    a = [[Fraction(3, 5), Fraction(-4, 5), Fraction(0)], [Fraction(4, 5), Fraction(3, 5), Fraction(0)],
         [Fraction(0), Fraction(0), Fraction(1)]]
    b = [[Fraction(1), Fraction(0), Fraction(0)], [Fraction(0), Fraction(5, 13), Fraction(-12, 13)],
         [Fraction(0), Fraction(12, 13), Fraction(5, 13)]]
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def test_rotated_box_matches_exact_rational_reference():
    # Box [0,2]x[0,1]x[0,3/2] rotated by an exactly rational rotation and shifted: the reference is
    # the exact sum over a 6-tetrahedron (Kuhn) split, in rational arithmetic.
    rot = _rational_rotation()
    size = [Fraction(2), Fraction(1), Fraction(3, 2)]
    shift = [Fraction(1, 3), Fraction(-2, 7), Fraction(5, 4)]
    corner = {}
    for i in range(8):
        p = [size[d] * ((i >> d) & 1) for d in range(3)]
        corner[i] = [sum(rot[r][k] * p[k] for k in range(3)) + shift[r] for r in range(3)]
    # Kuhn split: paths 0 -> ... -> 7 flipping one bit at a time.
    tets = []
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        path, v = [0], 0
        for bit in perm:
            v |= 1 << bit
            path.append(v)
        tets.append([corner[k] for k in path])
    ref = np.array([float(sum(_simplex_moment(t, tuple(a), _tet_volume(t)) for t in tets)) for a in EXPS.tolist()])
    box = trimesh.creation.box(bounds=[[0, 0, 0], [2, 1, 1.5]])
    xyz = np.array([[float(x) for x in corner[(int(p[0] > 0)) | (int(p[1] > 0) << 1) | (int(p[2] > 0) << 2)]]
                    for p in box.vertices])
    got = volume_moments(xyz, box.faces, DEGREE, [0, 0, 0], 1.0)
    assert got[0] == pytest.approx(3.0, rel=1e-14)
    _close(got, ref, 1e-12)


def test_tetrahedron_matches_dirichlet_formula():
    verts = [[Fraction(1, 4), Fraction(-1, 2), Fraction(3, 8)], [Fraction(2), Fraction(1, 8), Fraction(1, 2)],
             [Fraction(1, 2), Fraction(7, 4), Fraction(-1, 4)], [Fraction(3, 4), Fraction(1, 2), Fraction(2)]]
    vol = _tet_volume(verts)
    xyz = np.array([[float(x) for x in v] for v in verts])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    signed = np.dot(xyz[1] - xyz[0], np.cross(xyz[2] - xyz[0], xyz[3] - xyz[0]))
    if signed < 0:
        faces = faces[:, ::-1]
    for centre, scale in ((np.zeros(3), 1.0), (np.array([0.8, 0.4, 0.6]), 0.5)):
        c = [Fraction(x).limit_denominator(10) for x in centre]
        s = Fraction(scale).limit_denominator(10)
        shifted = [[(v[d] - c[d]) / s for d in range(3)] for v in verts]
        ref = np.array([float(_simplex_moment(shifted, tuple(a), vol / s**3)) for a in EXPS.tolist()])
        _close(volume_moments(xyz, faces, DEGREE, centre, scale), ref, 1e-12)


def test_area_moments_of_triangles_in_a_plane():
    verts = [[Fraction(1, 4), Fraction(-1, 2), Fraction(3, 8)], [Fraction(2), Fraction(1, 8), Fraction(3, 8)],
             [Fraction(1, 2), Fraction(7, 4), Fraction(3, 8)]]
    ux, uy = (verts[1][0] - verts[0][0], verts[1][1] - verts[0][1])
    vx, vy = (verts[2][0] - verts[0][0], verts[2][1] - verts[0][1])
    area = abs(ux * vy - uy * vx) / 2
    ref = np.array([float(_simplex_moment(verts, tuple(a), area)) for a in EXPS.tolist()])
    xyz = np.array([[float(x) for x in v] for v in verts])
    _close(area_moments(xyz, np.array([[0, 1, 2]]), DEGREE, [0, 0, 0], 1.0), ref, 1e-12)
    _close(area_moments(xyz, np.array([[0, 2, 1]]), DEGREE, [0, 0, 0], 1.0), ref, 1e-12)  # orientation-free
    # The full high x-face of the unit cell about its centre, from its two triangles.
    square = np.array([[0.5, -0.5, -0.5], [0.5, 0.5, -0.5], [0.5, 0.5, 0.5], [0.5, -0.5, 0.5]])
    got = area_moments(square, np.array([[0, 1, 2], [0, 2, 3]]), DEGREE, [0, 0, 0], 1.0)
    _close(got, cell_face_moments(DEGREE)[0], 1e-14)
    by_exp = {tuple(e): v for e, v in zip(EXPS.tolist(), cell_face_moments(DEGREE)[2])}
    assert by_exp[(0, 0, 3)] == 0.125 and by_exp[(2, 0, 1)] == pytest.approx(1 / 24, rel=1e-15)


def test_hollow_box_inner_shell_subtracts():
    outer = trimesh.creation.box(bounds=[[0, 0, 0], [3, 2, 2]])
    inner = trimesh.creation.box(bounds=[[1, 0.5, 0.25], [2, 1.5, 1.5]])
    verts = np.concatenate([outer.vertices, inner.vertices])
    faces = np.concatenate([outer.faces, inner.faces[:, ::-1] + len(outer.vertices)])
    c, s = np.array([1.4, 0.9, 1.1]), 0.8
    ref = box_moments((np.zeros(3) - c) / s, (np.array([3, 2, 2]) - c) / s, DEGREE) \
        - box_moments((np.array([1, 0.5, 0.25]) - c) / s, (np.array([2, 1.5, 1.5]) - c) / s, DEGREE)
    _close(volume_moments(verts, faces, DEGREE, c, s), ref, 1e-12)


def test_shift_and_rescale_are_exact():
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.9)
    a, b = np.array([0.3, -0.2, 0.1]), np.array([-0.5, 0.4, 0.25])
    m_a = volume_moments(sphere.vertices, sphere.faces, DEGREE, a, 0.5)
    m_b = volume_moments(sphere.vertices, sphere.faces, DEGREE, b, 0.5)
    _close(shift_moments(m_a, DEGREE, (b - a) / 0.5), m_b, 1e-13)
    batch = shift_moments(np.stack([m_a, m_a]), DEGREE, np.stack([(b - a) / 0.5, np.zeros(3)]))
    _close(batch[0], m_b, 1e-13)
    _close(batch[1], m_a, 1e-15)
    m_big = volume_moments(sphere.vertices, sphere.faces, DEGREE, a, 2.0)
    _close(rescale_moments(m_a, DEGREE, 0.25), m_big, 1e-14)


def test_bad_input_is_reported():
    with pytest.raises(GeometryError, match=r"vertices must have shape \[m, 3\]"):
        volume_moments(np.zeros((4, 2)), np.array([[0, 1, 2]]), 2, [0, 0, 0], 1.0)
    with pytest.raises(GeometryError, match="scale must be a positive finite length, got 0.0"):
        area_moments(np.zeros((3, 3)), np.array([[0, 1, 2]]), 2, [0, 0, 0], 0.0)
    with pytest.raises(GeometryError, match="triangle vertex index out of range"):
        volume_moments(np.zeros((3, 3)), np.array([[0, 1, 3]]), 2, [0, 0, 0], 1.0)
