"""Where a staggered job's error at the probes comes from: its rigid part and the rest, by radius.

    .venv/bin/python -m benchmarks.error_split --problem ball --n 32 64 [--form divergence|quadrature]
                                              [--traction-everywhere] [--hold-everywhere]

One job per n (h = 1/n) of ``verification.problems`` (the accuracy benchmark's problems and probes).
The error e = u_h - u at the probes is split into its least-squares rigid motion t + w x x and the
rest; each is reported relative to |u| over the probes, beside the RMS error in shells of radius.
A rigid part that does not fall with h is a global imbalance between loads and holds (a body
moved as a whole), not a discretization error that refinement removes. Variants (the ball only):
``--form`` how the traction on the free part becomes loads; ``--traction-everywhere`` the exact
traction on the whole surface, the cap held as well; ``--hold-everywhere`` the exact field held on
the whole surface, no traction.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
from pathlib import Path

import numpy as np


def rigid_split(points: np.ndarray, error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the rigid motion's coefficients [t (3), w (3)], the rest of ``error`` [P, 3]) by least squares."""
    a = np.zeros((3 * len(points), 6))
    for i in range(3):
        a[i::3, i] = 1.0
        basis = np.cross(np.eye(3)[i], points)  # e_i x x: the velocity of a unit rotation about axis i
        a[0::3, 3 + i], a[1::3, 3 + i], a[2::3, 3 + i] = basis.T
    coef, *_ = np.linalg.lstsq(a, error.ravel(), rcond=None)
    return coef, (error.ravel() - a @ coef).reshape(-1, 3)


def one(problem_name: str, n: int, form: str, traction_everywhere: bool, hold_everywhere: bool) -> dict:
    from engine import simulate
    from engine.geometry.cache import GeometryCache
    from verification.problems import problem, relative_l2

    p = problem(problem_name)
    spec, mesh, functions = p.job({"kind": "staggered"}, 1.0 / n)
    functions = dataclasses.replace(functions, stress_form=form)
    if traction_everywhere:
        spec["boundaries"][1]["region"] = {"all": True}
    if hold_everywhere:
        spec["boundaries"] = [{"kind": "displacement", "name": "cap", "value": [0, 0, 0], "region": {"all": True}}]
        functions = dataclasses.replace(functions, stress={})
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "solid.ply"
        spec["geometry"]["mesh"] = path.name
        mesh.export(path)
        result = simulate(spec, path, cache=GeometryCache(None), functions=functions)
    u, exact = result.fields.probes["displacement"], p.exact(p.probes)
    coef, rest = rigid_split(p.probes, u - exact)
    scale = float(np.sqrt((exact**2).sum()))
    row = {"problem": problem_name, "n": n, "error": relative_l2(u, exact),
           "rigid": float(np.linalg.norm((u - exact).ravel() - rest.ravel()) / scale),
           "rest": float(np.linalg.norm(rest) / scale), "translation": coef[:3].tolist(), "rotation": coef[3:].tolist()}
    radius, err = np.linalg.norm(p.probes, axis=1), np.linalg.norm(u - exact, axis=1)
    norm = np.sqrt((np.linalg.norm(exact, axis=1) ** 2).mean())
    for lo, hi in ((0.0, 0.5), (0.5, 0.8), (0.8, 0.9), (0.9, 0.98)):
        shell = (radius >= lo) & (radius < hi)
        if shell.any():
            row[f"r {lo}-{hi}"] = float(np.sqrt((err[shell] ** 2).mean()) / norm)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problem", default="ball")
    ap.add_argument("--n", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--form", default="divergence", choices=["divergence", "quadrature"])
    ap.add_argument("--traction-everywhere", action="store_true")
    ap.add_argument("--hold-everywhere", action="store_true")
    a = ap.parse_args(argv)
    if (a.traction_everywhere or a.hold_everywhere) and a.problem != "ball":
        ap.error("--traction-everywhere and --hold-everywhere change the ball's cap and rest boundaries only")
    for n in a.n:
        print(json.dumps(one(a.problem, n, a.form, a.traction_everywhere, a.hold_everywhere)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
