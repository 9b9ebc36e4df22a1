"""Meshes finer than the grid: the staggered setup's cost against the triangle count at one resolution.

    .venv/bin/python -m benchmarks.fine_mesh [--subdivisions 5 6 7] [--resolution 48] [--json out.json]

A unit sphere (icosphere, the given subdivisions) clamped on its cap z < -0.6, pulled by a traction on
z > 0.5 and pressed by a pressure on x > 0.5, E = 1 MPa, nu = 0.3, staggered method on the CPU.
Each tessellation runs in its own process, two jobs through ``engine.simulate`` (geometry cache off);
the second (warm) job's stage times are printed. Scanned models bring 10^5-10^6 triangles: what a
job costs should follow the grid, not the tessellation.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from .geometry import run_isolated


def spec(resolution: int) -> dict:
    """The job: cap clamped, top pulled, side pressed."""
    def half(point, normal):
        return {"halfspace": {"point": point, "normal": normal}}

    return {
        "dimension": 3, "geometry": {"mesh": "sphere.ply"}, "grid": {"resolution": resolution},
        "method": {"kind": "staggered"}, "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3},
        "solver": {"arch": "cpu"},
        "boundaries": [
            {"kind": "displacement", "name": "clamp", "value": [0, 0, 0], "region": half([0, 0, -0.6], [0, 0, -1])},
            {"kind": "traction", "name": "pull", "value": [1e3, 0, 0], "region": half([0, 0, 0.5], [0, 0, 1])},
            {"kind": "pressure", "name": "push", "value": 1e3, "region": half([0.5, 0, 0], [1, 0, 0])},
        ],
        "output": {"fields": ["displacement"], "surface": False},
    }


def _job(subdivisions: int, resolution: int, queue) -> None:
    import trimesh

    from engine import simulate
    from engine.geometry.cache import GeometryCache

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sphere.ply"
        mesh.export(path)
        for _ in range(2):  # the second is the warm job
            t = time.perf_counter()
            result = simulate(spec(resolution), path, cache=GeometryCache(None))
            wall = time.perf_counter() - t
    queue.put({"subdivisions": subdivisions, "triangles": len(mesh.faces), "resolution": resolution, "wall_s": wall,
               "stages": result.solver.stage_times, "iterations": result.solver.iterations})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--subdivisions", type=int, nargs="+", default=[5, 6, 7])
    ap.add_argument("--resolution", type=int, default=48)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    rows = []
    for s in args.subdivisions:
        r = run_isolated(_job, s, args.resolution)
        rows.append(r)
        st = r["stages"]
        print(f"{r['triangles']:>9} triangles at {r['resolution']}: {r['wall_s']:.1f} s, discretization "
              f"{st.get('discretization', 0):.1f} s, solve {st.get('solve', 0):.1f} s, {r['iterations']} iterations",
              flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
