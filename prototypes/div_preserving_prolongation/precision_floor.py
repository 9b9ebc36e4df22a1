"""The true relative residual single precision leaves on the held shell of ``benchmarks.staggered``
(rtol 1e-5), per nu: the message the solve fails with. One process per nu (Taichi keeps one
precision per process).

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/precision_floor.py RES NU...
"""

from __future__ import annotations

import multiprocessing as mp
import sys
import tempfile
from pathlib import Path


def _one(res: int, nu: float) -> None:
    from benchmarks.staggered import job, shell_mesh
    from engine import simulate
    from engine.geometry.cache import GeometryCache

    with tempfile.TemporaryDirectory() as tmp:
        mesh = Path(tmp) / "shell.stl"
        shell_mesh(mesh)
        try:
            r = simulate(job(str(mesh), res, nu, 1e-5, "cpu", "f32"), str(mesh), cache=GeometryCache(None))
            print(f"nu {nu}: {r.solver.iterations} iterations, true residual {r.solver.residual:.2e}", flush=True)
        except Exception as exc:  # the solver's message is what is measured
            print(f"nu {nu}: {exc}", flush=True)


if __name__ == "__main__":
    ctx = mp.get_context("spawn")
    for value in sys.argv[2:]:
        p = ctx.Process(target=_one, args=(int(sys.argv[1]), float(value)))
        p.start()
        p.join()
