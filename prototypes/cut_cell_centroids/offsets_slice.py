import sys, json, os
sys.path.insert(0, __import__("os").path.dirname(__file__))
import numpy as np
import cutstrain
from verification.parts import WIDTH, E0, NU0, TIP_TRACTION, offset_bar, offset_grid, timoshenko_tip, LENGTH
from verification.stress.running import cantilever_job, solve, tip_deflection

cells = int(sys.argv[1]) if len(sys.argv) > 1 else 8
on = sys.argv[2] == "on" if len(sys.argv) > 2 else True
offs = tuple(float(v) for v in os.environ.get("OFFS", "0,1e-6,1e-4,1e-2,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,0.99,0.9999,0.999999").split(","))
h = WIDTH / cells
grid = offset_grid((round(LENGTH / h), cells, cells), h)
cutstrain.G["on"] = on; import os; cutstrain.G["muonly"] = os.environ.get("MUONLY") == "1"; cutstrain.G["flux"] = os.environ.get("FLUX") == "1"; cutstrain.G["order2"] = os.environ.get("ORDER2") == "1"; cutstrain.G["slice"] = on
import os; cutstrain.G["beta"] = float(os.environ.get("BETA", "0.05")); cutstrain.G["shear"] = os.environ.get("SHEAR") == "1"; cutstrain.G["along"] = os.environ.get("ALONG", "1") == "1"; cutstrain.G["second"] = os.environ.get("SECOND") == "1"; cutstrain.G["extend"] = os.environ.get("EXTEND") == "1"; cutstrain.G["wetonly"] = os.environ.get("WET") == "1"; cutstrain.G["skipheld"] = os.environ.get("SKIPHELD") == "1"; cutstrain.G["jhold"] = os.environ.get("JHOLD") == "1"
cutstrain.G["origin"] = np.asarray(grid.origin, float)
tips = []
for off in offs:
    bar = offset_bar(off, h)
    lo, hi = bar.mesh().bounds
    s = solve(cantilever_job({"kind": "staggered", "solver": "direct"}, h, bar), bar.mesh(), grid=grid, condition=False)
    it = s.stats[-1].iterations if hasattr(s.stats[-1], "iterations") else None
    tips.append(tip_deflection(s, bar))
    print(off, tips[-1], it, flush=True)
t = np.array(tips)
print(json.dumps({"on": on, "spread%": 100 * (t.max() - t.min()) / t.mean(), "mean": t.mean(),
                  "beam": timoshenko_tip(TIP_TRACTION * WIDTH**2, LENGTH, WIDTH, E0, NU0)}))
