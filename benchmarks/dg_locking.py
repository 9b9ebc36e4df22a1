"""DG near incompressibility (issue 21): the Lame thick sphere's error against Poisson's ratio.

    .venv/bin/python -m benchmarks.dg_locking [--degree 2] [--h 0.125] [--nu 0.3,0.49,0.499,0.4999]

The accuracy benchmark's ``lame`` geometry, probes and volume-equivalent radii
(``verification.problems``: icospheres of subdivision 6, a = 0.5, b = 1, 1,200 interior probes) with
E = 1 Pa and an internal pressure of 1 Pa, free body (the rigid modes left free and removed).
Prints one JSON line per nu: relative L2 error of u at the probes (against the closed form),
its ratio to the first nu's, the penalty used, and the seconds of discretisation + solve.
Runs in this process (Taichi on the CPU, f64).
"""

from __future__ import annotations

import argparse
import json
import time


def sphere_error(nu: float, degree: int, h: float) -> dict:
    """One free thick sphere: {"nu", "error_u", "eta", "eta_volumetric", "seconds"}."""
    import numpy as np

    from verification.problems import _shell, lame_problem, problem, relative_l2
    from engine.boundary import SurfaceLoad
    from engine.dg.elasticity import DGElasticity
    from engine.geometry.slicing import slice_cells
    from engine.geometry.surface import Surface
    from engine.grid import make_grid
    from engine.material import Material
    from engine.regions import Ball

    reference = problem("lame")
    mesh = _shell()
    surface = Surface(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    cut = slice_cells(surface, make_grid(*surface.bounds, cell_size=h, padding=1))
    lame = lame_problem(*reference.radii, 1.0, 1.0, nu, reference.probes)
    t = time.perf_counter()
    m = DGElasticity(cut=cut, surface=surface, material=Material(1.0, nu), degree=degree, flux="ip",
                     surface_loads=[SurfaceLoad(Ball(np.zeros(3), 0.75), "inner", pressure=1.0)])
    u = m.evaluate(m.solve().u, m.locate(lame.probes), lame.probes)
    return {"nu": nu, "error_u": relative_l2(u, lame.exact(lame.probes)), "eta": m.eta, "eta_volumetric": m.eta_volumetric,
            "seconds": time.perf_counter() - t}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--degree", type=int, default=2)
    ap.add_argument("--h", type=float, default=0.125, help="cell size [m]")
    ap.add_argument("--nu", default="0.3,0.49,0.499,0.4999", help="Poisson's ratios, comma-separated")
    a = ap.parse_args(argv)
    from engine.runtime import init

    init("cpu", "f64")
    first = None
    for nu in (float(v) for v in a.nu.split(",")):
        row = sphere_error(nu, a.degree, a.h)
        first = first or row["error_u"]
        row.update(degree=a.degree, h=a.h, ratio=row["error_u"] / first)
        print(json.dumps({k: (float(f"{v:.4g}") if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
