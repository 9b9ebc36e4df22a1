"""Scaling (issue 6): time and peak memory against DOFs for both methods, multigrid iterations against h.

    .venv/bin/python -m benchmarks scaling                      # staggered 32..256^3, DG k = 1, 2 at 8..32
    .venv/bin/python -m benchmarks scaling --quick              # staggered 32, 64; DG 8, 12 (a few minutes)
    .venv/bin/python -m benchmarks scaling --staggered 32 64 128 --dg 8 12 16 --degrees 1 \\
        [--repeats 3] [--timeout 1800] [--arch cpu] [--json out.json] [--png out.png]
    .venv/bin/python -m benchmarks scaling --staggered --dg 8 12 16   # DG only (an empty list skips a method)

The problem is the one of ``benchmarks.staggered`` for both methods: a sphere shell (icospheres of
radius 1 and 0.6), E = 1e6 Pa, nu = 0.3, clamped below z = -0.8, gravity, rtol 1e-6 (staggered);
DG is IP with the default penalty. Resolution n: n cells across the bounding box (plus 1 padding
cell on each side), h = 2 m / n.

Every run is a whole job through ``engine.pipeline.run`` in its own spawned process (cold
geometry cache; peak RSS is that job's alone), after one untimed run per method at its smallest
size to warm Taichi's kernel cache. Repeats alternate (repeat r of every configuration before
repeat r + 1); medians are reported. A run past --timeout is killed and recorded as timed out, and
the larger sizes of that method are then skipped; a crash is recorded too (exit code 1).

Per run: DOFs (unknowns solved: staggered, the free displacement components; DG, elements x 3 x
basis size), active cells (volume fraction > 0) and DG elements (after merging small pieces),
job time [s] (around ``engine.pipeline.run``: runtime init, geometry, discretisation, solve,
fields), solve time [s] (staggered: multigrid-preconditioned CG, the hierarchy is built in the
discretisation; DG: the solver's set-up, which happens while discretising -- the PARDISO
factorisation, or above the size limit the p-multigrid's coarse factorisation -- plus the solve:
the prescribed values' right-hand side, back-substitution or CG to the job's rtol, residual), the
pipeline's stage times (and DG's own: basis, element blocks, loads, assembly, factorisation), peak
RSS [GiB] (the job's process; DG slicing workers separately), CG iterations and final relative
residual (DG: 1 for a direct solve).

Output: a markdown table, the fitted exponents p of time ~ DOFs^p (and of peak RSS) per method,
by least squares on log-log over the sizes from the second smallest up (the smallest is dominated
by fixed costs) and over all sizes; the multigrid iterations against h; a JSON file (default under
the temporary directory) and with --png a log-log plot of time and memory against DOFs.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import platform
import resource
import statistics
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .geometry import run_isolated
from .memory import peak_rss_bytes
from .staggered import job, shell_mesh

STAGGERED_SIZES = (32, 64, 128, 256)
DG_SIZES = (8, 12, 16, 24, 32)
QUICK_STAGGERED, QUICK_DG = (32, 64), (8, 12)
DEGREES = (1, 2)
RTOL = 1e-6
POISSON = 0.3
MEMORY_LIMIT = 64 * 2**30  # [bytes] the pipeline's estimate check; the machine's memory is the real limit


def label_of(method: str, degree: int | None) -> str:
    """Row label: 'staggered', 'dg1', 'dg2'."""
    return method if method == "staggered" else f"dg{degree}"


def spec_of(method: str, degree: int | None, resolution: int, mesh: str, arch: str) -> dict:
    """The job dict of one run: ``benchmarks.staggered.job``'s shell, with the DG method if asked."""
    spec = job(mesh, resolution, POISSON, RTOL, arch)
    # the staggered rows measure the multigrid V-cycle, also where "auto" would factorise a small grid
    spec["method"] = {"kind": "staggered", "solver": "iterative"} if method == "staggered" else {"kind": "dg", "degree": degree}
    return spec


# ----------------------------------------------------------------------------- one run (child process)


def _record_method(record: dict) -> None:
    """Make ``engine.pipeline.run`` hand its method object and per-solve seconds to ``record``.

    The Result reports stage times but not the number of unknowns nor the pure solve time, and
    the stages called one by one would no longer be the pipeline's own code path; wrapping its
    discretisation step keeps the path and exposes the method (this process only)."""
    import engine.pipeline as pipeline

    inner = pipeline._discretize

    def discretize(spec, geo, functions, progress=None):
        method = inner(spec, geo, functions, progress)
        solve = method.solve

        def timed_solve(*args, **kwargs):
            state = solve(*args, **kwargs)
            record["solve_seconds"].append(state.seconds)
            return state

        method.solve = timed_solve
        record["method"] = method
        return method

    record["solve_seconds"] = []
    pipeline._discretize = discretize


