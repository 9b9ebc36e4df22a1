"""Cold start: the bundled cantilever run several times in one fresh process (the Python API,
geometry cache off, so every job recomputes its geometry); the first job pays Taichi's front end
and code generation for every kernel it launches, the later ones do not.

    .venv/bin/python -m benchmarks.cold_start [--jobs 3]

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
    args = ap.parse_args(argv)
    from engine import simulate
    from engine.geometry.cache import GeometryCache

    spec = json.loads((EXAMPLES / "cantilever.json").read_text())
    times = []
    for _ in range(max(args.jobs, 2)):
        t = time.perf_counter()
        simulate(spec, EXAMPLES / "cantilever.stl", cache=GeometryCache(None))
        times.append(time.perf_counter() - t)
    warm = statistics.median(times[1:])
    print(json.dumps({"jobs_s": [round(x, 2) for x in times], "first_extra_s": round(times[0] - warm, 2)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
