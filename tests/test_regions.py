"""Regions: closed membership, exact clipping by planes, bounded clipping by balls."""

import numpy as np
import pytest
import trimesh

from engine.errors import VoxelasticError
from engine.boundary import facet_measures, select_patch
from engine.regions import Ball, make_region
from schemas import parse_job


def regions_of(*specs, dim=3):
    job = {
        "dimension": dim,
        "geometry": {"mesh": "m.stl"},
        "grid": {"resolution": 8},
        "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3},
        "boundaries": [{"kind": "pressure", "region": r, "value": 1.0} for r in specs],
    }
    return [make_region(b.region, dim) for b in parse_job(job).boundaries]


def area_vectors(tris):
    return 0.5 * np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])


def test_membership_is_closed_and_normals_are_normalised():
    box, ball, half, everything = regions_of(
        {"box": [[0, 0, 0], [1, 1, 1]]},
        {"sphere": {"center": [0, 0, 0], "radius": 1.0}},
        {"halfspace": {"point": [0.5, 0, 0], "normal": [3, 0, 0]}},
        {"all": True},
    )
    pts = np.array([[1.0, 0.5, 0.0], [1.0 + 1e-12, 0.5, 0.5], [0.0, 0.0, 1.0], [0.5, 9.0, -9.0]])
    np.testing.assert_array_equal(box.contains(pts), [True, False, True, False])
    np.testing.assert_array_equal(ball.contains(pts), [False, False, True, False])
    np.testing.assert_array_equal(half.contains(pts), [False, False, True, True])
    np.testing.assert_array_equal(everything.contains(pts), [True] * 4)
    assert box.contains(pts[1:2], slack=1e-9)[0]


def test_halfspace_clips_a_cube_surface_exactly():
    cube = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    (half,) = regions_of({"halfspace": {"point": [0.3, 0, 0], "normal": [1, 0, 0]}})
    pieces, source = half.clip(cube.triangles)
    vec = area_vectors(pieces)
    assert abs(np.linalg.norm(vec, axis=1).sum() - (1.0 + 4 * 0.3)) < 1e-14
    # the clipped closed surface plus the cap (area 1, normal +x) is closed again
    np.testing.assert_allclose(vec.sum(axis=0), [-1.0, 0.0, 0.0], atol=1e-14)
    assert np.all(pieces[:, :, 0] <= 0.3 + 1e-15)
    # every piece keeps its facet's orientation
    normals = cube.face_normals[source]
    assert np.all(np.einsum("ij,ij->i", vec, normals) > 0)


def test_thin_end_box_selects_the_end_face_and_its_strips():
    bar = trimesh.creation.box(bounds=[[0, -0.1, -0.1], [1, 0.1, 0.1]])
    (end,) = regions_of({"box": [[0.999, -0.2, -0.2], [1.1, 0.2, 0.2]]})
    pieces, _ = end.clip(bar.triangles)
    area = np.linalg.norm(area_vectors(pieces), axis=1).sum()
    assert abs(area - (0.04 + 4 * 0.2 * 0.001)) < 1e-14


def test_faces_off_a_plane_by_round_off_are_selected_whole():
    # hex slicing leaves the end face of a bar 1e-14 relative off the mesh's plane, either side
    bar = trimesh.creation.box(bounds=[[0, -0.1, -0.1], [2, 0.1, 0.1]]).triangles
    jitter = np.random.default_rng(0).uniform(-5e-14, 5e-14, bar.shape)
    (end,) = regions_of({"box": [[2.0, -1, -1], [3, 1, 1]]})
    (half,) = regions_of({"halfspace": {"point": [2.0, 0, 0], "normal": [-1, 0, 0]}})
    for region in (end, half):
        pieces, _ = region.clip(bar + jitter)
        assert abs(np.linalg.norm(area_vectors(pieces), axis=1).sum() - 0.04) < 1e-12
    # an explicit zero tolerance is the exact clip, which loses part of the face
    pieces, _ = end.clip(bar + jitter, tolerance=0.0)
    assert np.linalg.norm(area_vectors(pieces), axis=1).sum() < 0.04 - 1e-3


