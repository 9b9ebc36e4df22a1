"""Where the staggered cantilever's tip moves with the grid: each end face of the stress suite's bar
swept through its cell on its own (issue 17's sub-cell offsets).

    .venv/bin/python -m benchmarks.clamp_sweep [--cells 8] [--method staggered] [--nu 0.3] [--sweeps ...]

The bar (1 m x W x W, W = 0.25 m, E = 1 MPa, Poisson's ratio --nu) on a pinned grid of h = W / cells, the face
moved by delta h for delta = 0, 0.1, ..., 0.9 with the other face on a grid plane:

- ``tip``: the loaded face moves (length 1 + delta h), ``clamp``: the held face (length 1 - delta h),
  ``both``: the bar moves whole (the suite's offsets along the axis alone), ``across`` / ``load``: the
  bar moves whole across the load (y) / along it (z, its partial layers bend); tip deflection over
  Timoshenko's for its length, under the suite's end traction;
- ``pull_clamped`` / ``pull_roller``: the held face moves, the far face pulled along the axis; tip
  u_x over T L / E, the face held in all components or in u_x alone (rollers on two symmetry planes
  keep the rest in place).

Prints each sweep's ratios and its spread (max - min) / mean.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

SWEEPS = ("tip", "clamp", "both", "across", "load", "pull_clamped", "pull_roller")


def sweep(kind: str, cells: int, method: dict, nu: float) -> list[float]:
    from verification.parts import (
        ALIGNED,
        E0,
        TIP_TRACTION,
        WIDTH,
        Bar,
        offset_grid,
        timoshenko_tip,
    )
    from verification.stress.running import cantilever_job, job, solve, tip_deflection

    h = WIDTH / cells
    grid = offset_grid((round(1 / h) + 1, cells, cells), h)
    out = []
    for delta in np.arange(10) / 10:
        length, start = {"tip": (1 + delta * h, 0.0), "both": (1.0, delta * h), "across": (1.0, 0.0),
                         "load": (1.0, 0.0)}.get(kind, (1 - delta * h, delta * h))
        side = delta * h * np.array([kind == "across", kind == "load"], dtype=float)
        bar = Bar(length, WIDTH, ALIGNED, np.array([start, WIDTH / 2 + side[0], WIDTH / 2 + side[1]]))
        if not kind.startswith("pull"):
            solved = solve(cantilever_job(method, h, bar, nu=nu), bar.mesh(), grid=grid, condition=False)
            beam = timoshenko_tip(TIP_TRACTION * WIDTH**2, length, WIDTH, E0, nu)
            out.append(tip_deflection(solved, bar) / beam)
            continue
        slack = 1e-3 * h
        held = [0, 0, 0] if kind == "pull_clamped" else [0, None, None]
        boundaries = [{"kind": "displacement", "name": "end", "region": bar.beyond(slack, -1), "value": held},
                      {"kind": "traction", "name": "pull", "region": bar.end(+1, slack), "value": [TIP_TRACTION, 0, 0]}]
        if kind == "pull_roller":  # the bar's lower sides y = 0, z = 0 on rollers: no rigid motion left
            for axis in (1, 2):
                normal = np.eye(3)[axis].tolist()
                value = [0 if k == axis else None for k in range(3)]
                boundaries.append({"kind": "displacement", "name": f"roller{axis}", "value": value,
                                   "region": {"halfspace": {"point": [0.0, 0.0, 0.0], "normal": normal}}})
        spec = job(method, h, boundaries, probes=[bar.point(length - slack)], nu=nu)
        solved = solve(spec, bar.mesh(), grid=grid, condition=False)
        out.append(float(solved.probe()[0][0]) / (TIP_TRACTION * length / E0))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cells", type=int, default=8, help="cells across the bar's width")
    ap.add_argument("--method", default="staggered", choices=("staggered", "dg"))
    ap.add_argument("--nu", type=float, default=0.3)
    ap.add_argument("--sweeps", nargs="*", default=list(SWEEPS), choices=SWEEPS)
    args = ap.parse_args(argv)
    method = {"kind": "staggered"} if args.method == "staggered" else {"kind": "dg", "degree": 2}
    for kind in args.sweeps:
        ratios = np.asarray(sweep(kind, args.cells, method, args.nu))
        spread = float((ratios.max() - ratios.min()) / ratios.mean())
        print(json.dumps({"sweep": kind, "ratios": [round(float(r), 5) for r in ratios],
                          "spread_percent": round(100 * spread, 2)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
