"""The staggered memory estimate against whole jobs' peaks, each job in a fresh process.

    .venv/bin/python -m benchmarks.staggered_memory [--cases cube:64 shell:128 ...] [--nu 0.3 0.4999]

A case is BODY:RESOLUTION with BODY one of ``cube`` (a unit cube filling its grid, held on its bottom
face), ``shell`` (``benchmarks.staggered``'s held shell, radii 1 and 0.6, a hollow body) or ``ball``
(a solid icosphere of radius 1 held below z = -0.8) or ``plate`` (1 x 1 x 0.05, held within 0.05 of
one edge: the tiles of 8 cells hold about 2.5x its cells) or, in 2D, ``annulus`` (radii 0.8 and 0.325,
held inside r = 0.5); gravity, rtol 1e-6, ``method.solver`` "auto",
through ``engine.pipeline.run`` as the CLI and the service run a job. Prints per job the CG iterations,
the process's peak resident memory (``VmHWM``) and ``engine.pipeline.estimate_memory`` of the job (the
method's estimate and the steps the run keeps), which the service's admission compares with a worker's
memory limit: an estimate below the peak lets a job in that the worker's limit then stops.
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
from engine.geometry.occupancy import occupied_cells_bound
from engine.pipeline import estimate_memory, load_geometry, run
from schemas import parse_job
from verification.problems import circle

body, res, nu, fields, analysis, write_surface = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), \
    sys.argv[4].split(","), sys.argv[5], sys.argv[6] == "surface"
tmp = Path(tempfile.mkdtemp())
mesh = tmp / f"{body}.stl"
if body == "shell":
    shell_mesh(mesh)
elif body == "cube":
    trimesh.creation.box([1, 1, 1]).export(mesh)
elif body == "plate":
    trimesh.creation.box([1, 1, 0.05]).export(mesh)
elif body == "ball":
    trimesh.creation.icosphere(4, radius=1.0).export(mesh)
spec = job(str(mesh), res, nu, 1e-6, "cpu")
if body == "annulus":  # 2D: radii 0.8 and 0.325, held inside r = 0.5
    spec.update(dimension=2, geometry={"polygon": [circle(0.8), circle(0.325)]}, loads={"gravity": [0, -9.81]})
    spec["boundaries"][0]["region"] = {"sphere": {"center": [0, 0], "radius": 0.5}}
    spec["boundaries"][0]["value"] = [0, 0]
    mesh = None
spec["method"]["solver"] = "auto"
spec["output"]["fields"] = fields
spec["output"]["surface"] = write_surface
if analysis == "dynamic":
    spec["analysis"] = {"kind": "dynamic", "time_step": 1e-3, "steps": int(sys.argv[7])}
if body == "cube":
    spec["boundaries"][0]["region"] = {"box": [[-1, -1, -1], [1, 1, -0.49]]}
if body == "plate":
    spec["boundaries"][0]["region"] = {"box": [[-1, -1, -1], [-0.45, 1, 1]]}
parsed = parse_job(json.dumps(spec))
data, name = (mesh.read_bytes(), mesh.name) if mesh else (None, None)
result = run(parsed, data, filename=name, cache=GeometryCache(None))
surface, _ = load_geometry(parsed, data, filename=name)
print(json.dumps({"iterations": int(result.solver.iterations), "peak": peak_rss_bytes(),
                  "estimate": estimate_memory(result.grid, parsed.method, surface, job=parsed),
                  "cells": int(result.grid.num_cells), "occupied": occupied_cells_bound(surface, result.grid)}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=["cube:64", "cube:128", "shell:64", "shell:128", "ball:128"])
    ap.add_argument("--nu", nargs="+", type=float, default=[0.3, 0.4999])
    ap.add_argument("--fields", default="displacement", help="output.fields, comma-separated (default displacement)")
    ap.add_argument("--analysis", choices=["static", "dynamic"], default="static",
                    help="dynamic: backward-Euler steps of 1 ms")
    ap.add_argument("--steps", type=int, default=2, help="steps of a dynamic run (default 2)")
    ap.add_argument("--surface", action="store_true", help="output.surface: write the deformed surface too")
    args = ap.parse_args()
    print(f"{'job':>12s} {'nu':>7s} {'its':>4s} {'cells':>10s} {'occupied':>10s} {'peak MiB':>9s} {'estimate MiB':>13s} "
          f"{'peak/est':>9s}", flush=True)
    for case in args.cases:
        body, res = case.split(":")
        for nu in args.nu:
            out = subprocess.run([sys.executable, "-c", JOB, body, res, str(nu), args.fields, args.analysis,
                              "surface" if args.surface else "none", str(args.steps)], cwd=ROOT, capture_output=True, text=True,
                                 check=False)
            if out.returncode != 0:
                print(f"{case:>12s} {nu:7g} failed: {out.stderr.strip().splitlines()[-1:]}", flush=True)
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"{case:>12s} {nu:7g} {r['iterations']:4d} {r['cells']:10d} {r['occupied']:10d} "
                  f"{r['peak'] / 2**20:9.0f} {r['estimate'] / 2**20:13.0f} {r['peak'] / r['estimate']:9.2f}", flush=True)


if __name__ == "__main__":
    main()
