"""The realistic-part benchmarks' own logic (benchmarks/parts.py): the peer's patch selection, which
must take the same facets as the job voxelastic is given, and that job itself (no solves, no peer)."""

import numpy as np

from benchmarks import bracket, parts, scan
from schemas.job import parse_job


def test_facing_keeps_normals_within_the_angle():
    angles = np.radians([0.0, 19.0, 21.0, 90.0, 180.0])
    normals = np.column_stack([np.sin(angles), -np.cos(angles), np.zeros(5)])  # from -y towards +x
    rule = {"direction": [0.0, -2.0, 0.0], "max_angle_deg": 20.0}  # any length
    assert parts.facing(rule, normals).tolist() == [True, True, False, False, False]
    assert parts.facing(None, normals).all()


def test_regions_of_the_spec_forms():
    x = np.array([[0.0, 0.004, 0.0], [0.0, 0.006, 0.0], [0.5, 0.5, 0.5]])
    below = {"halfspace": {"point": [0.0, 0.005, 0.0], "normal": [0.0, 3.0, 0.0]}}  # the normal points out
    assert parts.inside(below, x).tolist() == [True, False, False]
    assert parts.inside({"box": [[-1, -1, -1], [0.1, 0.005, 1]]}, x).tolist() == [True, False, False]
    assert parts.inside({"sphere": {"center": [0.5, 0.5, 0.4], "radius": 0.1}}, x).tolist() == [False, False, True]


def test_the_jobs_are_valid_specs_with_the_parts_boundaries():
    points = [[0.0, 0.02, 0.0]]
    bunny = parse_job(parts.spec(scan.BUNNY, "bunny.stl", points, {"kind": "dg", "degree": 2}, 0.005))
    (held,) = bunny.boundaries
    assert held.kind == "displacement" and held.value == (0.0, 0.0, 0.0)
    assert held.facing.direction == (0.0, -1.0, 0.0) and held.facing.max_angle_deg == 20.0
    assert bunny.loads.gravity == (5 * 9.81, -9.81, 0.0) and bunny.material.density == 1240.0
    job = parse_job(parts.spec(bracket.part(), "bracket.stl", points, {"kind": "staggered"}, 0.004))
    *bolts, push = job.boundaries
    assert len(bolts) == 2 and all(b.facing is None for b in bolts)
    assert push.kind == "traction" and push.value == bracket.TRACTION and push.facing.direction == (-1.0, 0.0, 0.0)
    assert job.loads.gravity in (None, (0.0, 0.0, 0.0))


def test_selected_keeps_the_named_methods_at_the_given_sizes():
    runs = {"a": [("vox", {"kind": "staggered"}, h) for h in (4, 2, 1)], "b": [("peer", 2, h) for h in (8, 5, 3)]}
    args = parts.parser("").parse_args(["--quick"])
    assert parts.selected(runs, args) == {"a": runs["a"][:2], "b": runs["b"][:2]}
    args = parts.parser("").parse_args(["--method", "b", "--h", "6"])
    assert parts.selected(runs, args) == {"b": [("peer", 2, 6.0)]}
