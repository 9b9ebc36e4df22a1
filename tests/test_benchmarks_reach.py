"""benchmarks.reach's step rule (the runs themselves are the benchmark's, not the suite's)."""

import pytest

from benchmarks.reach import next_size


def runs(*pairs):
    return [{"h": h, "seconds": t} for h, t in pairs]


def test_a_cheap_chain_refines_by_the_largest_step():
    # time ~ h^-3 from (0.1, 1 s), (0.05, 8 s): half of 600 s is (300 / 8)^(1/3) = 3.35x finer, capped at 2x
    assert next_size(runs((0.1, 1.0), (0.05, 8.0)), 600.0) == pytest.approx(0.025)


def test_a_step_lands_the_extrapolated_time_on_half_the_budget():
    # p = 3 from (0.2, 10 s), (0.1, 80 s); 300 s is (300 / 80)^(1/3) = 1.55x finer than 80 s
    assert next_size(runs((0.2, 10.0), (0.1, 80.0)), 600.0) == pytest.approx(0.1 / 3.75 ** (1 / 3))


def test_near_the_budget_the_least_step_or_none():
    # p = log 2 / log 1.25 = 3.106 from (0.1, 100 s), (0.08, 200 s): (300 / 200)^(1/p) = 1.14 < 1.2, and
    # 200 s * 1.2^p = 352 s fits 600 s: the least step; from 400 s, 704 s would not: no next size
    assert next_size(runs((0.1, 100.0), (0.08, 200.0)), 600.0) == pytest.approx(0.08 / 1.2)
    assert next_size(runs((0.1, 200.0), (0.08, 400.0)), 600.0) is None


def test_noisy_small_runs_do_not_promise_a_free_refinement():
    # the finer run was faster (noise): p falls back to 3, so 600 s / 2 from 2 s is a 2x step, not infinite
    assert next_size(runs((0.1, 2.5), (0.05, 2.0)), 600.0) == pytest.approx(0.025)
