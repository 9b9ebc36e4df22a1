"""Run time against error, side by side in one run: voxelastic's methods and the peer (issue 6.1).

    .venv/bin/python -m benchmarks accuracy [--quick | --full] [--problems lame,annulus,ball]
        [--methods staggered,dg1,dg2,p1,p2,p1-stl,p2-stl] [--repeats 3] [--out docs/accuracy] [--arch cpu]

Problems and probes: ``verification.problems``. Methods: the staggered method, DG k = 1 and k = 2
(IP, default penalty; 3D only) at several cell sizes h, and the peer (``benchmarks.peer``:
scikit-fem P1 / P2 on gmsh meshes of the CAD geometry, pyamg CG; with ``p1-stl`` / ``p2-stl`` on
fTetWild's tetrahedra of the STL voxelastic reads, meshing counted) at several mesh sizes; the same
meshes solved by DOLFINx (``dolfinx-p1``, ``dolfinx-p2``, ``dolfinx-p1-stl``, ``dolfinx-p2-stl``;
``benchmarks.dolfinx_peer``: PETSc CG + GAMG in Debian's ``python3-dolfinx``, a worker process of
the system Python, whose start and imports the cold job counts). Every run is a whole job in
its own spawned process (geometry, discretisation, solve, fields at the probes; no geometry
cache), twice: the first job is *cold* (what one CLI run costs: Taichi loads and compiles its
kernels), the second *warm* (what a job costs a service worker that has run one before; kernels
loaded, nothing of the first job's geometry kept). Wall time is measured around
``engine.simulate`` / ``run_peer`` / ``run_dolfinx``, imports excluded; the peers run twice the same
way. Peak RSS is the process's (plus the DOLFINx worker's). Runs are alternated (repeat r of every configuration before repeat r + 1) and
medians reported.

Errors: relative L2 over the 1200 probes of the displacement and of the von Mises stress (of
the warm job; ``rerun_difference`` says how far the cold job's probe displacements were from it).
Output under --out: accuracy.json (every run and the medians), accuracy.png (log-log error vs
time, one line per method and problem; solid warm, dotted cold) and accuracy.md (the tables, warm
and cold: for each error target, each method's time over the peer's at that error, the fastest of
the peers run on the CAD geometry and of those on the STL, interpolated log-log on the measured
curves; > 1 means voxelastic is slower).
"""

from __future__ import annotations

import argparse
import functools
import json
import multiprocessing as mp
import platform
import queue
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .memory import peak_rss_bytes

TARGETS = (1e-2, 1e-3, 1e-4)
# cell sizes h [m] (mesh sizes for the peer) per problem and method; --quick keeps the first few
SIZES = {
    "lame": {"staggered": [1 / 6, 1 / 8, 1 / 12, 1 / 16, 1 / 24, 1 / 32], "dg1": [1 / 4, 1 / 6, 1 / 8, 1 / 12],
             "dg2": [1 / 3, 1 / 4, 1 / 6, 1 / 8], "p1": [0.2, 0.14, 0.1, 0.07], "p2": [0.4, 0.28, 0.2, 0.14],
             "p1-stl": [0.2, 0.14, 0.1, 0.07], "p2-stl": [0.4, 0.28, 0.2, 0.14]},
    # the ball's staggered error is noisy below 1 / 8 (0.03 to 0.10 over h = 1 / 5 .. 1 / 7: first-order
    # surface tractions and the cap's rim); from 1 / 8 on it falls steadily
    "ball": {"staggered": [1 / 8, 1 / 12, 1 / 16, 1 / 24, 1 / 32], "dg1": [1 / 4, 1 / 6, 1 / 8, 1 / 12],
             "dg2": [1 / 3, 1 / 4, 1 / 6, 1 / 8], "p1": [0.28, 0.2, 0.14, 0.1], "p2": [0.4, 0.28, 0.2, 0.14],
             "p1-stl": [0.28, 0.2, 0.14, 0.1], "p2-stl": [0.4, 0.28, 0.2, 0.14]},
    "annulus": {"staggered": [1 / 20, 1 / 40, 1 / 80, 1 / 160, 1 / 320], "p1": [0.05, 0.025, 0.0125, 0.00625],
                "p2": [0.1, 0.05, 0.025, 0.0125]},
}
# DOLFINx (benchmarks.dolfinx_peer): the scikit-fem peer's meshes, so its sizes
for _sizes in (SIZES["lame"], SIZES["ball"]):
    _sizes.update({f"dolfinx-{m}": _sizes[m] for m in ("p1", "p2", "p1-stl", "p2-stl")})
