"""The held shell's job with the curl smoothing's Chebyshev polynomials of the first kind (the
engine's, on [upper / CURL_SPREAD, upper]) or of the fourth kind on [0, upper] (Phillips & Fischer
2022; Lottes 2023), at a given degree.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/fourth_kind.py RES NU first|fourth [DEGREE]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from benchmarks.staggered import job, shell_mesh
from engine import simulate
from engine.geometry.cache import GeometryCache
from engine.staggered import multigrid as mg


def fourth(upper: float, spread: float, degree: int) -> list[tuple[float, float]]:
    """(c1, c2) per step as ``multigrid.chebyshev_coefficients`` gives them, for the fourth kind."""
    return [(0.0, 4.0 / (3.0 * upper))] + [((2 * k - 1) / (2 * k + 3), (8 * k + 4) / ((2 * k + 3) * upper))
                                           for k in range(1, degree)]


def main(res: int, nu: float, kind: str, degree: int) -> None:
    mg.CURL_DEGREE = degree
    if kind == "fourth":
        mg.chebyshev_coefficients = fourth
    with tempfile.TemporaryDirectory() as tmp:
        mesh = Path(tmp) / "shell.stl"
        shell_mesh(mesh)
        t = time.perf_counter()
        r = simulate(job(str(mesh), res, nu, 1e-6, "cpu"), str(mesh), cache=GeometryCache(None))
    print(f"{kind} kind, degree {degree}, {res}^3, nu {nu}: {r.solver.iterations} iterations, "
          f"{time.perf_counter() - t:.1f} s, solve {r.solver.stage_times['solve']:.1f} s", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), sys.argv[3], int(sys.argv[4]) if len(sys.argv) > 4 else mg.CURL_DEGREE)
