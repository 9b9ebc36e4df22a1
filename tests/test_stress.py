"""The cheap cases of the numerical-stability stress suite (:mod:`verification.stress`) as tests.

    .venv/bin/python -m pytest -q tests/test_stress.py

Every test runs the suite's own case functions at its quick sizes (staggered h = W / 6, DG k = 2
at h = W / 3 on the 1 m x 0.25 m x 0.25 m cantilever) and asserts their numbers. Where the engine
falls short today the test is a strict xfail whose reason gives the measured numbers: it starts
failing the day the engine changes, and then the mark goes. The whole suite, with the expensive
cases (nu = 0.4999, the full offset sweep, 10% strain on the staggered grid...), is
``python -m benchmarks.stress``.
"""

import dataclasses
import math

import numpy as np
import pytest

from verification import stress as S

SIZE = S.QUICK
METHODS = ["staggered", "dg"]


def assert_passed(rows: list[S.Row]) -> None:
    for row in rows:
        assert row.passed, (row.case, row.method, row.params, row.quantity, row.note)


# ----------------------------------------------------------------------------- material extremes


@pytest.mark.parametrize("method", METHODS)
def test_youngs_modulus_from_1_to_1e9_leaves_the_strains_unchanged(method):
    rows = S.youngs_case(method, SIZE)
    assert_passed(rows)
    summaries = [r for r in rows if "max_relative_difference" in r.values]
    assert len(summaries) == 2  # scaled and fixed traction
    for r in summaries:
        assert r.values["max_relative_difference"] <= 1e-8, r.quantity
    runs = [r for r in rows if "tip" in r.values]
    assert len(runs) == 2 * len(SIZE.youngs)
    # the condition number is scale-free: the same estimate at every E (to the estimators' 1e-3)
    conds = np.array([r.condition for r in runs])
    assert np.all(np.isfinite(conds)) and conds.max() <= 1.01 * conds.min(), conds


@pytest.mark.parametrize("method", METHODS)
def test_near_incompressibility_stays_finite_and_converged(method):
    # measured (quick sizes): staggered tip / beam 0.995 -> 0.903, 19 -> 14 CG iterations (the curl
    # smoothing and face transfers above lambda / mu = 4; 213 at 0.499 before them), condition 1.1e6 ->
    # 2.2e7 from nu 0.3 to 0.499 (2.1e8 while the clamp's cells held the wall by a lambda-scaled penalty,
    # before their finite-volume divergence); DG k = 2 0.975 -> 0.900, condition 3.1e6 -> 3.2e8
    low, high = S.poisson_case(method, SIZE, 0.3), S.poisson_case(method, SIZE, 0.499)
    assert_passed([low, high])
    assert 0.9 < low.values["ratio"] < 1.05
    assert 0.8 < high.values["ratio"] < low.values["ratio"]  # some locking, no collapse
    assert high.condition > 10 * low.condition
    if method == "staggered":
        assert high.iterations <= 2 * low.iterations  # the V-cycle no longer degrades as lambda / mu grows


def test_dg_at_nu_04999_is_finite_with_a_direct_solve_residual_below_1e6():
    row = S.poisson_case("dg", SIZE, 0.4999)
    assert_passed([row])
    assert row.values["ratio"] > 0.85  # k = 2 does not lock (measured 0.899)
    assert row.residual < S.DG_RESIDUAL_LIMIT and row.condition > 1e9


# ----------------------------------------------------------------------------- cut cells


OFFSETS = (0.0, 1e-6, 0.4, 0.99, 1 - 1e-6)  # 5 of the suite's 16: the extremes of the staggered sweep


