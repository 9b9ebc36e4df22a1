"""States every method holds exactly on any shape: a body held at one displacement c on its whole
surface is at u = c with no stress, in every cell (slivers too), at the probes and on the surface.

A staggered sliver none of whose edges of a pair holds material took that shear strain from faces
that are no unknowns (zeros): c / h in such a cell of a rotated box, and through the cut cells' fit
0.14 E |c| / m in cells beside it."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from engine import simulate
from engine.geometry.cache import GeometryCache


@pytest.mark.parametrize("method", [{"kind": "staggered"}, {"kind": "dg", "degree": 1}], ids=["staggered", "dg1"])
@pytest.mark.parametrize("seed", [1, 3])
def test_a_body_held_at_one_displacement_everywhere_is_unstrained(method, seed):
    c = np.array([3e-4, -2e-4, 1e-4])
    box = trimesh.creation.box(extents=[0.9, 0.5, 0.3])
    box.apply_transform(trimesh.transformations.random_rotation_matrix(np.random.default_rng(seed).random(3)))
    spec = {"geometry": {"mesh": "box.stl"}, "grid": {"resolution": 16 if method["kind"] == "staggered" else 8},
            "method": method, "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3},
            "boundaries": [{"kind": "displacement", "name": "all", "region": {"box": [[-2, -2, -2], [2, 2, 2]]},
                            "value": c.tolist()}],
            "solver": {"rtol": 1e-12},
            "output": {"fields": ["displacement", "stress"], "surface": True, "probes": [[0, 0, 0]]}}
    r = simulate(spec, box.export(file_type="stl"), filename="box.stl", cache=GeometryCache(None))
    scale = 1e6 * np.linalg.norm(c)  # E |c| / 1 m
    for level in ("cells", "probes", "surface"):
        u = getattr(r.fields, level)["displacement"].reshape(-1, 3)
        s = getattr(r.fields, level)["stress"].reshape(-1, 6)
        u, s = u[np.isfinite(u).all(axis=1)], s[np.isfinite(s).all(axis=1)]
        assert len(u) and len(s)
        np.testing.assert_allclose(u, np.broadcast_to(c, u.shape), atol=1e-10 * np.linalg.norm(c), err_msg=level)
        assert np.abs(s).max() < 1e-9 * scale, (level, np.abs(s).max() / scale)  # measured 3e-13; 0.14 before


def _constant_stress(sigma: np.ndarray, normals: np.ndarray) -> list[dict]:
    """One traction boundary per outward facet direction n [m, d]: sigma n (a free body in balance)."""
    d = len(sigma)
    return [{"kind": "traction", "name": f"t{i}", "region": {"box": [[-9] * d, [9] * d]},
             "facing": {"direction": n.tolist(), "max_angle_deg": 1.0}, "value": (sigma @ n).tolist()}
            for i, n in enumerate(normals)]


def test_dg_holds_a_constant_stress_given_as_tractions_on_a_rotated_box():
    a = np.random.default_rng(4).uniform(-1e3, 1e3, (3, 3))
    sigma = (a + a.T) / 2
    box = trimesh.creation.box(extents=[0.9, 0.5, 0.3])
    box.apply_transform(trimesh.transformations.random_rotation_matrix(np.random.default_rng(2).random(3)))
    normals = np.unique(np.round(box.face_normals, 12), axis=0)
    spec = {"geometry": {"mesh": "box.stl"}, "grid": {"resolution": 6}, "method": {"kind": "dg", "degree": 1},
            "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3}, "boundaries": _constant_stress(sigma, normals),
            "solver": {"rtol": 1e-12}, "output": {"fields": ["stress"], "surface": True, "probes": [[0, 0, 0]]}}
    r = simulate(spec, box.export(file_type="stl"), filename="box.stl", cache=GeometryCache(None))
    want = np.array([sigma[0, 0], sigma[1, 1], sigma[2, 2], sigma[1, 2], sigma[0, 2], sigma[0, 1]])
    for level in ("cells", "probes", "surface"):
        s = getattr(r.fields, level)["stress"].reshape(-1, 6)
        s = s[np.isfinite(s).all(axis=1)]
        # the STL's float32 vertices tilt its facets' normals by ~1e-7 from the float64 ones the tractions use
        assert len(s) and np.abs(s - want).max() < 1e-6 * np.abs(sigma).max(), level  # measured 5.4e-8


@pytest.mark.parametrize("shear", [
    0.0,  # measured 2.7e-15 (8.5e-4 while the loads were the interpolation's transpose)
    pytest.param(1.0, marks=pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
        "measured (h = 0.1 on a 1 x 0.5 rectangle whose sides lie on grid planes): sigma_xx off by 0.093 of the shear "
        "in the corner cells (0.23 while the loads were the interpolation's transpose). At a corner the two ghost "
        "samples beyond it are tied to the body by one edge only, so both stay out and that edge is pruned; the "
        "energy's own force there is the load renormalised onto the sample inside, but the couple that gives each "
        "load the quadrature's first moments moves it back; without the couple the rectangle is exact to 3e-15 "
        "(a prototype; docs/benchmarks.md, 'A constant stress given as tractions')"))),
])
def test_staggered_rectangle_on_grid_planes_holds_a_constant_stress_given_as_tractions(shear):
    sigma = np.array([[1e3, shear * 1e3], [shear * 1e3, 5e2]])
    normals = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    spec = {"dimension": 2, "geometry": {"polygon": [[[0, 0], [1, 0], [1, 0.5], [0, 0.5]]]},
            "grid": {"resolution": 10}, "method": {"kind": "staggered", "solver": "direct"},
            "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3}, "boundaries": _constant_stress(sigma, normals),
            "solver": {"rtol": 1e-12}, "output": {"fields": ["stress"]}}
    r = simulate(spec, cache=GeometryCache(None))
    s = r.fields.cells["stress"].reshape(-1, 3)
    s = s[np.isfinite(s).all(axis=1)]
    want = np.array([sigma[0, 0], sigma[1, 1], sigma[0, 1]])
    assert len(s) and np.abs(s - want).max() < 1e-9 * 1e3, np.abs(s - want).max() / 1e3
