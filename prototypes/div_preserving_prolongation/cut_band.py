"""The engine's V-cycle with the band's vertex patches (``patches.py``) around every cut cell as well
as around the surface terms' DOFs: is the held shell's slow mode a smoothing failure near the cut
surface?

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/cut_band.py RES NU
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi

from engine.staggered import patches

sys.path.insert(0, str(Path(__file__).parent))
from harness import held_shell, mg, pcg_spectrum  # noqa: E402


def wide_patches(level) -> np.ndarray | None:
    """``patches.vertex_patches`` with the cut cells' positions among the seeds."""
    sf, lay, d, size = level.surface, level.layout, level.dim, level.size
    near = np.zeros(size, dtype=np.uint8)
    if sf is not None:
        near[sf.pos] = 1
    vc = level.vc_host
    near[: len(vc)][(vc > 0) & (vc < 1)] = 1
    dense = lay.dense(near)
    for a in range(d):
        dense = ndi.maximum_filter1d(dense, 4, axis=a, mode="constant")
    vertices = np.argwhere(dense > 0)
    columns = []
    for a in range(d):
        for o in itertools.product(*[(0,) if k == a else (-1, 0) for k in range(d)]):
            at = lay.positions(vertices + np.asarray(o))
            ok = at >= 0
            ok[ok] = level.free[a, at[ok]]
            columns.append(np.where(ok, a * size + at, -1))
    keys = np.stack(columns, axis=1)
    keys = keys[(keys >= 0).sum(axis=1) >= 2]
    print(f"  {level.layout.box}: {len(keys)} patches", flush=True)
    return keys if len(keys) else None


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