@pytest.mark.parametrize("method", METHODS)
def test_sub_cell_offsets_change_the_tip_by_less_than_2_percent(method):
    # staggered: 5.11% here and 2.71% over the suite's 16 offsets at W/8 while the partial cell layers
    # along the load weighed their normal strains at the cell centres; with their mu weights at the
    # solid's first moments (engine/staggered/flat_layers.py) 1.42% here, 0.67% at W/8
    rows = S.offsets_case(method, SIZE, OFFSETS)
    runs, summary = rows[:-1], rows[-1]
    assert len(runs) == len(OFFSETS)
    assert all(r.passed for r in runs), [(r.params, r.note) for r in runs if not r.passed]  # finite, converged
    assert summary.values["spread"] < 0.02, summary.quantity
    assert summary.passed


@pytest.mark.parametrize("method, placement", [
    ("staggered", "across"),
    ("dg", "inside"),
])
def test_thin_walled_box_with_walls_of_03_h(method, placement):
    row = S.thin_wall_case(method, SIZE, placement)
    assert_passed([row])
    # thin-walled beam theory (bending + web shear); measured 1.045 staggered across, 1.052 DG inside
    assert 0.9 < row.values["ratio"] < 1.15, row.quantity


def test_staggered_thin_walls_inside_one_cell_layer_are_a_named_error():
    """A wall thinner than a cell inside one cell layer has one sample across its thickness: the shear
    terms that would tie its transverse motion to its in-plane samples reach the empty neighbour layers
    and are pruned, and the staggered energy has no bending term. K has a 957-dimensional null space
    (dense eigenvalues of the Jacobi-scaled free operator at h = W / 6: 957 below 6e-16 of the largest,
    the next 2.9e-5), all of it found and named before any solve. Filling the missing samples by constant
    extrapolation instead locks (top / beam 0.29); solving off the null space gives 1.13 but leaves the
    flanges' transverse displacement arbitrary (0 where the webs move 5.8e-3 m): no honest fix without
    a plate-bending term, so the job stops with the error that says what to change."""
    from engine.errors import ThinFeatureError

    row = S.thin_wall_case("staggered", SIZE, "inside")
    assert_passed([row])  # with expect=ThinFeatureError: only that error passes, a solved job fails
    error = row.values["error"]
    # the dense eigenvalues of the Jacobi-scaled free operator (6084 DOFs, taken from the level the
    # error names, ghost samples at the pushed top included): 957 below 1e-14 of the largest, the
    # next 2.4e-5 (1074 were named before the top's ghost samples tied some of them)
    assert error.startswith(f"{ThinFeatureError.__name__}: grid.cell_size: 957 independent motion(s)"), error
    assert "thinner than a grid cell" in error and "at most 30% of their cells" in error
    assert "method.kind 'dg'" in error and "about 0.0125 m" in error  # the wall is 0.3 h = 0.0125 m thick
    assert "RuntimeError" not in row.note


@pytest.mark.parametrize("method", METHODS)
def test_bar_rotated_off_the_axes_bends_like_the_aligned_bar(method):
    aligned, rotated = S.rotated_case(method, SIZE)
    assert_passed([aligned, rotated])
    # measured rotated / aligned 0.968 staggered (the rotated bar's cut cells weigh their strain at
    # the cell centre, which stiffens bending: see the offsets row), 1.0010 DG; tip / beam 0.97-0.99
    assert abs(rotated.values["rotated_over_aligned"] - 1) < (0.04 if method == "staggered" else 0.02)
    assert 0.95 < aligned.values["ratio"] < 1.02


@pytest.mark.parametrize("method", METHODS)
def test_plate_with_a_through_hole(method):
    row = S.hole_case(method, SIZE)
    assert_passed([row])
    # the hole softens the plate: measured end / (T L / E) 1.214 staggered, 1.199 DG; sxx / T 2.8-3.1
    # staggered, 2.50 DG (its recovered strain, the own element weighted 16 in the patch fit: with
    # equal weights the quick size's hole, 2.4 cells across, was smeared to 1.80; the exact peak ~3.6)
    assert 1.1 < row.values["ratio"] < 1.3
    assert 2.0 < row.values["max_sxx_over_T"] < 4.0


# ----------------------------------------------------------------------------- large strain, time steps