QUICK = 3  # sizes per method with --quick
LABELS = {"staggered": "voxelastic staggered", "dg1": "voxelastic DG k=1", "dg2": "voxelastic DG k=2",
          "p1": "scikit-fem P1", "p2": "scikit-fem P2 (curved)",
          "p1-stl": "scikit-fem P1 (fTetWild on the STL)", "p2-stl": "scikit-fem P2 (fTetWild on the STL)",
          "dolfinx-p1": "DOLFINx P1", "dolfinx-p2": "DOLFINx P2 (curved)",
          "dolfinx-p1-stl": "DOLFINx P1 (fTetWild on the STL)", "dolfinx-p2-stl": "DOLFINx P2 (fTetWild on the STL)"}
# the peers' runs: on the CAD geometry (their best case) and on fTetWild's tetrahedra of the STL
PEERS = ("p1", "p2", "p1-stl", "p2-stl", "dolfinx-p1", "dolfinx-p2", "dolfinx-p1-stl", "dolfinx-p2-stl")
CAD_PEERS = ("p1", "p2", "dolfinx-p1", "dolfinx-p2")


def _voxelastic(problem_name: str, method: str, h: float, queue, warm: bool = True, arch: str = "cpu") -> None:
    from engine import simulate
    from engine.errors import VoxelasticError
    from engine.geometry.cache import GeometryCache
    from verification.problems import problem

    p = problem(problem_name)
    kind = {"staggered": {"kind": "staggered"}, "dg1": {"kind": "dg", "degree": 1},
            "dg2": {"kind": "dg", "degree": 2}}[method]

    def job() -> dict:
        spec, mesh, functions = p.job(dict(kind), h)
        spec["solver"] = {**spec.get("solver", {}), "arch": arch}
        with tempfile.TemporaryDirectory() as tmp:
            path = None
            if mesh is not None:
                path = Path(tmp) / spec["geometry"]["mesh"].replace(".stl", ".ply")
                spec["geometry"]["mesh"] = path.name
                mesh.export(path)  # binary PLY keeps float64 vertices
            t0 = time.perf_counter()
            result = simulate(spec, path, cache=GeometryCache(None), functions=functions)
            seconds = time.perf_counter() - t0
        return {"seconds": seconds, "displacement": result.fields.probes["displacement"],
                "von_mises": result.fields.probes["von_mises"], "iterations": result.solver.iterations,
                "residual": result.solver.residual, "stages": result.solver.stage_times,
                "warnings": result.solver.warnings}

    try:
        record = _cold_and_warm(p, problem_name, method, h, job, warm)
    except VoxelasticError as exc:  # refused (the memory estimate, a limit): a row that says why
        record = {"problem": problem_name, "method": method, "h": h, "failed": f"{type(exc).__name__}: {exc}"}
    queue.put(record)


def _cold_and_warm(p, problem_name: str, method: str, h: float, job: Callable[[], dict], twice: bool = True) -> dict:
    """The record of one configuration: ``job()`` run twice in this process, the second (warm) run's
    errors and times, the first one's time as ``seconds_cold``; with ``twice`` False one cold run,
    whose time is both."""
    from verification.problems import relative_l2

    cold = job()
    warm = job() if twice else dict(cold)
    u = np.asarray(warm.pop("displacement"))
    vm = np.asarray(warm.pop("von_mises"))
    scale = float(np.abs(u).max()) or 1.0
    return {**warm, "problem": problem_name, "method": method, "h": h,
            "seconds_cold": cold["seconds"], "stages_cold": cold["stages"],
            "rerun_difference": float(np.abs(np.asarray(cold["displacement"]) - u).max() / scale),
            "peak_rss_gib": peak_rss_bytes() / 2**30 + warm.pop("worker_peak_rss_gib", 0.0),
            "error_u": relative_l2(u, p.exact(p.probes)), "error_vm": relative_l2(vm, p.von_mises(p.probes))}


def _peer(problem_name: str, method: str, h: float, queue, warm: bool = True, arch: str = "cpu") -> None:
    import contextlib

    from verification.problems import problem

    # P2 isoparametric (curved faces): on straight facets the lame pressure caps P2 at h^2 (peer.py);
    # "-stl": fTetWild's tetrahedra of the STL voxelastic reads, straight-sided
    name = method.removeprefix("dolfinx-")
    order = int(name[1])
    geometry = "stl" if name.endswith("-stl") else "curved" if order == 2 else "straight"
    with contextlib.ExitStack() as stack:
        if method.startswith("dolfinx-"):  # one DOLFINx worker: started by the cold job, reused by the warm
            from benchmarks.dolfinx_peer import Worker, run_dolfinx

            solve = functools.partial(run_dolfinx, worker=stack.enter_context(Worker()))
        else:
            from benchmarks.peer import run_peer as solve

        def job() -> dict:
            out = solve(problem_name, order, h, geometry=geometry)
            return {k: v for k, v in out.items() if k not in ("error_u", "error_vm", "problem", "method", "h")}

        queue.put(_cold_and_warm(problem(problem_name), problem_name, method, h, job, warm))


