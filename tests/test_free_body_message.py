"""A free body whose loads do not balance: both methods name the net force and the net torque about
its centroid, as the vector [T_x, T_y, T_z] (2D: T_z).

A pure couple on a DG body was "loads do not balance (net force [0.0, -0.0, 0.0] N)", which
contradicts itself, and the staggered method wrote the torque about z as [100.0, 0.0, 0.0]."""

from __future__ import annotations

import pytest
import trimesh

import engine
from engine.solvers.rigid import UnbalancedLoadError, torque_vector


def shear_couple(kind: str) -> dict:
    """A 1 m cube held by nothing, sheared along y by +-100 Pa on its x faces: a couple of 100 N m about z."""
    def face(x: float, sign: float) -> dict:
        return {"kind": "traction", "region": {"halfspace": {"point": [x, 0, 0], "normal": [-sign, 0, 0]}},
                "facing": {"direction": [sign, 0, 0], "max_angle_deg": 10}, "value": [0, 100 * sign, 0]}

    return {"geometry": {"mesh": "cube.stl"}, "grid": {"resolution": 6}, "method": {"kind": kind},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3},
            "boundaries": [face(0.999, 1.0), face(0.001, -1.0)]}


@pytest.mark.parametrize("kind, expected", [
    ("dg", "boundaries: the displacement boundaries leave 6 rigid-body mode(s) of a body of 216 element(s) free and "
           "its loads do not balance (net force [0.0, 0.0, 0.0] N, net torque about its centroid [0.0, 0.0, 100.0] "
           "N m); add a displacement boundary on that body or balance the loads"),
    ("staggered", "net force [0.0, 0.0, 0.0] N, net torque about its centroid [0.0, 0.0, 100.0] N m"),
])
def test_a_pure_couple_on_a_free_body_names_its_torque(tmp_path, kind, expected):
    box = trimesh.creation.box(extents=(1, 1, 1))
    box.apply_translation((0.5, 0.5, 0.5))
    box.export(tmp_path / "cube.stl")
    with pytest.raises(UnbalancedLoadError) as caught:
        engine.simulate(shear_couple(kind), tmp_path / "cube.stl")
    assert expected in str(caught.value)


def test_torque_vector_turns_plane_work_into_the_axial_vector():
    # work on the rotations in the planes (0, 1), (0, 2), (1, 2): about z, -y and x
    assert torque_vector([3.0, 2.0, 1.0], 12) == [1.0, -2.0, 3.0]
    assert torque_vector([-0.0, 0.0, -0.0], 12) == [0.0, 0.0, 0.0] and str(torque_vector([-0.0], 9)) == "0.0"
