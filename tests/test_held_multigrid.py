"""The V-cycle beside held surfaces near incompressibility (issue 21): coarse surface terms as the
Galerkin product of the finer level's (engine/staggered/galerkin.py) and exact vertex-patch solves in
the held band (engine/staggered/patches.py; the smoother's formula is checked against assembled
matrices in tests/test_staggered_incompressible.py)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from engine import simulate
from engine.geometry.cache import GeometryCache
from engine.runtime import device_array
from engine.staggered import kernels
from engine.staggered.curls import CurlSmoother
from engine.staggered.galerkin import prolongation_matrix
from engine.staggered.multigrid import _curl_inverse, _lanczos_largest
from engine.staggered.operator import make_coarse_level
from tests.test_staggered_incompressible import assembled, band_solves, curls, held_body


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("kind", [kernels.LINEAR, kernels.FACE])
def test_prolongation_matrix_is_the_cycles_prolongation(d, kind, rng):
    fine = held_body(d).level
    coarse = make_coarse_level(fine)
    v = rng.standard_normal((d, coarse.size)) * coarse.active
    x = fine.zeros()
    kernels.prolong_add(d, kind, fine.coords, device_array(fine.layout.parents(coarse.layout)), fine.mask,
                        device_array(v, fine.dtype), x)
    comp, pos = np.nonzero(fine.free)
    P, keys = prolongation_matrix(fine, coarse, comp, pos, kind)
    assert np.all(coarse.active[keys // coarse.size, keys % coarse.size])
    want = x.to_numpy()[comp, pos]
    got = P @ v[keys // coarse.size, keys % coarse.size]
    assert np.abs(want).max() > 0
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def shell_iterations(nu: float) -> int:
    """CG iterations (rtol 1e-6, the V-cycle) of the shell of benchmarks/staggered.py (radii 1 and
    0.6, held below z = -0.8, gravity) at 32 cells across."""
    from benchmarks.staggered import job, shell_mesh

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "shell.stl"
        shell_mesh(path)
        r = simulate(job(str(path), 32, nu, 1e-6, "cpu"), path, cache=GeometryCache(None))
    return r.solver.iterations


def test_held_shell_iterations_near_incompressibility():
    # measured: 8 / 11 / 10 / 16 iterations at nu 0.3 / 0.45 / 0.49 / 0.4999 (64^3: 10 / 14 / 14 / 25,
    # 128^3 13 / - / - / 32); with the coarse holds rediscretised and no patches 0.4999 took 56 (64^3
    # 76, 128^3 108); with the patches and the power iteration's bound 0.45 took 71 (64^3: 371)
    base = shell_iterations(0.3)
    assert shell_iterations(0.45) <= 2 * base
    assert shell_iterations(0.49) <= 2 * base
    assert shell_iterations(0.4999) <= 3 * base


@pytest.mark.parametrize("d", [2, 3])
def test_smoothing_bound_is_the_largest_eigenvalue(d):
    """The Chebyshev smoothing's upper bound on the curl path comes from CG's Lanczos coefficients
    (12 steps): within 10% of the largest eigenvalue of M^-1 A (dense, from assembled matrices), never
    above it. Power iteration's 12 steps gave 12.5 where it was 15.3 on the 64^3 held shell at nu 0.45,
    and the smoothing then amplified what lay above (371 CG iterations)."""
    level = held_body(d).level
    level.set_shift(3.0, 1.0)  # ``assembled`` reads the mass; the smoother and the bound see it too
    A, comp, pos = assembled(level)
    C = curls(level, comp, pos)
    number = -np.ones((d, level.size), dtype=np.int64)
    number[comp, pos] = np.arange(len(comp))
    theta = np.asarray((C.T @ A @ C).diagonal()).ravel()
    M = np.diag(1.0 / A.diagonal()) + (C @ sp.diags(np.where(theta > 0, 1.0 / np.where(theta > 0, theta, 1), 0)) @ C.T).toarray()
    M += band_solves(level, A, number).toarray()
    largest = float(np.max(np.linalg.eigvals(M @ A.toarray()).real))
    estimate = _lanczos_largest(level, _curl_inverse(CurlSmoother(level)))
    assert 0.9 * largest <= estimate <= largest * (1 + 1e-9), (estimate, largest)