def _one(problem_name: str, method: str, h: float, timeout: float, warm: bool = True,
         max_rss_gib: float | None = None, arch: str = "cpu") -> dict:
    """One configuration in its own spawned process: cold and (with ``warm``) warm job. A crash, a
    timeout or (with ``max_rss_gib``) a process whose resident memory passes that many GiB -- it is
    killed then -- is a row with ``failed`` saying which."""
    import psutil

    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    target = _peer if method in PEERS else _voxelastic
    proc = ctx.Process(target=target, args=(problem_name, method, h, q, warm, arch))
    t0 = time.perf_counter()
    proc.start()
    watched = psutil.Process(proc.pid)
    row, why = None, None
    while row is None and time.perf_counter() - t0 < timeout:
        try:
            row = q.get(timeout=1.0)
        except queue.Empty:
            if not proc.is_alive() and q.empty():
                break
            if max_rss_gib is not None and _rss_gib(watched) > max_rss_gib:
                why = f"killed above {max_rss_gib:g} GiB resident"
                proc.kill()
                break
    if row is None:  # a crash or a timeout is a row of the table, not an abort
        if why is None:
            why = f"exit code {proc.exitcode}" if proc.exitcode is not None else f"timed out after {timeout:g} s"
        row = {"problem": problem_name, "method": method, "h": h, "failed": why}
    proc.join(timeout=10)
    if proc.is_alive():
        proc.kill()
    row["process_s"] = time.perf_counter() - t0
    return row


def _rss_gib(process) -> float:
    """Resident memory [GiB] of ``process`` and its children (0 once it is gone)."""
    import psutil

    try:
        procs = [process, *process.children(recursive=True)]
        return sum(p.memory_info().rss for p in procs) / 2**30
    except psutil.Error:
        return 0.0


def medians(runs: list[dict]) -> list[dict]:
    """One row per (problem, method, h): medians of seconds and memory, errors of the first run."""
    groups: dict[tuple, list[dict]] = {}
    for r in runs:
        groups.setdefault((r["problem"], r["method"], r["h"]), []).append(r)
    out = []
    for (prob, method, h), rs in groups.items():
        ok = [r for r in rs if "failed" not in r]
        if not ok:
            out.append({"problem": prob, "method": method, "h": h, "failed": rs[0]["failed"]})
            continue
        row = {k: v for k, v in ok[0].items()
               if k not in ("seconds", "seconds_cold", "peak_rss_gib", "process_s", "stages", "stages_cold")}
        for key in ("seconds", "seconds_cold"):
            row[key] = statistics.median(r[key] for r in ok)
        row["peak_rss_gib"] = statistics.median(r["peak_rss_gib"] for r in ok)
        row["repeats"] = len(ok)
        out.append(row)
    return out


def time_at(rows: list[dict], target: float, key: str = "error_u", clock: str = "seconds") -> float | None:
    """Run time [s] (``clock``: "seconds" warm, "seconds_cold") at which a method's error curve
    reaches ``target``: log-log interpolation between the two measured points around it; None when
    no measured run is that accurate."""
    pts = sorted((r[key], r[clock]) for r in rows if "failed" not in r and np.isfinite(r[key]) and r[key] > 0)
    if not pts or min(e for e, _ in pts) > target:
        return None
    if max(e for e, _ in pts) <= target:
        return min(t for e, t in pts if e <= target)  # even the cheapest run is that accurate
    for (e0, t0), (e1, t1) in zip(pts, pts[1:]):  # sorted by error: e0 <= target <= e1
        if e0 <= target <= e1:
            w = (np.log(target) - np.log(e0)) / (np.log(e1) - np.log(e0)) if e1 > e0 else 0.0
            return float(np.exp(np.log(t0) + w * (np.log(t1) - np.log(t0))))
    return None


def _methods_run(rows: list[dict]) -> list[str]:
    """The methods that have rows, in LABELS' order."""
    return [m for m in LABELS if any(r["method"] == m for r in rows)]


