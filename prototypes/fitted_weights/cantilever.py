"""The bundled cantilever's tip u_z at several resolutions: `cantilever.py on|off 16,24,32`."""
import sys, json, os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import trimesh
import fit
from engine import simulate
from engine.geometry.cache import GeometryCache

EX = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples")
spec = json.load(open(os.path.join(EX, "cantilever.json")))
mesh = os.path.join(EX, "cantilever.stl")
if sys.argv[1] == "on":
    fit.install()
    fit.MODE["centroids"] = fit.box_centroids(*trimesh.load(mesh).bounds)
for res in [int(x) for x in sys.argv[2].split(",")]:
    spec["grid"]["resolution"] = res
    spec["method"] = {"kind": "staggered", "solver": "direct"}
    spec["output"] = {"fields": ["displacement"], "probes": [[1.0, 0, 0]], "surface": False}
    r = simulate(spec, mesh, cache=GeometryCache(None))
    print(res, r.fields.probes["displacement"][0][2], flush=True)
