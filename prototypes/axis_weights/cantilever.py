"""The bundled cantilever's tip u_z at several resolutions: `cantilever.py on|off 16,24,32` (moments sliced)."""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import axisw
from engine import simulate
from engine.geometry.cache import GeometryCache

EX = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples")
spec = json.load(open(os.path.join(EX, "cantilever.json")))
mesh = os.path.join(EX, "cantilever.stl")
axisw.mode(sys.argv[1])
axisw.G["slice"] = axisw.G["shear"] = axisw.G["on"]
method = json.loads(os.environ.get("METHOD", '{"kind": "staggered", "solver": "direct"}'))
for res in [int(x) for x in sys.argv[2].split(",")]:
    spec["grid"]["resolution"] = res
    spec["method"] = method
    spec["output"] = {"fields": ["displacement"], "probes": [[1.0, 0, 0]], "surface": False}
    r = simulate(spec, mesh, cache=GeometryCache(None))
    print(res, r.fields.probes["displacement"][0][2], flush=True)
