"""Cold start: the bundled cantilever run several times in one fresh process (the Python API,
geometry cache off, so every job recomputes its geometry); the first job pays Taichi's front end
and code generation for every kernel it launches, the later ones do not.

    .venv/bin/python -m benchmarks.cold_start [--jobs 3] [--stages] [--arch cpu]

Prints the wall seconds of each job and the first job's extra time over the median of the others.
Run it as its own process: an earlier job in the same process would warm it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=3)
    ap.add_argument("--stages", action="store_true",
                    help="first import what a job imports and initialise Taichi, timed apart, then print each "
                         "job's stage times: where the first job's extra goes")
    ap.add_argument("--arch", help="solver.arch of the jobs (cpu, cuda, auto); default: the example's")
    args = ap.parse_args(argv)
    out = {}
    if args.stages:
        t = time.perf_counter()
        import engine.pipeline  # noqa: F401 - what the first job would import
        import engine.staggered.elasticity  # noqa: F401
        out["imports_s"] = round(time.perf_counter() - t, 3)
        from engine import runtime

        t = time.perf_counter()
        runtime.init(args.arch or "cpu", "f64")
        out["init_s"] = round(time.perf_counter() - t, 3)
    from engine import simulate
    from engine.geometry.cache import GeometryCache

    spec = json.loads((EXAMPLES / "cantilever.json").read_text())
    if args.arch:
        spec["solver"] = {**spec.get("solver", {}), "arch": args.arch}
    times, stages = [], []
    for _ in range(max(args.jobs, 2)):
        t = time.perf_counter()
        result = simulate(spec, EXAMPLES / "cantilever.stl", cache=GeometryCache(None))
        times.append(time.perf_counter() - t)
        stages.append({k: round(v, 3) for k, v in result.solver.stage_times.items()})
    warm = statistics.median(times[1:])
    out.update(jobs_s=[round(x, 2) for x in times], first_extra_s=round(times[0] - warm, 2))
    if args.stages:
        out["stages_s"] = stages
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
