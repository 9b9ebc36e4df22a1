"""Every level of the engine's V-cycle with the linear-across divergence-preserving prolongation
(prolongation.py) instead of kernels.FACE: transfers applied on the host (scipy), coarse levels the
engine's rediscretised bulk with their surface terms P^T S P of this prolongation, smoothing the
engine's own (curl Chebyshev with the band's patches, on the device).

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/all_levels.py RES NU [SLOPES...]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from engine.runtime import device_array
from engine.staggered import galerkin

sys.path.insert(0, str(Path(__file__).parent))
from harness import held_shell, mg, pcg_spectrum  # noqa: E402
from prolongation import tr_prolongation  # noqa: E402


def say(name: str, its: int, ev: np.ndarray, seconds: float) -> None:
    print(f"{name}: {its} iterations, Ritz values of B A {ev[0]:.3f} ... {ev[-1]:.3f}, "
          f"condition {ev[-1] / ev[0]:.2f} ({seconds:.1f} s)", flush=True)


class HostTransfers(mg.Multigrid):
    """The engine's Multigrid with host-side transfers P_k built by ``tr_prolongation``."""

    slopes = "interior"

    def __init__(self, fine, slopes: str) -> None:
        self.slopes = slopes
        own = galerkin.prolongation_matrix
        galerkin.prolongation_matrix = lambda f, c, comp, pos, kind: tr_prolongation(f, c, comp, pos, slopes)
        try:
            super().__init__(fine)
        finally:
            galerkin.prolongation_matrix = own
        self.P = []
        for up, lv in zip(self.levels, self.levels[1:]):
            comp, pos = np.nonzero(up.free)
            P, keys = tr_prolongation(up, lv, comp, pos, slopes)
            self.P.append((comp, pos, P.tocsr(), P.T.tocsr(), keys // lv.size, keys % lv.size))

    def _cycle(self, k: int, b, x) -> None:
        lv = self.levels[k]
        if k == len(self.levels) - 1:
            self.coarse.solve(b, x)
            return
        r = self.work[k][0]
        down = self.levels[k + 1]
        comp, pos, P, Pt, ccomp, cpos = self.P[k]
        self._smooth(k, b, x, first=True)
        lv.residual(x, b, r)
        bc, xc = self.work[k + 1][1:3]
        v = np.zeros((down.dim, down.size))
        v[ccomp, cpos] = Pt @ r.to_numpy()[comp, pos]
        v *= down.free
        bc.from_numpy(v.astype(down.dtype))
        self._cycle(k + 1, bc, xc)
        xv = x.to_numpy()
        xv[comp, pos] += P @ xc.to_numpy()[ccomp, cpos]
        x.from_numpy(xv.astype(lv.dtype))
        self._smooth(k, b, x, first=False)


def main(res: int, nu: float, variants: list[str]) -> None:
    problem = held_shell(res, nu)
    t = time.perf_counter()
    say("engine, every level", *pcg_spectrum(problem, problem.multigrid.precondition), time.perf_counter() - t)
    print("levels:", [lv.layout.box for lv in problem.multigrid.levels], flush=True)
    for slopes in variants or ["interior"]:
        m = HostTransfers(problem.level, slopes)
        t = time.perf_counter()
        say(f"linear-across P ({slopes}), every level", *pcg_spectrum(problem, m.precondition), time.perf_counter() - t)


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), sys.argv[3:])
