"""Small staggered jobs: the whole problem factorised against the multigrid V-cycle (``method.solver``
"direct" / "iterative"; "auto" chooses direct up to ``engine.staggered.problem.DIRECT_SAMPLES``).

    .venv/bin/python -m benchmarks.direct_solve [--bar 32 48 64 80] [--ball 16 24 32 40] [--repeats 3]

Two shapes: the bundled cantilever (examples/cantilever.json, a thin bar, its factor fills slowly)
and a unit ball (an icosphere of 5,120 triangles) clamped on its cap z <= -0.8 under gravity (a
compact body, whose factor fills fastest). Each resolution runs both solvers in this process after
a warm-up job, ``--repeats`` times alternated; prints one JSON line per resolution: the
median warm job time and the discretisation + solve stages of each, CG iterations (the unknowns
of each size are in docs/benchmarks.md, "Small jobs solved directly").
"""

from __future__ import annotations

import argparse
import io
import json
import statistics
import time
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def ball_job(resolution: int) -> tuple[dict, bytes]:
    import trimesh

    buf = io.BytesIO()
    trimesh.creation.icosphere(4, radius=1.0).export(buf, file_type="stl")
    spec = {"geometry": {"mesh": "ball.stl"}, "grid": {"resolution": resolution, "padding": 1},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000},
            "loads": {"gravity": [0, 0, -9.81]},
            "boundaries": [{"kind": "displacement", "name": "clamp", "value": [0, 0, 0],
                            "region": {"halfspace": {"point": [0, 0, -0.8], "normal": [0, 0, 1]}}}],
            "output": {"fields": ["displacement"], "surface": False}}
    return spec, buf.getvalue()


def bar_job(resolution: int) -> tuple[dict, bytes]:
    spec = json.loads((EXAMPLES / "cantilever.json").read_text())
    spec["grid"]["resolution"] = resolution
    return spec, (EXAMPLES / "cantilever.stl").read_bytes()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bar", type=int, nargs="*", default=[32, 48, 64, 80])
    ap.add_argument("--ball", type=int, nargs="*", default=[16, 24, 32, 40])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    from engine import simulate
    from engine.geometry.cache import GeometryCache

    def once(spec: dict, mesh: bytes, solver: str) -> tuple[float, object]:
        spec = {**spec, "method": {"kind": "staggered", "solver": solver}}
        t = time.perf_counter()
        result = simulate(spec, mesh, filename="part.stl", cache=GeometryCache(None))
        return time.perf_counter() - t, result

    for shape, make, sizes in (("cantilever", bar_job, args.bar), ("ball", ball_job, args.ball)):
        for n in sizes:
            spec, mesh = make(n)
            once(spec, mesh, "direct")  # warm-up: kernels, MKL
            runs = {"direct": [], "iterative": []}
            for _ in range(args.repeats):
                for solver, rows in runs.items():
                    seconds, result = once(spec, mesh, solver)
                    stages = result.solver.stage_times
                    rows.append((seconds, stages["discretization"] + stages["solve"], result.solver.iterations))
            row = {"shape": shape, "resolution": n}
            for solver, rs in runs.items():
                row[solver] = {"job_s": round(statistics.median(r[0] for r in rs), 3),
                               "discretization_solve_s": round(statistics.median(r[1] for r in rs), 3),
                               "iterations": rs[-1][2]}
            row["direct_over_iterative"] = round(row["direct"]["job_s"] / row["iterative"]["job_s"], 2)
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
