"""Multigrid-preconditioned CG on the staggered operator: iterations level off under refinement.

A unit sphere (icosphere, 20k triangles) clamped below z = -0.7 or -0.8 under gravity, nu = 0.3,
rtol 1e-8. The clamp holds the sphere's surface below the plane (Nitsche, rediscretised on every
level): 12 / 13 / 14 (clamp -0.7) and 12 / 14 / 15 (-0.8) iterations at 32^3, 64^3, 128^3. When it
held the samples below the plane: 15 / 15 / 15 and 14 / 16 / 18 with the boundary smoothing,
18 / 22 / 24 and 19 / 30 / 41 without.
"""

import numpy as np
import pytest
import trimesh

from engine.geometry.cache import GeometryCache
from engine.pipeline import run


@pytest.fixture(scope="module")
def sphere(tmp_path_factory):
    path = tmp_path_factory.mktemp("mg") / "sphere.stl"
    trimesh.creation.icosphere(subdivisions=5, radius=1.0).export(path)
    return path


def spec(resolution: int, nu: float = 0.3, clamp: float = -0.7) -> dict:
    return {
        "geometry": {"mesh": "sphere.stl"},
        "grid": {"resolution": resolution},
        "method": {"kind": "staggered", "solver": "iterative"},
        "material": {"youngs_modulus": 1e6, "poisson_ratio": nu, "density": 1000},
        "loads": {"gravity": [0, 0, -9.81]},
        "boundaries": [{"kind": "displacement", "name": "base", "region": {"box": [[-2, -2, -2], [2, 2, clamp]]}, "value": [0, 0, 0]}],
        "solver": {"rtol": 1e-8},
        "output": {"fields": ["displacement"], "probes": [[0, 0, 0.95]], "surface": False},
    }


@pytest.mark.parametrize("clamp", [-0.7, -0.8])
def test_iterations_grow_at_most_30_percent_per_refinement(sphere, clamp):
    iterations, tips = [], []
    for n in (32, 64, 128):
        result = run(spec(n, clamp=clamp), sphere, cache=GeometryCache(None))
        assert result.solver.residual <= 1e-8
        iterations.append(result.solver.iterations)
        tips.append(result.fields.probes["displacement"][0, 2])
    assert all(b <= 1.3 * a for a, b in zip(iterations, iterations[1:])), iterations
    # and the answer settles: the top sinks, successive changes stay within 1.5% of the tip. The
    # clamp holds its surface patch, whose rim (a clamped-free transition, u ~ r^(1/2)) is resolved
    # at first order at best: measured changes 6.6e-5, 4.6e-5 (-0.7) and 2.5e-4, 2.4e-4 (-0.8) on
    # tips of 1.6e-2 and 2.1e-2 (the hold of whole samples gave 6.4e-4, 3.4e-4 at -0.8)
    assert all(t < 0 for t in tips)
    assert all(abs(b - a) < 0.015 * abs(b) for a, b in zip(tips, tips[1:])), tips
