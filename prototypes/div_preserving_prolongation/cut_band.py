"""The engine's V-cycle with the band's vertex patches (``patches.py``) around every cut cell as well
as around the surface terms' DOFs: is the held shell's slow mode a smoothing failure near the cut
surface?

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/cut_band.py RES NU
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from engine.staggered import patches

sys.path.insert(0, str(Path(__file__).parent))
from harness import held_shell, mg, pcg_spectrum  # noqa: E402


def wide_patches(level) -> np.ndarray | None:
    """``patches.vertex_patches`` with the cut cells' positions among the seeds."""
    vc = level.vc_host
    seeds = np.nonzero((vc > 0) & (vc < 1))[0]
    if level.surface is not None:
        seeds = np.concatenate([seeds, level.surface.pos])
    keys = patches.patches_near(level, seeds)
    print(f"  {level.layout.box}: {0 if keys is None else len(keys)} patches", flush=True)
    return keys


def main(res: int, nu: float) -> None:
    problem = held_shell(res, nu)
    print(f"engine: {pcg_spectrum(problem, problem.multigrid.precondition)[0]} iterations", flush=True)
    patches.vertex_patches = wide_patches
    for levels in (12, 2):
        its, ev = pcg_spectrum(problem, mg.Multigrid(problem.level, max_levels=levels).precondition)
        print(f"patches around cut cells too, {'every level' if levels > 2 else 'two levels'}: {its} iterations, "
              f"Ritz values {ev[0]:.3f} ... {ev[-1]:.3f}", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]))
