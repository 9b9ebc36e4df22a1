"""The smallest error each method reaches within a time and a memory budget (issue 23).

    .venv/bin/python -m benchmarks.reach [--problems lame,ball] [--methods staggered,dg2,p2-stl]
        [--budget 600] [--memory-gib 22] [--json docs/reach.json]

For each problem and method (the problems, probes and runs of ``benchmarks.accuracy``), one cold job
per size -- a fresh process, the first job in it: what one CLI run costs -- from the two finest sizes
the accuracy benchmark lists, then refined while the job fits: the next size is the one whose time,
extrapolated from the last two runs (time ~ h^-p), is half the budget, refined at least 1.2x and at
most 2x per step. A chain stops at the first run that does not fit: over the budget (killed at it),
above the memory (the process and its children killed when their resident memory passes
--memory-gib), refused by voxelastic's memory estimate (``VOXELASTIC_MAX_MEMORY_GB`` is set to the
same budget, so a refusal is the estimate's verdict, which may be conservative), or any other
failure; the row says which. A failed step longer than 1.44x is tried once more at its geometric
mean with the last size that fit. The table gives, per problem and method, the finest run that fit:
its h, relative L2 error of u at the probes, seconds and peak resident memory, and the run that
stopped the chain.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path

from .accuracy import SIZES, _commit, _one

FIRST_TARGET = 0.5  # of the budget: where the extrapolated next run should land
REFINE = (1.2, 2.0)  # least and most refinement of h per step


def next_size(runs: list[dict], budget: float) -> float | None:
    """The next (smaller) h of a chain from its last two fitting runs: the size whose extrapolated time
    is FIRST_TARGET * budget, refined within REFINE; None when even the least refinement REFINE[0] is
    extrapolated to take over the budget."""
    (h0, t0), (h1, t1) = [(r["h"], r["seconds"]) for r in runs[-2:]]
    p = math.log(t1 / t0) / math.log(h0 / h1) if t1 > t0 and h0 > h1 else 3.0
    p = max(p, 1.0)  # noise in two small runs must not promise a free refinement
    factor = (FIRST_TARGET * budget / t1) ** (1.0 / p)
    if factor < REFINE[0]:
        return None if t1 * REFINE[0] ** p > budget else h1 / REFINE[0]
    return h1 / min(factor, REFINE[1])


def chain(problem: str, method: str, budget: float, memory_gib: float) -> tuple[list[dict], str]:
    """The runs of one problem and method, coarse to fine, up to the first that does not fit, and what
    ended the chain."""
    sizes = SIZES[problem][method][-2:]
    runs: list[dict] = []
    h: float = sizes[0]
    bisected = False
    while True:
        row = _one(problem, method, h, budget + 60.0, warm=False, max_rss_gib=memory_gib)
        if "failed" not in row and row["seconds"] > budget:
            row["failed"] = f"took {row['seconds']:.0f} s, over the budget"
        runs.append(row)
        brief = {k: (round(v, 6) if isinstance(v, float) else v) for k, v in row.items()
                 if k in ("problem", "method", "h", "seconds", "error_u", "peak_rss_gib", "failed")}
        print(json.dumps(brief), flush=True)
        fitting = [r for r in runs if "failed" not in r]
        if "failed" in row:
            last = fitting[-1]["h"] if fitting else None
            if last is None or bisected or last / h < REFINE[0] ** 2:
                return runs, f"h = {h:.4g}: {row['failed']}"
            h, bisected = math.sqrt(last * h), True  # once per chain: the step may have been too long
            continue
        step = sizes[1] if len(fitting) == 1 else next_size(fitting, budget)
        if step is None:
            return runs, f"the next size refined {REFINE[0]:g}x would take over {budget:g} s (extrapolated)"
        h = step


def table(runs: list[dict], stops: dict[tuple[str, str], str]) -> str:
    """Markdown: per problem and method, the run of smallest error within the budget and what ended the
    chain."""
    lines = ["| problem | method | h of the smallest error | error of u | seconds (cold) | peak [GiB] | stopped by |",
             "|---|---|---|---|---|---|---|"]
    for key in dict.fromkeys((r["problem"], r["method"]) for r in runs):
        mine = [r for r in runs if (r["problem"], r["method"]) == key]
        fit = [r for r in mine if "failed" not in r]
        best = min(fit, key=lambda r: r["error_u"]) if fit else None
        cells = ([f"1/{1 / best['h']:.1f}" if best["h"] < 1 else f"{best['h']:g}", f"{best['error_u']:.2e}",
                  f"{best['seconds']:.1f}", f"{best['peak_rss_gib']:.2f}"] if best else ["-"] * 4)
        lines.append(f"| {key[0]} | {key[1]} | " + " | ".join(cells) + f" | {stops[key]} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", default="lame,ball")
    ap.add_argument("--methods", default="staggered,dg2,p2-stl,p2")
    ap.add_argument("--budget", type=float, default=600.0, help="seconds per job")
    ap.add_argument("--memory-gib", type=float, default=22.0, help="resident memory per job [GiB]")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    os.environ["VOXELASTIC_MAX_MEMORY_GB"] = f"{a.memory_gib:g}"  # the spawned jobs read it at import
    runs, stops = [], {}
    for problem in a.problems.split(","):
        for method in a.methods.split(","):
            if method in SIZES[problem]:
                done, stops[(problem, method)] = chain(problem, method, a.budget, a.memory_gib)
                runs += done
    text = table(runs, stops)
    print(text)
    if a.json:
        a.json.write_text(json.dumps({"machine": platform.processor() or platform.machine(), "commit": _commit(),
                                      "date": time.strftime("%Y-%m-%d"), "budget_s": a.budget,
                                      "memory_gib": a.memory_gib, "runs": runs,
                                      "stopped_by": {f"{k[0]} {k[1]}": v for k, v in stops.items()}},
                                     indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