def _job(method: str, degree: int | None, resolution: int, mesh: str, arch: str, queue) -> None:
    """Run one job end to end and put its figures on ``queue`` (see the module docstring)."""
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import Limits, run

    record: dict = {}
    _record_method(record)
    spec = spec_of(method, degree, resolution, mesh, arch)
    t = time.perf_counter()
    result = run(spec, mesh, cache=GeometryCache(None), limits=Limits(max_memory_bytes=MEMORY_LIMIT))
    wall = time.perf_counter() - t
    m = record.get("method")
    if m is None:
        raise RuntimeError("engine.pipeline.run no longer calls _discretize: update benchmarks.scaling._record_method")
    stages = dict(result.solver.stage_times)
    row = {
        "method": method, "degree": degree, "label": label_of(method, degree), "resolution": resolution,
        "h": float(result.grid.spacing), "shape": list(result.grid.shape),
        "active_cells": int(np.count_nonzero(result.volume_fraction > 0)),
        "wall_s": wall, "stages": stages, "iterations": int(result.solver.iterations),
        "residual": float(result.solver.residual), "warnings": list(result.solver.warnings),
    }
    solves = sum(record["solve_seconds"])  # [s] the method's solve calls (one: the analysis is static)
    if method == "staggered":
        row.update(dofs=int(m.level.free.sum()), active_dofs=int(m.level.active.sum()), elements=None,
                   solve_s=solves)
    else:
        row.update(dofs=int(m.size), elements=int(m.elements.count), pieces=int(m.cut.num_pieces),
                   method_timings=dict(m.timings), nnz=int(m.matrix.nnz), eta=float(m.eta),
                   solve_s=m.timings.get("factorisation", 0.0) + solves)
    row["peak_rss_gib"] = peak_rss_bytes() / 2**30
    # the memory check's estimate for this grid and method (DG: with the pieces' count, as after the
    # slicing), beside the peak it must cover
    from engine.method import method_entry
    from schemas import parse_job

    pieces = None if method == "staggered" else int(m.cut.num_pieces)
    method_spec = parse_job(spec).method
    row["estimate_gib"] = method_entry(method_spec.kind).estimate_memory(result.grid, method_spec, occupied=pieces) / 2**30
    row["children_peak_rss_gib"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20
    queue.put(row)


def measure(method: str, degree: int | None, resolution: int, mesh: str, arch: str, timeout: float) -> dict:
    """One run in its own spawned process; a timeout or a crash becomes a row with 'failed'."""
    t = time.perf_counter()
    try:
        row = run_isolated(_job, method, degree, resolution, mesh, arch, timeout=timeout)
    except TimeoutError:
        row = {"failed": f"timed out after {timeout:g} s", "timed_out": True}
    except RuntimeError as exc:  # the child died without a result; its traceback is on stderr
        row = {"failed": str(exc).split(": ", 1)[-1]}
    row.update(method=method, degree=degree, label=label_of(method, degree), resolution=resolution)
    row["process_s"] = time.perf_counter() - t
    return row


# ----------------------------------------------------------------------------- analysis (pure)


def fit_exponent(dofs: Sequence[float], values: Sequence[float]) -> float | None:
    """p of values ~ c DOFs^p by least squares on log-log; None with fewer than 2 distinct DOF counts."""
    x, y = np.log(np.asarray(dofs, dtype=float)), np.log(np.asarray(values, dtype=float))
    if len(np.unique(x)) < 2:
        return None
    return float(np.polyfit(x, y, 1)[0])


def medians(runs: list[dict]) -> list[dict]:
    """One row per (label, resolution), in first-seen order: medians of the times and memory over
    the successful repeats, everything else from the first; 'failed' when none succeeded."""
    groups: dict[tuple, list[dict]] = {}
    for r in runs:
        groups.setdefault((r["label"], r["resolution"]), []).append(r)
    out = []
    for rs in groups.values():
        ok = [r for r in rs if "failed" not in r]
        if not ok:
            out.append(dict(rs[0]))
            continue
        row = {k: v for k, v in ok[0].items() if k != "repeat"}
        for key in ("wall_s", "solve_s", "peak_rss_gib", "children_peak_rss_gib"):
            row[key] = statistics.median(r[key] for r in ok)
        row["repeats"] = len(ok)
        out.append(row)
    return out


def fits(rows: list[dict], key: str) -> dict[str, dict]:
    """Per label: the exponent of ``key`` against DOFs over the sizes from the second smallest up
    ('p_tail', its resolutions 'tail') and over all sizes ('p_all'); failed rows are left out."""
    out = {}
    for label in dict.fromkeys(r["label"] for r in rows):
        ok = sorted((r for r in rows if r["label"] == label and "failed" not in r), key=lambda r: r["resolution"])
        tail = ok[1:]
        out[label] = {
            "tail": [r["resolution"] for r in tail],
            "p_tail": fit_exponent([r["dofs"] for r in tail], [r[key] for r in tail]),
            "all": [r["resolution"] for r in ok],
            "p_all": fit_exponent([r["dofs"] for r in ok], [r[key] for r in ok]),
        }
    return out


# ----------------------------------------------------------------------------- reporting


def _p(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def runs_table(rows: list[dict]) -> str:
    """Markdown: one line per (method, size)."""
    lines = ["| method | n | h [m] | DOFs | active cells | DG elements | job [s] | solve [s] | peak RSS [GiB] "
             "| estimate / peak | iterations | residual |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "failed" in r:
            lines.append(f"| {r['label']} | {r['resolution']} | | | | | {r['failed']} | | | | | |")
            continue
        elements = "" if r.get("elements") is None else f"{r['elements']:,}"
        # the memory estimate must cover the peak (>= 1) from the sizes where the process's own
        # ~0.3 GiB no longer dominates
        cover = f"{r['estimate_gib'] / r['peak_rss_gib']:.2f}" if r.get("estimate_gib") else ""
        lines.append(f"| {r['label']} | {r['resolution']} | {r['h']:.4g} | {r['dofs']:,} | {r['active_cells']:,} "
                     f"| {elements} | {r['wall_s']:.2f} | {r['solve_s']:.2f} | {r['peak_rss_gib']:.2f} | {cover} "
                     f"| {r['iterations']} | {r['residual']:.1e} |")
    return "\n".join(lines)


def fits_table(rows: list[dict]) -> str:
    """Markdown: exponents p of job time, solve time and peak RSS ~ DOFs^p per method."""
    lines = ["| method | quantity | p (n from the 2nd size) | sizes used | p (all sizes) | sizes used |",
             "|---|---|---:|---|---:|---|"]
    for key, name in (("wall_s", "job time"), ("solve_s", "solve time"), ("peak_rss_gib", "peak RSS")):
        for label, f in fits(rows, key).items():
            lines.append(f"| {label} | {name} | {_p(f['p_tail'])} | {', '.join(map(str, f['tail'])) or '-'} "
                         f"| {_p(f['p_all'])} | {', '.join(map(str, f['all'])) or '-'} |")
    return "\n".join(lines)


def iterations_table(rows: list[dict]) -> str:
    """Markdown: multigrid-preconditioned CG iterations against the cell size h."""
    lines = [f"| n | h [m] | CG iterations to rtol {RTOL:g} | final residual |", "|---:|---:|---:|---:|"]
    for r in sorted((r for r in rows if r["label"] == "staggered" and "failed" not in r), key=lambda r: r["resolution"]):
        lines.append(f"| {r['resolution']} | {r['h']:.4g} | {r['iterations']} | {r['residual']:.1e} |")
    return "\n".join(lines)


def plot(rows: list[dict], path: Path) -> None:
    """Log-log job time (solid), solve time (dashed) and peak RSS against DOFs, one colour per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(11, 4.5))
    for i, label in enumerate(dict.fromkeys(r["label"] for r in rows)):
        ok = sorted((r for r in rows if r["label"] == label and "failed" not in r), key=lambda r: r["dofs"])
        if not ok:
            continue
        dofs = [r["dofs"] for r in ok]
        colour = f"C{i}"
        ax_t.loglog(dofs, [r["wall_s"] for r in ok], "o-", color=colour, label=f"{label} job")
        ax_t.loglog(dofs, [r["solve_s"] for r in ok], "s--", color=colour, label=f"{label} solve")
        ax_m.loglog(dofs, [r["peak_rss_gib"] for r in ok], "o-", color=colour, label=label)
    ok = [r for r in rows if "failed" not in r]
    if ok:  # a guide of slope 1 (time proportional to DOFs, the multigrid goal) through the largest run
        top = max(ok, key=lambda r: r["dofs"])
        span = np.array([min(r["dofs"] for r in ok), top["dofs"]], dtype=float)
        ax_t.loglog(span, top["wall_s"] * span / top["dofs"], ":", color="0.5", label="slope 1")
    ax_t.set(xlabel="DOFs", ylabel="wall time [s]", title="time against DOFs")
    ax_m.set(xlabel="DOFs", ylabel="peak RSS [GiB]", title="peak memory against DOFs")
    for ax in (ax_t, ax_m):
        ax.grid(True, which="both", color="0.9")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ----------------------------------------------------------------------------- driver


def configurations(staggered: Sequence[int], dg: Sequence[int], degrees: Sequence[int]) -> list[tuple]:
    """(method, degree, resolution) of every run, each method's sizes ascending."""
    out = [("staggered", None, n) for n in sorted(staggered)]
    out += [("dg", k, n) for k in degrees for n in sorted(dg)]
    return out


def sweep(configs: list[tuple], mesh: str, arch: str, repeats: int, timeout: float) -> list[dict]:
    """Every configuration ``repeats`` times, alternating; sizes above a timed-out one are skipped
    (they would only time out too)."""
    runs: list[dict] = []
    stopped: dict[str, int] = {}  # label -> smallest resolution that timed out
    for repeat in range(repeats):
        for method, degree, n in configs:
            label = label_of(method, degree)
            if label in stopped and n >= stopped[label]:
                if repeat == 0:  # one row per skipped size is enough
                    runs.append({"method": method, "degree": degree, "label": label, "resolution": n,
                                 "failed": f"skipped ({stopped[label]} timed out)", "repeat": repeat})
                continue
            row = measure(method, degree, n, mesh, arch, timeout)
            row["repeat"] = repeat
            runs.append(row)
            if row.get("timed_out"):
                stopped[label] = n
            brief = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()
                     if k in ("label", "resolution", "dofs", "wall_s", "solve_s", "peak_rss_gib", "iterations",
                              "failed")}
            print(json.dumps(brief), flush=True)
    return runs


def warm_up(configs: list[tuple], mesh: str, arch: str, timeout: float) -> None:
    """One untimed run per method at its smallest size, so that no timed run compiles kernels."""
    for label in dict.fromkeys(label_of(m, k) for m, k, _ in configs):
        method, degree, n = min((c for c in configs if label_of(c[0], c[1]) == label), key=lambda c: c[2])
        row = measure(method, degree, n, mesh, arch, timeout)
        took = row.get("failed") or f"{row['process_s']:.1f} s"
        print(f"warm-up {label} {n}^3: {took}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks scaling", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--staggered", type=int, nargs="*", help=f"resolutions (default {STAGGERED_SIZES})")
    ap.add_argument("--dg", type=int, nargs="*", help=f"DG resolutions (default {DG_SIZES})")
    ap.add_argument("--degrees", type=int, nargs="+", default=list(DEGREES), choices=(1, 2))
    ap.add_argument("--quick", action="store_true",
                    help=f"staggered {QUICK_STAGGERED}, DG {QUICK_DG} (where --staggered / --dg are not given)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per configuration (medians reported)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run before it is killed")
    ap.add_argument("--arch", default="cpu", choices=("cpu", "cuda"), help="Taichi backend (solver.arch)")
    ap.add_argument("--json", type=Path, help="figures file (default: <tmp>/voxelastic_scaling.json)")
    ap.add_argument("--png", type=Path, help="log-log plot of time and memory against DOFs")
    ap.add_argument("--no-warmup", action="store_true", help="skip the untimed kernel-cache warm-up runs")
    a = ap.parse_args(argv)
    staggered = a.staggered if a.staggered is not None else QUICK_STAGGERED if a.quick else STAGGERED_SIZES
    dg = a.dg if a.dg is not None else QUICK_DG if a.quick else DG_SIZES
    configs = configurations(staggered, dg, a.degrees)
    if not configs:
        ap.error("nothing to run: both --staggered and --dg are empty")
    out_json = a.json or Path(tempfile.gettempdir()) / "voxelastic_scaling.json"
    with tempfile.TemporaryDirectory() as tmp:
        mesh = str(Path(tmp) / "shell.stl")
        shell_mesh(Path(mesh))
        if not a.no_warmup:
            warm_up(configs, mesh, a.arch, a.timeout)
        runs = sweep(configs, mesh, a.arch, a.repeats, a.timeout)
    rows = medians(runs)
    text = (f"## Runs (medians of {a.repeats})\n\n{runs_table(rows)}\n\n"
            f"## Exponents p of quantity ~ DOFs^p (least squares on log-log)\n\n{fits_table(rows)}\n\n")
    if any(r["label"] == "staggered" and "failed" not in r for r in rows):
        text += f"## Multigrid iterations against h\n\n{iterations_table(rows)}\n"
    print("\n" + text)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps({
        "machine": f"{platform.node()} {platform.processor() or platform.machine()}, {mp.cpu_count()} cores",
        "arch": a.arch, "repeats": a.repeats, "timeout_s": a.timeout, "rtol": RTOL,
        "fits": {key: fits(rows, key) for key in ("wall_s", "solve_s", "peak_rss_gib")},
        "medians": rows, "runs": runs,
    }, indent=1, default=float))
    print(f"figures: {out_json}")
    if a.png:
        plot(rows, a.png)
        print(f"plot: {a.png}")
    crashed = [r for r in runs if "failed" in r and not r.get("timed_out") and not r["failed"].startswith("skipped")]
    return 1 if crashed else 0


if __name__ == "__main__":
    raise SystemExit(main())
