import sys, json
sys.path.insert(0, __import__("os").path.dirname(__file__))
import numpy as np
import cutstrain
from verification.parts import WIDTH, E0, NU0, TIP_TRACTION, offset_bar, offset_grid, timoshenko_tip, LENGTH
from verification.stress.running import cantilever_job, solve, tip_deflection

cells = int(sys.argv[1]) if len(sys.argv) > 1 else 8
on = sys.argv[2] == "on" if len(sys.argv) > 2 else True
offs = (0.0, 1e-6, 1e-4, 1e-2, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99, 1 - 1e-4, 1 - 1e-6)
h = WIDTH / cells
grid = offset_grid((round(LENGTH / h), cells, cells), h)
import os
cutstrain.G["on"] = on
cutstrain.G["slice"] = on and os.environ.get("MOMENTS") == "slice"
cutstrain.configure_from_env()
cutstrain.G["origin"] = np.asarray(grid.origin, float)
tips = []
for off in offs:
    bar = offset_bar(off, h)
    lo, hi = bar.mesh().bounds
    if os.environ.get("MOMENTS") != "slice":  # the bar's analytic cell moments (cells only: no SHEAR)
        cutstrain.G["moments"] = cutstrain.box_moments(lo, hi)
    s = solve(cantilever_job({"kind": "staggered", "solver": "direct"}, h, bar), bar.mesh(), grid=grid, condition=False)
    it = s.stats[-1].iterations if hasattr(s.stats[-1], "iterations") else None
    tips.append(tip_deflection(s, bar))
    print(off, tips[-1], it, flush=True)
t = np.array(tips)
print(json.dumps({"on": on, "spread%": 100 * (t.max() - t.min()) / t.mean(), "mean": t.mean(),
                  "beam": timoshenko_tip(TIP_TRACTION * WIDTH**2, LENGTH, WIDTH, E0, NU0)}))
