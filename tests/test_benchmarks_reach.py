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


def test_a_chain_refines_until_a_run_does_not_fit_and_bisects_a_long_failed_step_once(monkeypatch):
    import benchmarks.reach as reach

    tried = []

    def fake_one(problem, method, h, timeout, warm, max_rss_gib):
        # seconds ~ h^-3 (8 s at h = 0.1); above 22 GiB (here: h < 0.035) the run is killed
        tried.append(h)
        if h < 0.035:
            return {"problem": problem, "method": method, "h": h, "failed": "killed above 22 GiB resident"}
        return {"problem": problem, "method": method, "h": h, "seconds": 8.0 * (0.1 / h) ** 3, "error_u": h**2}

    monkeypatch.setattr(reach, "_one", fake_one)
    monkeypatch.setitem(reach.SIZES, "fake", {"m": [0.2, 0.14, 0.1]})
    runs, stop = reach.chain("fake", "m", 600.0, 22.0)
    # 0.14, 0.1 (the two finest listed), then 2x (300 / 8 s gives 3.35x): 0.05 (64 s); then
    # (300 / 64)^(1/3) = 1.67x: 0.0299, killed; bisected once: sqrt(0.05 * 0.0299) = 0.0387 fits (139 s);
    # then (300 / 139)^(1/3) = 1.29x: 0.0300, killed again, and the chain ends there
    assert tried[:3] == pytest.approx([0.14, 0.1, 0.05])
    assert tried[3] == pytest.approx(0.05 / (300 / 64) ** (1 / 3))
    assert tried[4] == pytest.approx((0.05 * tried[3]) ** 0.5)
    assert len(tried) == 6 and tried[5] < 0.035
    assert stop.endswith("killed above 22 GiB resident")
    assert min(r["error_u"] for r in runs if "failed" not in r) == pytest.approx(tried[4] ** 2)
