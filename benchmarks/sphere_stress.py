"""Stresses on the Lame thick sphere (issue 19): von Mises at interior probes and on both surfaces.

    .venv/bin/python -m benchmarks.sphere_stress [--method staggered|dg] [--h 0.1,0.05,0.025]

The accuracy benchmark's ``lame`` geometry (verification.problems: icospheres of subdivision 6,
a = 0.5, b = 1, E = 1e7 Pa, nu = 0.3, internal pressure 1e4 Pa, free body). Probes: 500 points
uniform in 0.62 < r < 0.88 (seed 5). Prints one JSON line per h: the relative L2 error of von
Mises at the probes, and the surface von Mises on the inner and outer spheres over the exact value
there (max and mean over the vertices), with the wall time of the run (this process, CPU, f64).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def probes(n: int = 500):
    import numpy as np

    x = np.random.default_rng(5).uniform(-1, 1, (40000, 3))
    r = np.linalg.norm(x, axis=1)
    return x[(r > 0.62) & (r < 0.88)][:n]


def run(method: dict, h: float) -> dict:
    import numpy as np

    from engine import simulate
    from engine.geometry.cache import GeometryCache
    from verification.problems import problem

    pb = problem("lame")
    points = probes()
    spec, mesh, functions = pb.job(method, h)
    spec["output"].update(probes=points.tolist(), fields=["von_mises"], surface=True)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "shell.ply"
        mesh.export(path)
        spec["geometry"]["mesh"] = path.name
        result = simulate(spec, path, cache=GeometryCache(None), functions=functions)
    seconds = time.perf_counter() - t
    vm, exact = result.fields.probes["von_mises"], pb.von_mises(points)
    row = {"method": method["kind"], "h": h, "probe_error": float(np.sqrt(np.sum((vm - exact) ** 2) / np.sum(exact**2))),
           "seconds": round(seconds, 1)}
    v = result.surface_vertices
    r = np.linalg.norm(v, axis=1)
    surface = result.fields.surface["von_mises"]
    for name, side in (("inner", r < 0.75), ("outer", r > 0.75)):
        want = pb.von_mises(v[side]).mean()
        row[f"{name}_max"] = round(float(surface[side].max() / want), 4)
        row[f"{name}_mean"] = round(float(surface[side].mean() / want), 4)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", default="staggered", choices=["staggered", "dg"])
    ap.add_argument("--degree", type=int, default=2, help="DG degree")
    ap.add_argument("--h", default="0.1,0.05,0.025", help="cell sizes [m], comma-separated")
    args = ap.parse_args(argv)
    method = {"kind": "staggered"} if args.method == "staggered" else {"kind": "dg", "degree": args.degree}
    for h in (float(v) for v in args.h.split(",")):
        print(json.dumps(run(method, h)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
