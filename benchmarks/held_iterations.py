"""CG iterations of the staggered V-cycle on curved clamps: the thick sphere of verification/held.py held
on its whole outer surface ("all") or below z = 0.3 ("rim"), solved iteratively at each cell size.

    .venv/bin/python -m benchmarks.held_iterations [--nu 0.3] [--h 0.1 0.07 0.05 0.04 0.025] [--rtol 1e-10]

Prints per case and cell size: CG iterations, the final relative residual and the job's seconds. The
iteration counts should stay level under refinement; a count that jumps at one size is the smoothing
amplifying what its eigenvalue bound missed (docs/design-notes.md, "The point smoothing's bound").
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from verification.held import held_sphere


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nu", type=float, nargs="+", default=[0.3])
    parser.add_argument("--h", type=float, nargs="+", default=[0.1, 0.07, 0.05, 0.04, 0.025])
    parser.add_argument("--rtol", type=float, default=1e-10)
    args = parser.parse_args(argv)
    method = {"kind": "staggered", "solver": "iterative"}
    for nu in args.nu:
        for case, below in (("all", np.inf), ("rim", 0.3)):
            for h in args.h:
                t = time.perf_counter()
                r = held_sphere(nu, h, method, below=below, rtol=args.rtol)
                print(f"nu {nu} {case:3s} h {h:<6g} {r.solver.iterations:4d} iterations, residual "
                      f"{r.solver.residual:.1e}, {time.perf_counter() - t:5.1f} s", flush=True)


if __name__ == "__main__":
    main()
