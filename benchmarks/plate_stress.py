"""The holed plates (issue 19) on both methods against the stored P2 reference.

    .venv/bin/python -m benchmarks.plate_stress                                  # both cases, both methods
    .venv/bin/python -m benchmarks.plate_stress --case bending --method dg --h 0.05,0.04,0.025
    .venv/bin/python -m benchmarks.plate_stress --surface --json rows.json --plot plates.png
    .venv/bin/python -m benchmarks.plate_stress --rows rows.json --plot plates.png   # redraw, no runs

Each run goes through ``voxelastic run`` (engine.cli.main, in this process: Taichi CPU, f64) on
the job spec of verification.plates; the row is sigma_xx / LOAD at the case's probe, the P2
reference (verification/plate_reference.json, from benchmarks.plate_peer), the relative error and
the wall time of the run (geometry, solve, fields and writing the result). With ``--surface`` the
result keeps its surface, and the row adds the method's surface stress at the input mesh's vertex
nearest the point (the bending point is a vertex; the tension point, mid-thickness, is not).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from verification.plates import LOAD, PLATES, run_plate

DEFAULT_H = {"staggered": (0.05, 0.04, 0.025, 0.02, 0.0125, 0.01, 0.008, 0.00625),
             "dg": (0.1, 0.05, 0.04, 1 / 30, 0.025)}  # DG h = 0.025: ~12 GB (the direct factorisation)
METHODS = {"staggered": {"kind": "staggered"}, "dg": {"kind": "dg", "degree": 2}}


def row(case: str, method: str, h: float, surface: bool = False) -> dict:
    """One run: sigma_xx / LOAD at the probe against the reference, with the seconds it took."""
    plate = PLATES[case]
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        value, result = run_plate(plate, METHODS[method], h, Path(tmp), surface=surface)
        seconds = time.perf_counter() - start
    reference = plate.reference()
    out = {"case": case, "method": method, "h": h, "value": round(value, 5), "reference": round(reference, 5),
           "error": round(value / reference - 1, 5), "seconds": round(seconds, 1)}
    if surface and "stress" in result.fields.surface:
        v = result.surface_vertices
        i = int(np.argmin(np.linalg.norm(v - np.asarray(plate.point), axis=1)))
        out["surface_value"] = round(float(result.fields.surface["stress"][i, 0]) / LOAD, 5)
        out["surface_vertex_distance"] = float(np.linalg.norm(v[i] - np.asarray(plate.point)))
    return out


def plot(rows: list[dict], path: Path) -> None:
    """|error| against h per case and method, log-log (matplotlib, the benchmarks extra)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharey=True)
    for ax, case in zip(axes, PLATES):
        for method, marker in (("staggered", "o"), ("dg", "s")):
            got = sorted((r["h"], abs(r["error"])) for r in rows if r["case"] == case and r["method"] == method)
            if got:
                ax.loglog(*zip(*got), marker=marker, label=f"{method}" + (" k = 2" if method == "dg" else ""))
        ticks = sorted({r["h"] for r in rows if r["case"] == case})
        ax.set_xticks(ticks, [f"{h:.3g}" for h in ticks], minor=False)
        ax.set_xticks([], minor=True)
        ax.tick_params(axis="x", labelrotation=45)
        ax.set_title(f"{case}: sigma_xx at {PLATES[case].point}")
        ax.set_xlabel("h [m]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    axes[0].set_ylabel("|sigma_xx / P2 reference - 1|")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.plate_stress", description=__doc__.splitlines()[0])
    ap.add_argument("--case", action="append", choices=list(PLATES), help="only these cases (repeatable)")
    ap.add_argument("--method", action="append", choices=list(METHODS), help="only these methods (repeatable)")
    ap.add_argument("--h", help="cell sizes [m], comma-separated, instead of each method's default")
    ap.add_argument("--surface", action="store_true", help="also read the surface stress at the nearest vertex")
    ap.add_argument("--json", type=Path, help="write the rows to this file")
    ap.add_argument("--plot", type=Path, help="draw the errors against h to this picture (PNG)")
    ap.add_argument("--rows", type=Path, action="append",
                    help="no runs: read rows from these --json files, their errors against the stored reference")
    a = ap.parse_args(argv)
    rows = []
    for path in a.rows or []:
        for r in json.loads(path.read_text()):
            reference = PLATES[r["case"]].reference()
            rows.append({**r, "reference": round(reference, 5), "error": round(r["value"] / reference - 1, 5)})
            print(json.dumps(rows[-1]), flush=True)
    for case in [] if a.rows else a.case or list(PLATES):
        for method in a.method or list(METHODS):
            sizes = [float(v) for v in a.h.split(",")] if a.h else DEFAULT_H[method]
            for h in sizes:
                rows.append(row(case, method, h, a.surface))
                print(json.dumps(rows[-1]), flush=True)
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")
    if a.plot:
        plot(rows, a.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
