"""DG method floor: a sphere shell on a 16^3 grid, k = 2, static; stages and assembly throughput.

    .venv/bin/python -m benchmarks.dg [--resolution 16] [--degree 2] [--repeats 3] [--json out.json]

Shell: icospheres (subdivisions 5) of radius 1 and 0.6, clamped below z = -0.8, gravity,
E = 1e6, nu = 0.3, IP, penalty 10. Each repeat runs in its own spawned process (cold geometry
cache, warm Taichi kernel cache after the first); medians over repeats.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import platform
import resource
import statistics
import time
from pathlib import Path


def _run(resolution: int, degree: int, queue) -> None:
    import numpy as np
    import trimesh

    from engine.dg.elasticity import DGElasticity, Prescribed
    from engine.geometry.slicing import slice_cells
    from engine.geometry.surface import Surface
    from engine.grid import make_grid
    from engine.material import Material
    from engine.regions import Halfspaces
    from engine.runtime import init

    init("cpu", "f64")
    outer = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=5, radius=0.6)
    inner.invert()
    mesh = trimesh.util.concatenate([outer, inner])
    surface = Surface(mesh.vertices.astype(float), mesh.faces.astype("int64"))
    t0 = time.perf_counter()
    grid = make_grid(*surface.bounds, resolution=resolution)
    cut = slice_cells(surface, grid)
    t1 = time.perf_counter()
    clamp = Halfspaces(np.array([[0, 0, 1.0]]), np.array([-0.8]))
    m = DGElasticity(cut=cut, surface=surface, material=Material(1e6, 0.3, 1000), degree=degree, flux="ip",
                     penalty=10, prescribed=[Prescribed(clamp, (0, 0, 0), "base")],
                     body_force=np.array([0, 0, -9.81e3]))
    t2 = time.perf_counter()
    st = m.solve()
    t3 = time.perf_counter()
    queue.put({
        "elements": m.elements.count, "pieces": cut.num_pieces, "merged": m.elements.merged, "dofs": m.size,
        "slicing_s": t1 - t0, "discretization_s": t2 - t1, "solve_s": t3 - t2, "total_s": t3 - t0,
        "stages": m.timings, "nnz": int(m.matrix.nnz), "residual": st.stats.residual, "eta": m.eta,
        "assembly_elements_per_s": m.elements.count / (m.timings["element_blocks"] + m.timings["assembly"]),
        "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        "backend": m._factor.backend,
    })


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=16)
    ap.add_argument("--degree", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    ctx = mp.get_context("spawn")
    runs = []
    for _ in range(a.repeats):
        q = ctx.Queue()
        p = ctx.Process(target=_run, args=(a.resolution, a.degree, q))
        p.start()
        runs.append(q.get())
        p.join()
        print(json.dumps(runs[-1]), flush=True)
    keys = ("slicing_s", "discretization_s", "solve_s", "total_s", "assembly_elements_per_s")
    summary = {k: statistics.median(r[k] for r in runs) for k in keys}
    summary.update({"machine": platform.processor() or platform.machine(), "runs": runs})
    print("median:", json.dumps({k: round(v, 3) for k, v in summary.items() if k in keys}))
    if a.json:
        a.json.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
