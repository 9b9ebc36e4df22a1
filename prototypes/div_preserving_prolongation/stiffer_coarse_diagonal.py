"""Two levels of the engine's hierarchy, the coarse level solved exactly after stiffening it: plus
a times its shear part's diagonal (``diag:a``) or plus a times its shear part (``mu:a``). The
rediscretised coarse level is up to 10x too soft for some prolonged fields (design notes, "Held
bands"); a stiffer diagonal raises oscillatory coarse modes more than smooth ones (twenty-third session).

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/stiffer_coarse_diagonal.py RES NU diag:A mu:A...
"""
import sys
from pathlib import Path

import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).parent))
from harness import TwoLevel, held_shell, pcg_spectrum  # noqa: E402

from engine.staggered.patches import operator_block  # noqa: E402


def main(argv: list[str]) -> None:
    res, nu = int(argv[0]), float(argv[1])
    problem = held_shell(res, nu)
    two = TwoLevel(problem)
    P, keys = two.own()
    Ac = two.rediscretised(P, keys)
    c = two.coarse
    lam = c.lam
    c.lam = 0.0
    surface, c.surface = c.surface, None
    Amu = operator_block(c, keys).tocsr()
    c.lam, c.surface = lam, surface
    Dmu = sp.diags(Amu.diagonal())
    for spec in argv[2:]:
        kind, a = spec.split(":")
        a = float(a)
        A2 = (Ac + a * (Dmu if kind == "diag" else Amu)).tocsr()
        its, ev = pcg_spectrum(problem, two.cycle(P, A2))
        print(f"{spec}: {its} iterations, Ritz {ev[0]:.3f} ... {ev[-1]:.3f}, condition {ev[-1]/ev[0]:.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
