"""The DG memory estimate against measured peaks (issue 23): whole jobs, each in a fresh process.

    .venv/bin/python -m benchmarks.dg_memory --measure [--json docs/dg_memory.json] [--only ball]
    .venv/bin/python -m benchmarks.dg_memory [--json docs/dg_memory.json]

``--measure`` runs the DG jobs of ``RUNS`` (the accuracy benchmark's Lamé shell and ball,
``verification.problems``, through ``engine.simulate`` with the job's own outputs), one spawned process
each, and records the peak resident memory (``VmHWM``), the grid's cells, the elements (pieces of
cut cells) and the unknowns; the job's own memory check is lifted (``VOXELASTIC_MAX_MEMORY_GB`` 64) so
that the estimate cannot refuse what is being measured. Without ``--measure`` it reads the JSON and
prints, per run, the peak beside ``engine.pipeline.estimate_memory`` of the same grid, method and surface
as the engine computes it now, and the ratio: an estimate below a measured peak would let a job
exhaust a worker's memory, one far above refuses jobs that fit.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import queue
import time
from pathlib import Path

from .memory import peak_rss_bytes

# (problem, degree, solver, h): direct and iterative on a shell and on a solid ball, k = 1 and 2, from
# small to what fits this machine's 24 GiB
RUNS = [
    *[("ball", 2, "direct", h) for h in (1 / 5, 1 / 7, 1 / 9, 1 / 11)],
    *[("lame", 2, "direct", h) for h in (1 / 6, 1 / 8, 1 / 10)],
    *[("ball", 1, "direct", h) for h in (1 / 8, 1 / 12, 1 / 16)],
    *[("lame", 1, "direct", h) for h in (1 / 12, 1 / 16)],
    *[("ball", 2, "iterative", h) for h in (1 / 8, 1 / 12, 1 / 16, 1 / 21, 1 / 26)],
    *[("lame", 2, "iterative", h) for h in (1 / 12, 1 / 16, 1 / 21, 1 / 26)],
    *[("ball", 1, "iterative", h) for h in (1 / 12, 1 / 18, 1 / 26, 1 / 34)],
    *[("lame", 1, "iterative", h) for h in (1 / 16, 1 / 24, 1 / 32)],
]


def _job(name: str, degree: int, solver: str, h: float, queue) -> None:
    os.environ["VOXELASTIC_MAX_MEMORY_GB"] = "64"
    from verification.problems import problem, simulate_problem

    t = time.perf_counter()
    result = simulate_problem(problem(name), {"kind": "dg", "degree": degree, "solver": solver}, h)
    queue.put({"seconds": time.perf_counter() - t, "iterations": result.solver.iterations,
               "peak_rss_gib": peak_rss_bytes() / 2**30})


def problem_grid(name: str, h: float):
    """(surface, grid) of a problem's job at cell size h [m], as the engine builds them."""
    from engine.geometry.surface import Surface
    from engine.grid import make_grid
    from verification.problems import problem

    mesh = problem(name).surface_mesh()
    surface = Surface(mesh.vertices.astype(float), mesh.faces.astype("int64"))
    return surface, make_grid(*surface.bounds, cell_size=h, padding=1)


def measure(only: str | None) -> list[dict]:
    ctx = mp.get_context("spawn")
    rows = []
    for name, degree, solver, h in RUNS:
        if only and name != only:
            continue
        q = ctx.Queue()
        proc = ctx.Process(target=_job, args=(name, degree, solver, h, q))
        proc.start()
        row = {"problem": name, "degree": degree, "solver": solver, "h": h}
        try:
            row.update(q.get(timeout=1800))
        except queue.Empty as exc:  # a crash (nothing sent) or a job past 30 minutes is a row saying so
            row["failed"] = f"{type(exc).__name__}, exit code {proc.exitcode}"
        proc.join(timeout=30)
        from engine.geometry.slicing import slice_cells

        surface, grid = problem_grid(name, h)
        row.update(grid_cells=grid.num_cells, elements=slice_cells(surface, grid).num_pieces)
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def report(rows: list[dict]) -> str:
    from engine.pipeline import estimate_memory
    from schemas.job import DGMethod

    lines = ["| problem | k | solver | h | grid cells | elements | peak [GiB] | estimate [GiB] | estimate / peak |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "failed" in r:
            continue
        surface, grid = problem_grid(r["problem"], r["h"])
        est = estimate_memory(grid, DGMethod(kind="dg", degree=r["degree"], solver=r["solver"]), surface) / 2**30
        lines.append(f"| {r['problem']} | {r['degree']} | {r['solver']} | 1/{1 / r['h']:.0f} | {r['grid_cells']:,} | "
                     f"{r['elements']:,} | {r['peak_rss_gib']:.2f} | {est:.2f} | {est / r['peak_rss_gib']:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--measure", action="store_true", help="run the jobs (else report the JSON)")
    ap.add_argument("--json", type=Path, default=Path("docs/dg_memory.json"))
    ap.add_argument("--only", help="one problem: lame or ball")
    args = ap.parse_args(argv)
    if args.measure:
        rows = measure(args.only)
        args.json.write_text(json.dumps({"machine": platform.node(), "runs": rows}, indent=1) + "\n")
    print(report(json.loads(args.json.read_text())["runs"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
