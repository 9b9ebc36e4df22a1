"""Staggered method floors: a sphere shell solved statically, operator throughput, multigrid iterations.

    .venv/bin/python -m benchmarks.staggered [--resolution 256] [--repeats 1] [--arch cpu] [--precision f64] [--json out.json]
    .venv/bin/python -m benchmarks.staggered --resolution 128 --nu 0.3 0.4999     # the shell at each nu (issue 21)
    .venv/bin/python -m benchmarks.staggered --lame 0.05 --nu 0.3 0.49 0.499 0.4999   # free thick sphere (issue 21)
    .venv/bin/python -m benchmarks.staggered --iterations 32 64 128 --nu 0.3 0.45 0.49
    .venv/bin/python -m benchmarks.staggered --growth 32 64 [--fixed-share 0.5] [--no-band]

Every job runs in its own spawned process (peak memory is that job's alone); medians over repeats.
The shell: outer radius 1, inner 0.6, clamped below z = -0.8, gravity; rtol 1e-6; E = 1 MPa and
Poisson's ratio --nu (0.3 by default; several give one shell run each and their time ratios).
--lame H: the free Lame thick sphere of ``verification.problems`` at cell size H and each --nu
(rtol 1e-10): CG iterations, relative L2 error of u at its probes against the closed form, seconds.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import platform
import statistics
import tempfile
import time
from pathlib import Path

from .geometry import run_isolated
from .memory import peak_rss_bytes


def shell_mesh(path: Path) -> None:
    import trimesh

    outer = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=5, radius=0.6)
    inner.invert()
    trimesh.util.concatenate([outer, inner]).export(path)


def sphere_mesh(path: Path) -> None:
    import trimesh

    trimesh.creation.icosphere(subdivisions=5, radius=1.0).export(path)


def job(mesh: str, resolution: int, nu: float, rtol: float, arch: str, precision: str = "f64") -> dict:
    return {
        "geometry": {"mesh": mesh},
        "grid": {"resolution": resolution},
        "method": {"kind": "staggered", "solver": "iterative"},  # the multigrid's benchmark, also on small grids
        "material": {"youngs_modulus": 1e6, "poisson_ratio": nu, "density": 1000},
        "loads": {"gravity": [0, 0, -9.81]},
        "boundaries": [{"kind": "displacement", "name": "base", "region": {"box": [[-2, -2, -2], [2, 2, -0.8]]}, "value": [0, 0, 0]}],
        "solver": {"rtol": rtol, "arch": arch, "precision": precision, "max_iterations": 2000},
        "output": {"fields": ["displacement"], "surface": False},
    }


def _solve(spec: dict, queue) -> None:
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import Limits, run

    t = time.perf_counter()
    r = run(spec, cache=GeometryCache(None), limits=Limits(max_memory_bytes=64 * 2**30))
    wall = time.perf_counter() - t
    peak = peak_rss_bytes()
    queue.put({"wall_s": wall, "peak_bytes": peak, "iterations": r.solver.iterations, "residual": r.solver.residual,
               "stages": r.solver.stage_times, "shape": list(r.grid.shape)})


def _throughput(mesh: str, resolution: int, arch: str, queue) -> None:
    """Median time of one operator apply and of a Taichi copy of the same vectors."""
    import numpy as np

    from engine.geometry.fractions import volume_fractions
    from engine.geometry.loading import load_surface
    from engine.grid import make_grid
    from engine.runtime import init
    from engine.staggered import kernels
    from engine.staggered.operator import make_fine_level

    init(arch, "f64")
    surface = load_surface(Path(mesh).read_bytes(), filename=Path(mesh).name)
    grid = make_grid(*surface.bounds, resolution=resolution)
    level = make_fine_level(volume_fractions(surface, grid), 1.0, 1.0)
    x, y = level.zeros(), level.zeros()
    x.from_numpy(np.random.default_rng(0).standard_normal((grid.dim, level.size)) * level.active)

    def timed(f, n=10):
        f()
        times = []
        for _ in range(n):
            t = time.perf_counter()
            f()
            kernels.dot(grid.dim, y, y)  # synchronise
            times.append(time.perf_counter() - t)
        return statistics.median(times)

    apply_s = timed(lambda: level.apply(x, y))
    copy_s = timed(lambda: kernels.copy(grid.dim, x, y))
    d, pairs = grid.dim, len(level.ve_host)
    positions = level.layout.count * level.layout.tile_size
    cut = (level.layout.count - level.full_tiles) * level.layout.tile_size
    # the bytes an apply cannot avoid moving, each array once: x read, the weighted stresses (d + pairs
    # per position) written and read back, the fractions read in cut tiles only, the int8 mask read,
    # y written; neighbours' values re-read from cache are not counted
    moved = 8 * positions * (d + 2 * (d + pairs) + d) + positions * d + 8 * cut * (1 + pairs)
    queue.put({
        "kept_positions": positions, "active_dofs": int(level.active.sum()),
        "apply_s": apply_s, "copy_s": copy_s,
        "copy_GBps": 2 * x.to_numpy().nbytes / copy_s / 1e9,
        "apply_bytes": moved, "apply_GBps": moved / apply_s / 1e9,
        "apply_positions_per_s": positions / apply_s, "apply_dofs_per_s": int(level.active.sum()) / apply_s,
        "full_tiles": level.full_tiles, "tiles": level.layout.count,
    })


def _lame(h: float, nu: float, queue) -> None:
    from verification.problems import lame_at, relative_l2, simulate_problem

    pb = lame_at(nu)
    t = time.perf_counter()
    r = simulate_problem(pb, {"kind": "staggered", "solver": "iterative"}, h)
    queue.put({"wall_s": time.perf_counter() - t, "iterations": r.solver.iterations, "stages": r.solver.stage_times,
               "error_u": relative_l2(r.fields.probes["displacement"], pb.exact(pb.probes))})


def _growth(mesh: str, resolution: int, fixed_share: float | None, band: bool, queue) -> None:
    """Error growth per stationary V-cycle, e <- (I - M A) e with a zero right-hand side, after 12
    cycles (the dominant mode's factor; above 1 the cycle alone diverges and CG must absorb it)."""
    import numpy as np

    from engine.geometry.cache import GeometryCache
    from engine.pipeline import Functions, Limits, prepare_geometry
    from engine.runtime import init
    from engine.staggered import multigrid
    from engine.staggered.operator import device_array
    from engine.staggered.problem import make_staggered
    from schemas import parse_job

    if fixed_share is not None:
        multigrid.FIXED_SHARE = fixed_share
    if not band:
        multigrid.boundary_band = lambda level: None
    init("cpu", "f64")
    spec = parse_job(job(mesh, resolution, 0.3, 1e-8, "cpu"))
    method = make_staggered(spec, prepare_geometry(spec, None, cache=GeometryCache(None), limits=Limits()), Functions())
    level, mg = method.level, method.multigrid
    y, z = level.zeros(), level.zeros()

    def energy_norm(e):
        level.apply(device_array(e), y)
        return float(np.sqrt(np.sum(e * y.to_numpy())))

    e = np.random.default_rng(1).standard_normal(level.free.shape) * level.free
    e /= energy_norm(e)
    for _ in range(12):
        level.apply(device_array(e), y)
        mg.precondition(device_array(-y.to_numpy()), z)
        e = e + z.to_numpy() * level.free
        factor = energy_norm(e)
        e /= factor
    queue.put({"growth": factor})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--precision", default="f64", choices=("f64", "f32"), help="solver storage precision of the shell job")
    ap.add_argument("--iterations", type=int, nargs="*", help="resolutions of the multigrid iteration study (sphere)")
    ap.add_argument("--nu", type=float, nargs="*", default=[0.3])
    ap.add_argument("--growth", type=int, nargs="*", help="resolutions of the stationary V-cycle study (sphere)")
    ap.add_argument("--lame", type=float, help="cell size of the free thick sphere study, one run per --nu")
    ap.add_argument("--fixed-share", type=float, help="override multigrid.FIXED_SHARE in the V-cycle study")
    ap.add_argument("--no-band", action="store_true", help="V-cycle study without the boundary smoothing")
    ap.add_argument("--json")
    args = ap.parse_args()
    out: dict = {"machine": platform.platform(), "cpus": mp.cpu_count()}
    with tempfile.TemporaryDirectory() as tmp:
        shell, sphere = Path(tmp) / "shell.stl", Path(tmp) / "sphere.stl"
        shell_mesh(shell)
        sphere_mesh(sphere)
        if args.lame:
            out["lame"] = []
            for nu in args.nu:
                r = run_isolated(_lame, args.lame, nu)
                out["lame"].append({"nu": nu, "h": args.lame, **r})
                print(f"thick sphere h={args.lame:g} nu={nu:g}: {r['iterations']} iterations, error {r['error_u']:.3e}, "
                      f"{r['wall_s']:.1f} s (solve {r['stages'].get('solve', 0.0):.1f} s)", flush=True)
        elif args.growth:
            out["growth"] = []
            for n in args.growth:
                r = run_isolated(_growth, str(sphere), n, args.fixed_share, not args.no_band)
                out["growth"].append({"resolution": n, "fixed_share": args.fixed_share, "band": not args.no_band, **r})
                print(f"sphere {n}^3: error growth {r['growth']:.3g} per V-cycle", flush=True)
        elif args.iterations:
            rows = []
            for nu in args.nu:
                for n in args.iterations:
                    r = run_isolated(_solve, job(str(sphere), n, nu, 1e-8, args.arch))
                    rows.append({"nu": nu, "resolution": n, **r})
                    print(f"sphere nu={nu} {n}^3: {r['iterations']} iterations to 1e-8, {r['wall_s']:.1f} s", flush=True)
            out["iterations"] = rows
        else:
            tp = run_isolated(_throughput, str(shell), args.resolution, args.arch)
            out["throughput"] = tp
            print(f"operator: {tp['apply_s'] * 1e3:.1f} ms per apply, {tp['apply_dofs_per_s'] / 1e6:.1f} M DOF/s, "
                  f"{tp['apply_bytes'] / 1e9:.2f} GB moved per apply at least ({tp['apply_GBps']:.1f} GB/s), "
                  f"copy {tp['copy_GBps']:.1f} GB/s", flush=True)
            out["shell"] = []
            for nu in args.nu:
                runs = [run_isolated(_solve, job(str(shell), args.resolution, nu, 1e-6, args.arch, args.precision))
                        for _ in range(args.repeats)]
                wall = statistics.median(r["wall_s"] for r in runs)
                peak = statistics.median(r["peak_bytes"] for r in runs)
                out["shell"].append({"nu": nu, "runs": runs, "wall_s": wall})
                ratio = f", {wall / out['shell'][0]['wall_s']:.2f}x nu = {args.nu[0]:g}'s time" if len(out["shell"]) > 1 else ""
                print(f"shell {args.resolution}^3 nu={nu:g}: {wall:.1f} s, {peak / 2**30:.2f} GiB, {runs[0]['iterations']} "
                      f"iterations, stages {runs[0]['stages']}{ratio}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
