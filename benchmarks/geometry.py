"""Geometry floors: exact volume fractions at 256^3 and hex slicing at 32^3 of ~100k-triangle meshes.

    .venv/bin/python -m benchmarks.geometry [--repeats 3] [--quick] [--json out.json]

Every measurement runs in its own spawned process (so peak memory is that stage's alone, Taichi
compile caches warm after the first run); medians over the repeats are reported.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import platform
import resource
import statistics
import time

import numpy as np


def bumpy_sphere():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=6, radius=1.0)
    v = m.vertices
    r = 1.0 + 0.12 * np.sin(3 * v[:, 0]) * np.sin(4 * v[:, 1]) * np.sin(5 * v[:, 2] + 0.3)
    m.vertices = v * r[:, None]
    return m


def torus():
    import trimesh

    return trimesh.creation.torus(major_radius=1.0, minor_radius=0.4, major_sections=250, minor_sections=200)


MESHES = {"bumpy_sphere": bumpy_sphere, "torus": torus}


def _surface(name):
    from engine.geometry.surface import Surface

    m = MESHES[name]()
    return Surface(np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))


def _fractions(name: str, resolution: int, queue) -> None:
    from engine.geometry.fractions import volume_fractions
    from engine.grid import make_grid
    from engine.runtime import init

    init("cpu", "f64")
    surface = _surface(name)
    grid = make_grid(*surface.bounds, resolution=resolution, padding=1)
    t = time.perf_counter()
    vf = volume_fractions(surface, grid)
    seconds = time.perf_counter() - t
    exact = surface.enclosed_volume()
    queue.put(
        {
            "triangles": len(surface.faces),
            "grid": list(grid.shape),
            "seconds": seconds,
            "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
            "relative_volume_error": abs(vf.solid_volume() - exact) / exact,
            "stored_tiles": {str(s): len(b.coords) for s, b in vf.control.items()},
            "stored_mb": sum(b.nbytes for b in vf.control.values()) / 2**20,
        }
    )


def _slicing(name: str, resolution: int, workers: int | None, queue) -> None:
    from benchmarks.slicing_bench import bench_slicing
    from engine.grid import make_grid

    surface = _surface(name)
    grid = make_grid(*surface.bounds, resolution=resolution, padding=1)
    out = bench_slicing(surface, grid, workers=workers)
    out["peak_rss_gb"] = (out["peak_rss_mb"] + out["children_peak_rss_mb"]) / 1024
    queue.put(out)


def run_isolated(target, *args, timeout: float | None = None) -> dict:
    """``target(*args, queue)`` in a fresh spawned process; its result. A child that dies without
    one (an exception, the OOM killer) raises instead of leaving the benchmark waiting forever;
    one still working after ``timeout`` seconds (None: no limit) is killed and TimeoutError raised."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    p = ctx.Process(target=target, args=(*args, queue))
    start = time.perf_counter()
    p.start()
    while True:
        try:
            out = queue.get(timeout=1.0)
            break
        except Exception:  # queue.Empty: still working, or gone
            if not p.is_alive() and queue.empty():
                raise RuntimeError(f"{getattr(target, '__name__', target)}: the benchmark process ended with exit code "
                                   f"{p.exitcode} and no result (its error is printed above)") from None
            if timeout is not None and time.perf_counter() - start > timeout:
                p.kill()
                p.join()
                raise TimeoutError(f"{getattr(target, '__name__', target)}: no result after {timeout:g} s") from None
    p.join()
    return out


def median_of(runs: list[dict]) -> dict:
    out = dict(runs[-1])
    for key in ("seconds", "peak_rss_gb"):
        out[key] = statistics.median(r[key] for r in runs)
        out[key + "_all"] = [round(r[key], 3) for r in runs]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="smaller grids (64^3 / 16^3), one repeat")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--workers", type=int, default=None, help="slicing worker processes (default: automatic)")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    res_vf, res_slice = (64, 16) if args.quick else (256, 32)
    results = {"machine": f"{platform.node()} {platform.processor() or platform.machine()}, {mp.cpu_count()} cores"}
    # warm the Taichi offline cache so the first timed run does not include compilation
    run_isolated(_fractions, "bumpy_sphere", 16)
    for name in MESHES:
        vf = [run_isolated(_fractions, name, res_vf) for _ in range(repeats)]
        sl = [run_isolated(_slicing, name, res_slice, args.workers) for _ in range(repeats)]
        results[name] = {"volume_fractions": median_of(vf), "hex_slicing": median_of(sl)}
        a, b = results[name]["volume_fractions"], results[name]["hex_slicing"]
        print(
            f"{name:13s} {a['triangles']:7d} tris | fractions {'x'.join(map(str, a['grid']))}: "
            f"{a['seconds']:6.2f} s, {a['peak_rss_gb']:.2f} GB, vol err {a['relative_volume_error']:.1e} | "
            f"slicing {'x'.join(map(str, b['grid']))}: {b['seconds']:5.2f} s, {b['peak_rss_gb']:.2f} GB, "
            f"{b['pieces']} pieces ({b['workers']} proc), vol err {b['relative_volume_error']:.1e}"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
