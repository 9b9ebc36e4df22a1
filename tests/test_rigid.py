"""Rigid modes (engine/solvers/rigid.py): the in-place Gram orthonormalisation against an SVD.

    .venv/bin/python -m pytest -q tests/test_rigid.py
"""

import itertools

import numpy as np

from engine.solvers.rigid import _orthonormal, free_modes, rigid_modes


def test_rigid_modes_are_translations_then_unit_rotations(rng):
    points, axis = rng.normal(size=(50, 3)), rng.integers(0, 3, 50)
    centre = np.array([0.3, -0.2, 0.1])
    modes = rigid_modes(points, axis, centre)
    x = points - centre
    for k in range(3):
        np.testing.assert_array_equal(modes[:, k], (axis == k).astype(float))
    for m, (k, l) in enumerate(itertools.combinations(range(3), 2), start=3):
        want = np.where(axis == k, -x[:, l], 0.0) + np.where(axis == l, x[:, k], 0.0)
        np.testing.assert_allclose(modes[:, m], want, rtol=0, atol=1e-15)


def test_orthonormal_basis_spans_the_columns_to_round_off(rng):
    a = rng.normal(size=(3000, 6)) * [1.0, 2.0, 3.0, 0.5, 0.1, 4.0]
    want = np.linalg.svd(a, full_matrices=False)[0]  # the SVD's basis of the same span
    q = _orthonormal(a.copy())
    assert q.shape == (3000, 6)
    assert np.abs(q.T @ q - np.eye(6)).max() < 1e-14
    assert np.abs(q @ q.T @ want - want).max() < 1e-13  # one span: each basis reproduces the other


def test_dependent_columns_lose_a_direction(rng):
    a = rng.normal(size=(3000, 6))
    a[:, 5] = a[:, 0] - 2.0 * a[:, 3]  # a singular value ~1e-16 of the largest: the Gram matrix cannot tell it
    q = _orthonormal(a.copy())
    assert q.shape == (3000, 5)
    assert np.abs(q.T @ q - np.eye(5)).max() < 1e-14
    assert np.abs(q @ (q.T @ a) - a).max() < 1e-12 * np.abs(a).max()


def test_a_free_body_keeps_all_six_modes_and_a_pinned_point_removes_the_translations(rng):
    points = rng.uniform(-1, 1, size=(600, 3))
    axis = np.tile(np.arange(3), 200)
    body = np.ones(600, dtype=int)
    (dofs, q), = free_modes(points, axis, np.zeros(600, dtype=bool), body)
    assert len(dofs) == 600 and q.shape == (600, 6)
    modes = rigid_modes(points, axis)
    assert np.abs(q.T @ q - np.eye(6)).max() < 1e-14
    assert np.abs(q @ (q.T @ modes) - modes).max() < 1e-12  # the rigid modes, no other direction
    fixed = np.zeros(600, dtype=bool)
    fixed[:3] = True  # the three components of one point: only rotations about it stay free
    (dofs, q), = free_modes(points, axis, fixed, body)
    assert len(dofs) == 597 and q.shape == (597, 3)
