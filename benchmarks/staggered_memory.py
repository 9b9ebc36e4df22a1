"""The staggered memory estimate against whole jobs' peaks, each job in a fresh process.

    .venv/bin/python -m benchmarks.staggered_memory [--cases cube:64 shell:128 ...] [--nu 0.3 0.4999]

A case is BODY:RESOLUTION with BODY one of ``cube`` (a unit cube filling its grid, held on its bottom
face), ``shell`` (``benchmarks.staggered``'s held shell, radii 1 and 0.6, a hollow body) or ``ball``
(a solid icosphere of radius 1 held below z = -0.8); gravity, rtol 1e-6, ``method.solver`` "auto",
through ``engine.pipeline.run`` as the CLI and the service run a job. Prints per job the CG iterations,
the process's peak resident memory (``VmHWM``) and ``engine.staggered.problem.estimate_memory`` of its
grid, which the service's admission compares with a worker's memory limit: an estimate below the
peak lets a job in that the worker's limit then stops.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

JOB = r"""
import json, sys, tempfile
from pathlib import Path
import trimesh
from benchmarks.memory import peak_rss_bytes
from benchmarks.staggered import job, shell_mesh
from engine.geometry.cache import GeometryCache
from engine.pipeline import run
from engine.staggered.problem import estimate_memory
from schemas import parse_job

body, res, nu = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
tmp = Path(tempfile.mkdtemp())
mesh = tmp / f"{body}.stl"
if body == "shell":
    shell_mesh(mesh)
elif body == "cube":
    trimesh.creation.box([1, 1, 1]).export(mesh)
else:
    trimesh.creation.icosphere(4, radius=1.0).export(mesh)
spec = job(str(mesh), res, nu, 1e-6, "cpu")
spec["method"]["solver"] = "auto"
if body == "cube":
    spec["boundaries"][0]["region"] = {"box": [[-1, -1, -1], [1, 1, -0.49]]}
parsed = parse_job(json.dumps(spec))
result = run(parsed, mesh.read_bytes(), filename=mesh.name, cache=GeometryCache(None))
print(json.dumps({"iterations": int(result.solver.iterations), "peak": peak_rss_bytes(),
                  "estimate": estimate_memory(result.grid, parsed.method), "cells": int(result.grid.num_cells)}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=["cube:64", "cube:128", "shell:64", "shell:128", "ball:128"])
    ap.add_argument("--nu", nargs="+", type=float, default=[0.3, 0.4999])
    args = ap.parse_args()
    print(f"{'job':>12s} {'nu':>7s} {'its':>4s} {'peak MiB':>9s} {'estimate MiB':>13s} {'peak/est':>9s}", flush=True)
    for case in args.cases:
        body, res = case.split(":")
        for nu in args.nu:
            out = subprocess.run([sys.executable, "-c", JOB, body, res, str(nu)], cwd=ROOT, capture_output=True, text=True,
                                 check=False)
            if out.returncode != 0:
                print(f"{case:>12s} {nu:7g} failed: {out.stderr.strip().splitlines()[-1:]}", flush=True)
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"{case:>12s} {nu:7g} {r['iterations']:4d} {r['peak'] / 2**20:9.0f} {r['estimate'] / 2**20:13.0f} "
                  f"{r['peak'] / r['estimate']:9.2f}", flush=True)


if __name__ == "__main__":
    main()
