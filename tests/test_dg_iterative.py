"""DG's iterative solver (p-multigrid CG, engine/solvers/pmultigrid.py) against its sparse Cholesky.

    .venv/bin/python -m pytest -q tests/test_dg_iterative.py

The two solve the same matrix, so to a tight rtol they must give the same coefficients: clamped and
free (rigid modes bordered out), k = 1 (coarse space: constants) and k = 2 (coarse: k = 1, and below
it the constants when that level is large), statics and a backward-Euler step, and a penalty too
small to be positive definite (CG finds the negative curvature and the penalty doubles as it does on
a failed Cholesky). Its speed at scale is measured in ``benchmarks.dg`` (docs/benchmarks.md, "DG at
scale").
"""

import numpy as np
import pytest
import trimesh

from engine.boundary import Prescribed, SurfaceLoad
from engine.dg.elasticity import DGElasticity
from engine.geometry.slicing import slice_cells
from engine.grid import Grid
from engine.material import Material
from tests.conftest import surface_of
from tests.test_dg import EVERYWHERE, MAT, box_region, sphere_cut

RTOL = 1e-9  # the k = 2 bar's true residual floors near 1e-10 (its conditioning)


def bar(h: float, **kw) -> DGElasticity:
    """A 2 x 0.5 x 0.5 cantilever cut off the grid on every side, clamped at its root, under gravity."""
    mesh = trimesh.creation.box(extents=[2.0, 0.5, 0.5])
    mesh.apply_translation([1.0 + 0.37 * h, 0.25 + 0.21 * h, 0.25 + 0.13 * h])
    s = surface_of(mesh)
    n = np.ceil((np.array([2.0, 0.5, 0.5]) + 2 * h) / h).astype(int) + 1
    cut = slice_cells(s, Grid(origin=(-h, -h, -h), spacing=h, shape=tuple(int(v) for v in n)))
    root = 0.37 * h
    kw.setdefault("material", MAT)
    return DGElasticity(cut=cut, surface=s, flux="ip", body_force=np.array([0.0, 0.0, -1e-3]),
                        prescribed=[Prescribed(box_region([root - 1, -1, -1], [root + 1e-9, 2, 2]), (0, 0, 0),
                                               "clamp")],
                        rtol=RTOL, **kw)


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("degree", [1, 2])
def test_the_iterative_solve_equals_the_direct_one_on_a_clamped_cut_bar(degree):
    direct = bar(0.125, degree=degree, solver_kind="direct")
    iterative = bar(0.125, degree=degree, solver_kind="iterative")
    assert direct.solver.backend == "pardiso" and iterative.solver.backend.startswith("pmg-cg")
    a, b = direct.solve(), iterative.solve()
    assert b.stats.residual <= RTOL and 1 < b.stats.iterations < 80, b.stats
    assert relative(b.u, a.u) < 1e-8


def test_iterations_do_not_grow_with_the_grid():
    # the coarse level is solved exactly, so only the smoother's reach matters: h-independent counts
    counts = [bar(h, degree=2, solver_kind="iterative").solve().stats.iterations for h in (0.25, 0.125, 0.0625)]
    assert max(counts) <= 1.3 * min(counts), counts


def free_sphere(degree: int, kind: str) -> DGElasticity:
    """A thick sphere (radii 1, 0.5) under internal pressure and no displacement boundary."""
    s, cut = sphere_cut(6, 1.0, 0.5)
    inner = SurfaceLoad(EVERYWHERE, "inside", pressure=1.0)
    inner.region = type("Inner", (), {"clip": lambda self, f, tolerance=None: (
        f[np.linalg.norm(f.mean(axis=1), axis=1) < 0.75],
        np.nonzero(np.linalg.norm(f.mean(axis=1), axis=1) < 0.75)[0])})()
    return DGElasticity(cut=cut, surface=s, material=MAT, degree=degree, flux="ip", surface_loads=[inner],
                        solver_kind=kind, rtol=RTOL)


@pytest.mark.parametrize("degree", [1, 2])
def test_a_free_body_keeps_its_rigid_modes_out_of_the_iterative_solution(degree):
    runs = [free_sphere(degree, kind) for kind in ("direct", "iterative")]
    assert runs[1].modes and runs[1].solver.modes is not None  # six free rigid motions
    a, b = (m.solve() for m in runs)
    assert relative(b.u, a.u) < 1e-8
    Q = runs[1]._mode_matrix()
    assert np.linalg.norm(Q.T @ b.u.reshape(-1)) < 1e-10 * np.linalg.norm(b.u)


def test_a_backward_euler_step_matches():
    runs = [bar(0.125, degree=2, solver_kind=kind) for kind in ("direct", "iterative")]
    for m in runs:
        m.set_time_step(1e-2)
    a, b = (m.solve(inertia=np.zeros((m.elements.count, 3, m.n))) for m in runs)
    assert relative(b.u, a.u) < 1e-8


def test_a_penalty_too_small_doubles_on_the_iterative_path_too():
    # eta 0.05 leaves k = 1's IP matrix indefinite (it is positive definite between 1.25 and 1.5 on the
    # ball, docs/benchmarks.md): the iterative set-up or CG must notice and double, never return a field
    m = bar(0.125, degree=1, penalty=0.05, solver_kind="iterative")
    st = m.solve()
    assert m.eta > 0.05 and any(w.startswith("the penalty was doubled") for w in m.warnings)
    reference = bar(0.125, degree=1, penalty=m.eta, solver_kind="direct")
    assert reference.eta == m.eta  # positive definite at the eta the iterative path settled on
    assert relative(st.u, reference.solve().u) < 1e-8


def test_an_unknown_solver_kind_is_named():
    with pytest.raises(Exception, match="method.solver"):
        bar(0.25, degree=1, solver_kind="amg")


def test_auto_picks_by_size():
    from engine.dg import elasticity

    m = bar(0.25, degree=1)
    assert m.size < elasticity.DIRECT_LIMIT[1] and m.solver.backend == "pardiso"
    elasticity_limit = dict(elasticity.DIRECT_LIMIT)
    try:
        elasticity.DIRECT_LIMIT[1] = m.size - 1
        assert bar(0.25, degree=1).solver.backend.startswith("pmg-cg")
        # nearly incompressible: Cholesky up to the larger limit (CG's iterations grow like sqrt(lambda / mu))
        soft = Material(1.0, 0.4999)
        assert bar(0.25, degree=1, material=soft).solver.backend == "pardiso"
    finally:
        elasticity.DIRECT_LIMIT.update(elasticity_limit)


@pytest.mark.parametrize("free", [False, True])
def test_three_levels_when_the_k1_level_is_large(monkeypatch, free):
    # above COARSE_DIRECT coarse unknowns the k = 1 level is cycled over the constants, not factorised
    from engine.dg import elasticity

    monkeypatch.setattr(elasticity, "COARSE_DIRECT", 100)
    make = (lambda kind: free_sphere(2, kind)) if free else (lambda kind: bar(0.125, degree=2, solver_kind=kind))
    runs = [make(kind) for kind in ("direct", "iterative")]
    assert len(runs[1].solver.top.sizes) == 3, runs[1].solver.backend
    a, b = (m.solve() for m in runs)
    assert b.stats.residual <= RTOL
    assert relative(b.u, a.u) < 1e-7
