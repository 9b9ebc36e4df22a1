"""The scaling benchmark's pure logic: exponent fits, medians, skipped sizes (no solves)."""

import pytest

from benchmarks.scaling import configurations, fit_exponent, fits, fits_table, medians, runs_table


def _row(label: str, n: int, dofs: int, wall: float, repeat: int = 0, **extra) -> dict:
    return {"label": label, "resolution": n, "dofs": dofs, "wall_s": wall, "solve_s": wall / 2,
            "peak_rss_gib": 0.1 + dofs * 1e-6, "children_peak_rss_gib": 0.0, "h": 2 / n,
            "active_cells": dofs // 3, "elements": None, "iterations": 10, "residual": 1e-7,
            "repeat": repeat, **extra}


def test_fit_exponent_recovers_a_power_law():
    dofs = [1e4, 8e4, 6.4e5, 5.12e6]
    assert fit_exponent(dofs, [3e-5 * d**1.1 for d in dofs]) == pytest.approx(1.1)
    assert fit_exponent(dofs, [2.0 * d**2 for d in dofs]) == pytest.approx(2.0)


def test_fit_exponent_needs_two_distinct_sizes():
    assert fit_exponent([], []) is None
    assert fit_exponent([1e5], [3.0]) is None
    assert fit_exponent([1e5, 1e5], [3.0, 4.0]) is None


def test_fits_skip_the_smallest_size_and_failed_runs():
    # a fixed cost dominates the smallest size (30 s where DOFs alone would take 5 s); from the
    # second size up time ~ DOFs
    rows = [_row("staggered", 32, 10**4, 30.0),
            _row("staggered", 64, 8 * 10**4, 40.0), _row("staggered", 128, 64 * 10**4, 320.0),
            {"label": "staggered", "resolution": 256, "failed": "timed out after 1800 s"}]
    f = fits(rows, "wall_s")["staggered"]
    assert f["tail"] == [64, 128] and f["all"] == [32, 64, 128]
    assert f["p_tail"] == pytest.approx(1.0)
    assert f["p_all"] < 1.0


def test_medians_over_repeats_and_all_failed():
    runs = [_row("dg1", 8, 3000, 5.0, 0), _row("dg1", 8, 3000, 9.0, 1), _row("dg1", 8, 3000, 6.0, 2),
            {"label": "dg2", "resolution": 32, "failed": "timed out after 10 s", "repeat": 0}]
    rows = medians(runs)
    assert rows[0]["wall_s"] == 6.0 and rows[0]["repeats"] == 3 and "repeat" not in rows[0]
    assert rows[1]["failed"].startswith("timed out")
    table = runs_table(rows)
    assert "timed out after 10 s" in table and "| dg1 | 8 |" in table
    assert "n/a" in fits_table(rows)  # one size: no fit


def test_configurations_sort_sizes_per_method():
    assert configurations([64, 32], [12, 8], [2]) == [("staggered", None, 32), ("staggered", None, 64),
                                                     ("dg", 2, 8), ("dg", 2, 12)]
    assert configurations([], [8], [1, 2]) == [("dg", 1, 8), ("dg", 2, 8)]


def test_sweep_skips_sizes_above_a_timeout(monkeypatch, capsys):
    import benchmarks.scaling as scaling

    calls = []

    def fake(method, degree, n, mesh, arch, timeout):
        calls.append((degree, n))
        if degree == 2 and n >= 24:
            return {"label": f"dg{degree}", "resolution": n, "failed": "timed out after 1 s", "timed_out": True}
        return _row(f"dg{degree}", n, 1000 * n, 1.0)

    monkeypatch.setattr(scaling, "measure", fake)
    runs = scaling.sweep(configurations([], [16, 24, 32], [1, 2]), "mesh.stl", "cpu", repeats=2, timeout=1.0)
    assert (2, 32) not in calls and calls.count((2, 24)) == 1  # not retried in the second repeat
    assert calls.count((1, 32)) == 2
    skipped = [r for r in runs if r.get("failed", "").startswith("skipped")]
    assert [(r["label"], r["resolution"]) for r in skipped] == [("dg2", 32)]
    assert "timed out" in runs_table(medians(runs))
