"""The cantilever moved by sub-cell offsets at W/cells: `offsets.py 8 on|off [offsets]`."""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np

import axisw
from verification.parts import LENGTH, NU0, E0, TIP_TRACTION, WIDTH, offset_bar, offset_grid, timoshenko_tip
from verification.stress.running import cantilever_job, solve, tip_deflection

cells = int(sys.argv[1])
on = sys.argv[2] == "on"
offs = (0.0, 1e-6, 1e-4, 1e-2, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99, 1 - 1e-4, 1 - 1e-6)
if len(sys.argv) > 3:
    offs = tuple(float(x) for x in sys.argv[3].split(","))
h = WIDTH / cells
grid = offset_grid((round(LENGTH / h), cells, cells), h)
axisw.mode(sys.argv[2])
axisw.G["origin"] = np.asarray(grid.origin, float)
tips = []
for off in offs:
    bar = offset_bar(off, h)
    lo, hi = bar.mesh().bounds
    axisw.G["moments"] = axisw.cutstrain.box_moments(lo, hi)
    axisw.G["edge_moments"] = axisw.box_edge_moments(lo, hi, grid)
    s = solve(cantilever_job({"kind": "staggered", "solver": "direct"}, h, bar), bar.mesh(), grid=grid, condition=False)
    tips.append(tip_deflection(s, bar))
    print(off, tips[-1], flush=True)
t = np.array(tips)
print(json.dumps({"on": on, "spread%": 100 * (t.max() - t.min()) / t.mean(), "mean": t.mean(),
                  "beam": timoshenko_tip(TIP_TRACTION * WIDTH**2, LENGTH, WIDTH, E0, NU0)}))
