"""The accuracy benchmark's pure logic: medians of warm and cold times, time at an error target, the
ratio table (no solves)."""

import pytest

from benchmarks.accuracy import medians, table, time_at


def _run(method: str, h: float, error: float, warm: float, cold: float, repeat: int = 0) -> dict:
    return {"problem": "lame", "method": method, "h": h, "error_u": error, "error_vm": 10 * error,
            "seconds": warm, "seconds_cold": cold, "peak_rss_gib": 0.5, "repeat": repeat}


def test_medians_take_warm_and_cold_times_apart():
    runs = [_run("staggered", 0.1, 1e-2, w, c, r) for r, (w, c) in enumerate([(1.0, 3.0), (5.0, 2.0), (2.0, 4.0)])]
    runs.append({"problem": "lame", "method": "p1", "h": 0.2, "failed": "exit code -9"})
    rows = medians(runs)
    ours = next(r for r in rows if r["method"] == "staggered")
    assert (ours["seconds"], ours["seconds_cold"], ours["repeats"]) == (2.0, 3.0, 3)
    assert next(r for r in rows if r["method"] == "p1")["failed"] == "exit code -9"


def test_time_at_interpolates_log_log_on_the_chosen_clock():
    rows = [_run("staggered", 0.2, 1e-1, 1.0, 2.0), _run("staggered", 0.1, 1e-3, 100.0, 400.0)]
    assert time_at(rows, 1e-2) == pytest.approx(10.0)  # halfway in log error: halfway in log time
    assert time_at(rows, 1e-2, clock="seconds_cold") == pytest.approx((2.0 * 400.0) ** 0.5)
    assert time_at(rows, 1e-4) is None  # never that accurate
    assert time_at(rows, 1.0) == 1.0  # even the cheapest run is
    assert time_at(rows, 1e-2, key="error_vm") == pytest.approx(100.0)  # vm errors are 1e0 .. 1e-2


def test_table_gives_each_method_over_the_faster_peer():
    rows = [_run("staggered", 0.2, 1e-1, 1.0, 2.0), _run("staggered", 0.1, 1e-3, 100.0, 400.0),
            _run("p1", 0.2, 1e-1, 0.5, 0.5), _run("p1", 0.1, 1e-3, 5.0, 5.0),
            _run("p2", 0.4, 1e-1, 0.1, 0.1), _run("p2", 0.2, 1e-2, 4.0, 4.0)]
    line = next(l for l in table(rows).splitlines() if l.startswith("| lame | 0.01 |"))
    # staggered 10 s; peers P1 sqrt(0.5 * 5) = 1.58 s, P2 4 s: the faster is P1
    assert "10.00 s (6.3x CAD)" in line and "1.58 s" in line and "4.00 s" in line
    cold = next(l for l in table(rows, clock="seconds_cold").splitlines() if l.startswith("| lame | 0.01 |"))
    assert "28.28 s (18x CAD)" in cold
    # a peer meshing the STL: its own ratio beside the CAD one (P2 on the STL 20 s at 1e-2: 0.5x)
    rows += [_run("p2-stl", 0.4, 1e-1, 2.0, 2.0), _run("p2-stl", 0.2, 1e-3, 200.0, 200.0)]
    line = next(l for l in table(rows).splitlines() if l.startswith("| lame | 0.01 |"))
    assert "10.00 s (6.3x CAD, 0.5x STL)" in line and "20.00 s" in line


def test_the_faster_peer_may_be_dolfinx_and_only_methods_run_are_columns():
    rows = [_run("staggered", 0.2, 1e-1, 1.0, 2.0), _run("staggered", 0.1, 1e-3, 100.0, 400.0),
            _run("p2", 0.4, 1e-1, 0.1, 0.1), _run("p2", 0.2, 1e-2, 4.0, 4.0),
            _run("dolfinx-p2", 0.4, 1e-1, 0.1, 0.6), _run("dolfinx-p2", 0.2, 1e-2, 2.0, 2.5),
            _run("dolfinx-p2-stl", 0.4, 1e-1, 10.0, 11.0), _run("dolfinx-p2-stl", 0.2, 1e-3, 40.0, 41.0)]
    header, _, *lines = table(rows).splitlines()
    assert "DOLFINx P2 (curved)" in header and "scikit-fem P1 |" not in header and "DG" not in header
    line = next(l for l in lines if l.startswith("| lame | 0.01 |"))
    # staggered 10 s; CAD peers: scikit-fem P2 4 s, DOLFINx P2 2 s (the faster); DOLFINx on the STL 20 s
    assert "10.00 s (5x CAD, 0.5x STL)" in line