def table(rows: list[dict], key: str = "error_u", clock: str = "seconds") -> str:
    """Markdown: per problem and error target, each method run's time and its ratios to the fastest
    peer on the CAD geometry and, where run, on the STL (above 1: voxelastic is slower)."""
    methods = _methods_run(rows)
    lines = ["| problem | error target | " + " | ".join(LABELS[m] for m in methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    for prob in dict.fromkeys(r["problem"] for r in rows):
        mine = [r for r in rows if r["problem"] == prob]
        for target in TARGETS:
            times = {m: time_at([r for r in mine if r["method"] == m], target, key, clock) for m in methods}
            fastest = {}
            for name, group in (("CAD", CAD_PEERS), ("STL", tuple(m for m in PEERS if m not in CAD_PEERS))):
                found = [times[m] for m in group if times.get(m) is not None]
                if found:
                    fastest[name] = min(found)
            cells = []
            for m in methods:
                t = times[m]
                if t is None:
                    cells.append("not reached" if any(r["method"] == m for r in mine) else "-")
                elif m in PEERS or not fastest:
                    cells.append(f"{t:.2f} s")
                else:
                    cells.append(f"{t:.2f} s (" + ", ".join(f"{t / v:.2g}x {n}" for n, v in fastest.items()) + ")")
            lines.append(f"| {prob} | {target:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    problems = list(dict.fromkeys(r["problem"] for r in rows))
    fig, axes = plt.subplots(1, len(problems), figsize=(5.5 * len(problems), 4.5), squeeze=False)
    for ax, prob in zip(axes[0], problems):
        for i, m in enumerate(_methods_run(rows)):
            label = LABELS[m]
            mine = [r for r in rows if r["problem"] == prob and r["method"] == m and "failed" not in r]
            marker, colour = "o" if m in PEERS else "s", f"C{i}"
            for clock, style, name in (("seconds", "-", label), ("seconds_cold", ":", None)):
                pts = [(r[clock], r["error_u"]) for r in sorted(mine, key=lambda r: -r["h"])]  # coarse to fine
                if pts:
                    ax.loglog(*zip(*pts), marker + style, color=colour, label=name, alpha=1.0 if name else 0.5,
                              markersize=5 if name else 3)
        for target in TARGETS:
            ax.axhline(target, color="0.85", lw=0.8, zorder=0)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # decade labels only
        ax.set(title=prob, xlabel="whole-job wall time [s] (solid: warm, dotted: cold)",
               ylabel="relative L2 error of u at probes")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _commit() -> str | None:
    """The checkout's commit (short hash, "+" when files differ from it); None outside git."""
    import subprocess

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=Path(__file__).parent, capture_output=True, text=True,
                              check=True).stdout.strip()

    try:
        changed = git("status", "--porcelain", "--untracked-files=no")
        return git("rev-parse", "--short", "HEAD") + ("+" if changed else "")
    except (OSError, subprocess.CalledProcessError):
        return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks accuracy", description=__doc__.splitlines()[0])
    size = ap.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help=f"the first {QUICK} sizes per method, 1 repeat")
    size.add_argument("--full", action="store_true", help="every size, 3 repeats")
    ap.add_argument("--problems", default="lame,annulus,ball")
    ap.add_argument("--methods", default="staggered,dg1,dg2,p1,p2")
    ap.add_argument("--repeats", type=int)
    ap.add_argument("--timeout", type=float, default=1200.0, help="seconds per run")
    ap.add_argument("--out", type=Path, default=Path("docs/accuracy"))
    ap.add_argument("--finest", type=int, help="only the N finest sizes per method")
    ap.add_argument("--arch", default="cpu", help="voxelastic's solver.arch (cpu, cuda); the peer runs on the CPU")
    a = ap.parse_args(argv)
    repeats = a.repeats or (1 if a.quick else 3 if a.full else 2)
    methods = a.methods.split(",")
    configs = []
    for prob in a.problems.split(","):
        for m in methods:
            sizes = SIZES[prob].get(m, [])
            sizes = sizes[-a.finest:] if a.finest else sizes
            configs += [(prob, m, h) for h in (sizes[:QUICK] if a.quick else sizes)]
    runs = []
    for r in range(repeats):
        for prob, m, h in configs:
            row = _one(prob, m, h, a.timeout, arch=a.arch)
            row["repeat"] = r
            runs.append(row)
            brief = {k: (round(v, 6) if isinstance(v, float) else v) for k, v in row.items()
                     if k in ("problem", "method", "h", "seconds", "seconds_cold", "error_u", "error_vm", "iterations",
                              "failed")}
            print(json.dumps(brief), flush=True)
    rows = medians(runs)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "accuracy.json").write_text(json.dumps(
        {"machine": platform.processor() or platform.machine(), "arch": a.arch, "commit": _commit(), "date": time.strftime("%Y-%m-%d"),
         "repeats": repeats, "medians": rows, "runs": runs}, indent=1, default=float))
    plot(rows, a.out / "accuracy.png")
    text = (f"Displacement (relative L2 at the probes), time to reach the error, warm (a job in a process "
            f"that has run one before: a service worker); in brackets: over the fastest peer's time on the CAD "
            f"geometry, and on the STL where run.\n\n"
            f"{table(rows)}\n\nThe same, cold (the first job in a fresh process: one CLI run):\n\n"
            f"{table(rows, clock='seconds_cold')}\n\nVon Mises stress (relative L2 at the probes), warm:\n\n"
            f"{table(rows, 'error_vm')}\n")
    (a.out / "accuracy.md").write_text(text)
    print(text)
    return 0 if not any("failed" in r for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