def test_ball_clipping_error_is_bounded_by_tolerance_times_rim():
    plate = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]], float)
    ball = Ball(np.zeros(3), 0.5)
    exact, rim = np.pi * 0.25, np.pi
    errors = []
    for tol in (2e-2, 2e-3, 2e-4):
        pieces, source = ball.clip(plate, tolerance=tol)
        area = np.linalg.norm(area_vectors(pieces), axis=1).sum()
        errors.append(abs(area - exact))
        assert errors[-1] <= tol * rim
        assert set(np.unique(source)) <= {0, 1}
    assert errors[2] < errors[0]


def test_2d_segments_are_clipped_exactly():
    square = np.array([[[0, 0], [1, 0]], [[1, 0], [1, 1]], [[1, 1], [0, 1]], [[0, 1], [0, 0]]], float)
    (box,) = regions_of({"box": [[0.25, -1], [2, 0.5]]}, dim=2)
    pieces, source = box.clip(square)
    lengths = np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1)
    assert abs(lengths.sum() - (0.75 + 0.5)) < 1e-15
    np.testing.assert_array_equal(source, [0, 1])
    np.testing.assert_allclose(pieces[0], [[0.25, 0], [1, 0]])  # direction kept


def test_empty_selection_names_the_boundary_and_the_gap():
    square = np.array([[[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [1.0, 1.0]]])
    region = make_region(type("R", (), {"box": [[2.0, -1.0], [3.0, 2.0]]})(), 2)
    with pytest.raises(VoxelasticError, match=r"boundaries.1 \(tip_load\): the region holds no part of the mesh surface "
                                              r"\(its region is 1 m from the nearest surface vertex\)"):
        select_patch(region, square, "boundaries.1 (tip_load)")
    pieces, _ = select_patch(make_region(type("R", (), {"box": [[0.5, -1.0], [3.0, 2.0]]})(), 2), square, "b")
    assert abs(np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1).sum() - 1.5) < 1e-15


def test_a_ball_clips_a_sliver_in_few_pieces_and_keeps_its_area():
    # a needle 1 m x 4 mm crossed twice by a ball's surface: quartering the straddling pieces down to
    # the ball's tolerance (radius / 1000) made 13,104 pieces, more than that tolerance fits along the
    # needle (5,000); inside is x in [0.3, 0.7], area 0.002 (0.7^2 - 0.3^2)
    needle = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.004, 0.0]]])
    pieces, source = Ball(np.array([0.5, 0.0, 0.0]), 0.2).clip(needle)
    assert len(pieces) < 1.0 / (0.2 / 1000), len(pieces)
    assert np.all(source == 0)
    assert facet_measures(pieces).sum() == pytest.approx(0.002 * (0.7**2 - 0.3**2), rel=1e-3)
    normals = np.cross(pieces[:, 1] - pieces[:, 0], pieces[:, 2] - pieces[:, 0])
    assert np.all(normals[:, 2] > 0)  # every piece keeps the needle's orientation


def test_a_facing_ball_that_keeps_no_facet_names_the_boundary():
    """A sphere region whose facing filter keeps no facet handed the ball nothing to clip, and the
    clip's empty concatenation was a ValueError: a traceback from run, a 500 from the service."""
    from engine.boundary import Facing

    cube = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    facets = cube.vertices[cube.faces]
    ball = Ball(np.array([0.5, 0.5, 0.5]), 0.3)
    pieces, source = ball.clip(facets[:0])
    assert pieces.shape == (0, 3, 3) and source.shape == (0,) and source.dtype == np.int64
    upward = Facing(ball, np.array([0.0, 0.0, 1.0]), 30.0)
    assert facet_measures(select_patch(upward, facets, "b")[0]).sum() == pytest.approx(0.3**2 * np.pi / 4, rel=2e-2)
    sideways = Facing(ball, np.array([1.0, -1.0, 0.0]), 10.0)  # the cube's normals are 45 degrees off
    with pytest.raises(VoxelasticError, match=r"^boundaries.0 \(seat\): none of the 0.21\d* m\^2 of surface in its region "
                                              r"faces within 10 degrees of \(0.707, -0.707, 0\)"):
        select_patch(sideways, facets, "boundaries.0 (seat)")