def test_ten_percent_strain_linear_and_corotated():
    linear, corotated = S.large_strain_case("dg", SIZE)
    assert_passed([linear, corotated])
    assert linear.values["max_strain"] > 0.05  # cell centres sit half a cell inside the 10% fibre
    # the rotations' fixed point settles and the dead load then bends less than the linear model
    # (measured tip / elastica 1.025 corotated, 1.092 linear; 12 fixed-point iterations)
    assert corotated.iterations < 30
    assert 0.97 < corotated.values["tip"] / corotated.values["elastica"] < 1.06
    assert corotated.values["tip"] < 0.97 * linear.values["tip"]
    staggered = S.large_strain_case("staggered", SIZE)
    assert_passed(staggered)
    assert staggered[1].values["error"].startswith("MethodUnavailableError: material.model:")


@pytest.mark.parametrize("method", METHODS)
def test_backward_euler_steps_from_1e5_to_1_s_stay_bounded(method):
    size = dataclasses.replace(SIZE, time_steps=(1e-5, 1.0), steps=3)  # the suite adds 1e-3 and 0.1 s, 4 steps
    rows = S.dynamic_case(method, size)
    assert_passed(rows)
    steps = {r.params.split()[0]: r.values for r in rows[1:]}
    assert set(steps) == {"dt=1e-05", "dt=1"}
    for v in steps.values():
        assert -1e-9 <= v["ratio_min"] and v["ratio_max"] <= 2.0  # dissipative: within 2x the static tip
    assert steps["dt=1e-05"]["ratio_max"] < 1e-4  # 4e-5 s after the load: barely moved
    assert abs(steps["dt=1"]["ratio_last"] - 1) < 0.02  # dt >> period: the static solution


# ----------------------------------------------------------------------------- free bodies


@pytest.mark.parametrize("method", METHODS)
def test_balanced_free_body_is_solved_off_the_rigid_modes_with_a_warning(method):
    row = S.free_body_run(method, SIZE, rotated=False, balanced=True)
    assert_passed([row])
    assert row.values["warned"]
    assert math.isnan(row.condition)  # n/a: the rigid modes are bordered out / projected off
    assert abs(row.values["ratio"] - 1) < 1e-3  # uniform stress T: the stretch is T L / E


@pytest.mark.parametrize("method, tolerance", [("staggered", 2e-2), ("dg", 1e-3)])
def test_balanced_loads_on_a_rotated_free_body_are_accepted(method, tolerance):
    # The spread loads keep the quadrature's net force and moment per free body (sampling.surface_loads),
    # so balanced tractions on a bar off the axes pass the rigid-mode check. Measured stretch / (T L / E):
    # staggered 1.0075 (the rotated bar's interior strain is 1.0097 T / E at h = W / 6: the cut-cell
    # operator's discretisation error, within the 2% the rotated-bar bending test allows), DG within 1e-3
    row = S.free_body_run(method, SIZE, rotated=True, balanced=True)
    assert_passed([row])
    assert row.values["warned"] and abs(row.values["ratio"] - 1) < tolerance


@pytest.mark.parametrize("method", METHODS)
def test_unbalanced_loads_on_a_free_body_are_a_named_error_never_a_nan(method):
    from engine.solvers.rigid import UnbalancedLoadError

    row = S.free_body_run(method, SIZE, rotated=True, balanced=False)
    assert_passed([row])
    assert row.values["error"].startswith(f"{UnbalancedLoadError.__name__}: boundaries:")
    assert "do not balance" in row.values["error"] and "net force" in row.values["error"]


# ----------------------------------------------------------------------------- regions on faces


@pytest.mark.parametrize("setup", ["aligned", "offset", "rotated"])
def test_dg_regions_exactly_on_a_face_select_the_whole_face(setup):
    # sliced faces sit 1e-17..5e-14 m off the mesh's planes; the clip's round-off tolerance keeps them
    row = S.exact_faces_run("dg", SIZE, setup)
    assert_passed([row])
    assert abs(row.values["ratio"] - 1) <= 1e-6
