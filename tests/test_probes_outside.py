"""Probes outside the solid: decided from the surface alone, the same for both methods, NaN in every
field and named in the warning; points on the surface up to round-off sample the solid.

The staggered method used to give a probe 0.05 m beyond a cube's pulled face half a vector
([-1.4e-9, nan, nan]) and a finite von Mises with no warning, and a disk's probe 2 cm outside a
whole finite state."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import engine
from conftest import surface_of
from engine.geometry.containment import in_solid, surface_tolerance
from engine.output import outside_probes_warning

FIELDS = ["displacement", "strain", "stress", "von_mises", "pressure"]
# outside by 0.05 m and by 3e-6 m (above the 1.7e-6 m round-off of a 1 m cube); on the face, on
# it up to round-off, at a corner, at the centre
OUTSIDE = [[1.05, 0.5, 0.5], [1 + 3e-6, 0.5, 0.5]]
INSIDE = [[1.0, 0.5, 0.5], [1 + 1e-7, 0.5, 0.5], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5]]


def cube(tmp_path):
    box = trimesh.creation.box(extents=(1, 1, 1))
    box.apply_translation((0.5, 0.5, 0.5))
    path = tmp_path / "cube.stl"
    box.export(path)
    return path


def pulled_cube(method: dict, resolution: int) -> dict:
    return {
        "geometry": {"mesh": "cube.stl"}, "grid": {"resolution": resolution}, "method": method,
        "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3},
        "boundaries": [
            {"kind": "displacement", "region": {"halfspace": {"point": [0.001, 0, 0], "normal": [1, 0, 0]}},
             "value": [0, 0, 0]},
            {"kind": "traction", "region": {"halfspace": {"point": [0.999, 0, 0], "normal": [-1, 0, 0]}},
             "facing": {"direction": [1, 0, 0], "max_angle_deg": 10}, "value": [1e4, 0, 0]}],
        "output": {"fields": FIELDS, "probes": OUTSIDE + INSIDE},
    }


@pytest.mark.parametrize("method, resolution", [({"kind": "staggered"}, 12), ({"kind": "dg", "degree": 1}, 6)])
def test_a_probe_just_outside_is_nan_in_every_field_and_one_on_the_surface_is_inside(tmp_path, method, resolution):
    result = engine.simulate(pulled_cube(method, resolution), cube(tmp_path))
    n = len(OUTSIDE)
    for name in FIELDS:
        values = np.asarray(result.fields.probes[name]).reshape(len(OUTSIDE + INSIDE), -1)
        assert np.isnan(values[:n]).all(), (name, values[:n])
        assert np.isfinite(values[n:]).all(), (name, values[n:])
    # the pulled face moves by about t L / E = 1e-3 m wherever the probe is taken on it
    assert result.fields.probes["displacement"][n][0] == pytest.approx(9.6e-4, rel=0.02)
    assert outside_probes_warning(result) == (
        "2 of 6 probes lie outside the solid, where there is nothing to sample (NaN in their values): "
        "(1.05, 0.5, 0.5), (1.000003, 0.5, 0.5)")


def test_a_disk_probe_two_centimetres_outside_is_nan_at_every_step():
    angles = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    spec = {
        "dimension": 2, "geometry": {"polygon": [np.column_stack([np.cos(angles), np.sin(angles)]).tolist()]},
        "grid": {"resolution": 20}, "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3},
        "boundaries": [{"kind": "pressure", "region": {"all": True}, "value": 1e4}],
        "analysis": {"kind": "quasistatic", "steps": 2},
        "output": {"fields": ["displacement", "stress", "pressure", "von_mises"], "probes": [[0.5, 0], [1.02, 0]]},
    }
    result = engine.simulate(spec)
    for level in [result.fields, *result.steps]:
        for name, values in level.probes.items():
            assert np.isnan(values[1]).all(), (name, values)
            assert np.isfinite(values[0]).all(), (name, values)
    # uniform compression of a free disk (plane strain): u_r = -p r (1 + nu)(1 - 2 nu) / E
    assert result.fields.probes["displacement"][0][0] == pytest.approx(-1e4 * 0.5 * 1.3 * 0.4 / 1e7, rel=1e-3)


def test_in_solid_counts_the_surface_up_to_round_off_as_inside():
    box = trimesh.creation.box(extents=(2, 2, 2))
    surface = surface_of(box)
    h = 0.25
    tol = surface_tolerance(surface, h)
    assert tol == pytest.approx(1e-6 * np.sqrt(12))
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 1], [1, 1, 0.3], [1 + 0.5 * tol, 0, 0],
                       [1 + 2 * tol, 0, 0], [1.05, 0, 0], [5, 5, 5], [-1 - 2 * tol, -1, -1]])
    assert in_solid(surface, points, h).tolist() == [True] * 5 + [False] * 4


@pytest.mark.parametrize("method, resolution", [({"kind": "staggered"}, 8), ({"kind": "dg", "degree": 1}, 4)])
def test_probes_far_away_are_nan_at_every_step_and_the_method_is_not_asked(tmp_path, method, resolution):
    # a probe at 1e308 m overflowed the staggered strain fit: "Eigenvalues did not converge", a
    # traceback from the CLI and a failed job in the service
    spec = pulled_cube(method, resolution)
    far = [[1e308, 0.5, 0.5], [-1e300, 1e300, 1e300], [0.5, 1e30, 0.5]]
    spec["output"]["probes"] = [far[0], [0.5, 0.5, 0.5], *far[1:]]
    spec["analysis"] = {"kind": "quasistatic", "steps": 2}
    result = engine.simulate(spec, cube(tmp_path))
    for level in [result.fields, *result.steps]:
        assert sorted(level.probes) == sorted(FIELDS)
        for name, values in level.probes.items():
            values = np.asarray(values).reshape(4, -1)
            assert np.isnan(values[[0, 2, 3]]).all() and np.isfinite(values[1]).all(), (name, values)
    assert outside_probes_warning(result).startswith("3 of 4 probes lie outside the solid")
    # none inside: every field is there, NaN throughout
    spec["output"]["probes"] = far
    result = engine.simulate(spec, cube(tmp_path))
    assert {name: np.shape(v) for name, v in result.fields.probes.items()} == {
        "displacement": (3, 3), "strain": (3, 6), "stress": (3, 6), "von_mises": (3,), "pressure": (3,)}
    assert all(np.isnan(v).all() for v in result.fields.probes.values())
