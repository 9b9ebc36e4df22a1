"""Elasticity formulas against closed forms."""

import numpy as np
import pytest

from engine.material import Material, lame_parameters, stress, von_mises


def test_lame_parameters_closed_form():
    lam, mu = lame_parameters(1.0, 0.25)
    assert lam == pytest.approx(0.4, rel=1e-15) and mu == pytest.approx(0.4, rel=1e-15)
    lam, mu = lame_parameters(2.5, 0.0)
    assert lam == 0.0 and mu == 1.25


def test_uniaxial_stress_state_round_trip():
    E, nu, s = 210e9, 0.3, 1e6
    lam, mu = Material(E, nu).lame
    strain = np.array([s / E, -nu * s / E, -nu * s / E, 0, 0, 0])
    sig = stress(strain, lam, mu, 3)
    np.testing.assert_allclose(sig, [s, 0, 0, 0, 0, 0], atol=1e-9 * s)
    assert von_mises(sig, 3) == pytest.approx(s, rel=1e-14)


def test_pure_shear_and_hydrostatic():
    tau = 3.0
    assert von_mises(np.array([0, 0, 0, 0, 0, tau]), 3) == pytest.approx(np.sqrt(3) * tau, rel=1e-15)
    assert von_mises(np.array([5.0, 5.0, 5.0, 0, 0, 0]), 3) == pytest.approx(0.0, abs=1e-14)


def test_plane_strain_von_mises_uses_sigma_zz():
    E, nu = 1.0, 0.3
    lam, mu = lame_parameters(E, nu)
    eps2 = np.array([1e-3, -2e-4, 5e-4])  # xx, yy, xy with eps_zz = 0
    sig2 = stress(eps2, lam, mu, 2)
    eps3 = np.array([1e-3, -2e-4, 0.0, 0.0, 0.0, 5e-4])
    sig3 = stress(eps3, lam, mu, 3)
    np.testing.assert_allclose(sig2, sig3[[0, 1, 5]], rtol=1e-14)
    assert von_mises(sig2, 2, lam, mu) == pytest.approx(von_mises(sig3, 3), rel=1e-14)
    with pytest.raises(ValueError, match="plane strain needs lam and mu"):
        von_mises(sig2, 2)


@pytest.mark.parametrize("method", [{"kind": "staggered"}, {"kind": "dg", "degree": 1}])
def test_the_ends_of_the_accepted_modulus_range_solve_the_same_scaled_problem(method):
    """schemas.job.SCALE_RANGE: at E = 1e-100 and 1e100 Pa the displacement is the E = 1e7 one times
    1e7 / E (linear elasticity), to round-off; beyond the range the spec is refused."""
    import json
    from pathlib import Path

    from engine import simulate
    from schemas import SpecError, parse_job

    root = Path(__file__).resolve().parents[1] / "examples"
    spec = json.loads((root / "cantilever.json").read_text())
    spec.update(grid={"resolution": 12, "padding": 1}, method=method)
    mesh = (root / "cantilever.stl").read_bytes()

    def probe(E: float) -> np.ndarray:
        spec["material"]["youngs_modulus"] = E
        return simulate(spec, mesh, filename="cantilever.stl").fields.probes["displacement"]

    reference = probe(1e7)
    for E in (1e-100, 1e100):
        np.testing.assert_allclose(probe(E) * (E / 1e7), reference, rtol=1e-6, atol=1e-9 * np.abs(reference).max())
    spec["material"]["youngs_modulus"] = 1e101
    with pytest.raises(SpecError, match=r"material.youngs_modulus: 1e\+101 Pa is outside 1e-100 .. 1e\+100 Pa"):
        parse_job(spec)
