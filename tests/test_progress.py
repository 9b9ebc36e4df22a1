"""The CLI's progress line: relative residual and an ETA from the residual's way down to rtol."""

import io
import re

import engine.cli as cli


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_eta_follows_the_residual_to_rtol(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(cli.time, "perf_counter", clock)
    out = io.StringIO()
    bar = cli.ProgressBar(out, rtol=1e-8)
    bar("grid", 0.1, {"shape": [34, 9, 9], "spacing": 0.03})
    bar("solve", 0.4, {"step": 1, "steps": 2, "iterations": 0, "residual": 1.0})
    clock.now += 3.0  # 3 s to get from 1 to 1e-2: a quarter of step 1's way to 1e-8, an eighth of all
    bar("solve", 0.5, {"step": 1, "steps": 2, "iterations": 30, "residual": 1e-2})
    lines = out.getvalue().splitlines()
    assert "grid 34x9x9" in lines[0]
    last = lines[-1]
    assert "step 1/2, 30 it., rel. residual 1.0e-02" in last
    eta = float(re.search(r"ETA (\d+) s", last).group(1))
    assert eta == 21  # 3 s for 1/8 of the way: 7/8 left take 21 s
    clock.now += 9.0  # step 2 at half its way: 3/4 done in 12 s, 4 s left
    bar("solve", 0.8, {"step": 2, "steps": 2, "iterations": 40, "residual": 1e-4})
    assert "ETA 4 s" in out.getvalue().splitlines()[-1]


def test_no_eta_without_a_solve():
    out = io.StringIO()
    bar = cli.ProgressBar(out, rtol=1e-8)
    bar("cut_cells", 0.3, {"cache_hit": True})
    assert "ETA" not in out.getvalue() and "cached" in out.getvalue()


def test_a_direct_solve_reports_each_finished_step(monkeypatch):
    """A factorised staggered job takes one CG step per time step, so the reports every 10 CG
    iterations never come: a 400-step dynamic run sat at 38% for all its 18 s (and a Ctrl-C sent
    when the solve line appeared landed after the solve). Each finished step is reported instead,
    at most every ``STEP_REPORT_SECONDS``."""
    import json
    from pathlib import Path

    from engine import analysis
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import run

    monkeypatch.setattr(analysis, "STEP_REPORT_SECONDS", 0.0)
    examples = Path(__file__).resolve().parents[1] / "examples"
    spec = json.loads((examples / "cantilever.json").read_text())
    spec["grid"] = {"resolution": 16}
    spec["analysis"] = {"kind": "dynamic", "time_step": 1e-3, "steps": 4}
    seen = []
    result = run(spec, examples / "cantilever.stl", cache=GeometryCache(None),
                 progress=lambda stage, fraction, info: seen.append((stage, fraction, dict(info))))
    assert result.solver.iterations == 1  # solved directly
    steps = [(f, i["step"]) for s, f, i in seen if s == "solve" and "step" in i]
    assert [k for _, k in steps] == [1, 2, 3]  # the last one is the stage's own final report
    fractions = [f for f, _ in steps]
    assert fractions == sorted(fractions) and 0.4 < fractions[0] < fractions[-1] < 0.95
