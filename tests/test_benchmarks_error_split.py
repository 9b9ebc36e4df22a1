"""benchmarks.error_split's rigid split: a rigid motion is all rigid part, a strain is none of it."""

import numpy as np

from benchmarks.error_split import rigid_split


def test_a_rigid_motion_splits_off_exactly_and_a_symmetric_strain_leaves_no_rigid_part():
    g = np.linspace(-1, 1, 7)
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)  # centred, second moments ~ I
    t, w = np.array([1e-3, -2e-3, 5e-4]), np.array([3e-4, 1e-4, -2e-4])
    coef, rest = rigid_split(x, t + np.cross(w, x))
    np.testing.assert_allclose(coef, np.concatenate([t, w]), atol=1e-15)
    assert np.abs(rest).max() < 1e-15
    strain = np.array([[1.0, 0.2, 0.0], [0.2, -0.5, 0.1], [0.0, 0.1, 0.3]]) * 1e-3  # symmetric: no rotation
    coef, rest = rigid_split(x, x @ strain.T + t)
    np.testing.assert_allclose(coef[:3], t, atol=1e-15)
    np.testing.assert_allclose(coef[3:], 0, atol=1e-15)
    np.testing.assert_allclose(rest, x @ strain.T, atol=1e-15)
