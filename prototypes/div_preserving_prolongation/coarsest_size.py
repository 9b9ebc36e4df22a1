"""A larger coarsest level on the curl path: CG iterations, wall time and the multigrid's levels of held
and free bodies with the hierarchy stopped at the first level of at most LIMIT unknowns (factorised).

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/coarsest_size.py LIMIT CASE RES NU

LIMIT replaces ``multigrid.COARSEST_DOFS`` (1,000): a fine level within it is factorised whole (one
level, as "auto" does on small grids). CASE: shell (``benchmarks.staggered``'s held shell, rtol 1e-6),
or one of ``held_bodies.py``'s (rtol 1e-8): cantilever, dynamic (3 backward-Euler steps), torus, bar;
or ball (a free icosphere of radius 1 under two pressures). Run each in its own process; with
``/usr/bin/time -f "%M KB"`` for the peak.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import trimesh

sys.path.insert(0, str(Path(__file__).parent))

import held_bodies as hb  # noqa: E402
from benchmarks.staggered import job, shell_mesh  # noqa: E402
from engine import simulate  # noqa: E402
from engine.geometry.cache import GeometryCache  # noqa: E402
from engine.staggered import multigrid  # noqa: E402


def spec(case: str, res: int, tmp: Path) -> tuple[dict, str]:
    """(the job spec, its mesh path) of ``case`` at resolution ``res``."""
    if case == "shell":
        shell_mesh(tmp / "shell.stl")
        return job(str(tmp / "shell.stl"), res, 0.3, 1e-6, "cpu"), str(tmp / "shell.stl")
    if case in ("cantilever", "dynamic", "torus", "bar"):
        return hb.body(case, res, tmp)
    if case == "ball":
        trimesh.creation.icosphere(4, radius=1.0).export(tmp / "ball.stl")
        below = {"kind": "pressure", "name": "below", "region": {"box": [[-2, -2, -2], [2, 2, 0]]}, "value": 1e4}
        above = {"kind": "pressure", "name": "above", "region": {"box": [[-2, -2, 0], [2, 2, 2]]}, "value": 1e4}
        s = hb.spec(str(tmp / "ball.stl"), res, [below, above])
        s["loads"] = {}
        return s, str(tmp / "ball.stl")
    raise SystemExit(f"unknown case {case!r}")


def main(limit: int, case: str, res: int, nu: float) -> None:
    multigrid.COARSEST_DOFS = limit
    info = {}
    init = multigrid.Multigrid.__init__

    def timed(self, *args, **kwargs):
        t = time.perf_counter()
        init(self, *args, **kwargs)
        info["setup"] = info.get("setup", 0.0) + time.perf_counter() - t
        info["levels"] = [int(lv.active.sum()) for lv in self.levels]

    multigrid.Multigrid.__init__ = timed
    with tempfile.TemporaryDirectory() as tmp:
        s, mesh = spec(case, res, Path(tmp))
        s["material"]["poisson_ratio"] = nu
        t = time.perf_counter()
        r = simulate(s, mesh, cache=GeometryCache(None))
        wall = time.perf_counter() - t
    print(f"limit {limit}, {case} {res}, nu {nu}: {r.solver.iterations} iterations, {wall:.2f} s, multigrid setup "
          f"{info['setup']:.2f} s, unknowns per level {info['levels']}", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
