"""Clustered surface quadrature (engine.clusters): what the coarse multigrid levels' hold terms use
on meshes finer than the grid."""

import numpy as np
import pytest
import trimesh

from engine.boundary import CLUSTER, surface_quadrature
from engine.clusters import clustered_rule


def _rules(mesh, spacing):
    facets = mesh.vertices[mesh.faces]
    return surface_quadrature(facets, spacing), surface_quadrature(facets, spacing, merge=True)


def test_merged_rule_keeps_area_area_vector_and_second_moments_with_fewer_points():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    mesh.vertices = mesh.vertices * [1.0, 0.6, 0.3] + [0.3, 0.1, -0.2]  # an ellipsoid off the origin
    (x, w, n), (xm, wm, nm) = _rules(mesh, 0.3)
    assert len(wm) < len(w) / 4  # 7 points per triangle against 4 per cluster of several
    assert wm.sum() == pytest.approx(mesh.area, rel=1e-13)
    np.testing.assert_allclose((wm[:, None] * nm).sum(axis=0), 0.0, atol=1e-13)  # closed: in balance
    np.testing.assert_allclose(wm @ xm, w @ x, rtol=1e-12)  # first moments exact
    # second moments: exact in each cluster's tangent plane, so off by its curvature only
    second, merged = np.einsum("q,qi,qj->ij", w, x, x), np.einsum("q,qi,qj->ij", wm, xm, xm)
    assert np.abs(merged - second).max() < 1e-4 * np.abs(second).max()
    torque = (wm[:, None] * np.cross(xm - xm.mean(axis=0), nm)).sum(axis=0)
    assert np.abs(torque).max() < 1e-6 * wm.sum()
    np.testing.assert_allclose(np.linalg.norm(nm, axis=1), 1.0, atol=1e-3)


def test_sharp_edges_and_coarse_pieces_are_not_merged():
    cube = trimesh.creation.box(extents=[1.0, 1.0, 1.0]).subdivide().subdivide().subdivide()
    _, (xm, wm, nm) = _rules(cube, 1.0)  # every piece (edges <= 0.18) is below CLUSTER * spacing
    # no cluster takes pieces of two faces: every normal is a face's
    assert np.allclose(np.abs(nm).max(axis=1), 1.0, atol=1e-12)
    for k in range(3):
        for side in (-0.5, 0.5):
            on = np.isclose(nm[:, k], np.sign(side))
            assert np.allclose(xm[on, k], side, atol=1e-12) and wm[on].sum() == pytest.approx(1.0, rel=1e-12)
    big = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    plain, merged = surface_quadrature(big, 2.1), surface_quadrature(big, 2.1, merge=True)
    assert 1.0 > CLUSTER * 2.1  # the triangle is too large to merge: the degree-5 rule either way
    for a, b in zip(plain, merged):
        np.testing.assert_array_equal(a, b)


def test_one_straight_segment_gets_two_point_gauss():
    seg = np.array([[[0.0, 0.0], [1.0, 0.0]]])
    x, w, n = clustered_rule(seg, np.array([1.0]), np.array([[0.0, -1.0]]), 10.0)
    np.testing.assert_allclose(np.sort(x[:, 0]), 0.5 + np.array([-1, 1]) / (2 * np.sqrt(3)), rtol=1e-14)
    np.testing.assert_allclose(w, 0.5)
    assert (w * x[:, 0] ** 3).sum() == pytest.approx(0.25, rel=1e-14)  # exact to degree 3
