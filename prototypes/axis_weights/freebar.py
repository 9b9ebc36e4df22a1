"""The free bar of tests/test_staggered_solver.py (examples/cantilever.json at resolution 24, equal and
opposite end tractions of 1000 Pa): max |sigma_xx - 1000| / 1000 in the full cells. `freebar.py on|off`."""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np

import axisw
from engine.pipeline import run
from engine.geometry.cache import GeometryCache

EX = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples")
axisw.mode(sys.argv[1])
axisw.G["slice"] = axisw.G["shear"] = axisw.G["on"]
spec = json.load(open(os.path.join(EX, "cantilever.json")))
spec.update(grid={"resolution": 24}, loads={"gravity": [0, 0, 0]}, method={"kind": "staggered", "solver": "direct"},
            output={"fields": ["displacement", "stress"], "probes": [[0.5, 0, 0]], "surface": False},
            boundaries=[{"kind": "traction", "name": "r", "region": {"box": [[1.0, -1, -1], [2, 1, 1]]}, "value": [1000, 0, 0]},
                        {"kind": "traction", "name": "l", "region": {"box": [[-1, -1, -1], [0.0, 1, 1]]}, "value": [-1000, 0, 0]}])
result = run(spec, os.path.join(EX, "cantilever.stl"), cache=GeometryCache(None))
sxx = result.fields.cells["stress"][..., 0]
print("max |sigma_xx - 1000| / 1000 in full cells:", float(np.abs(sxx[result.volume_fraction == 1] - 1000).max() / 1000))
