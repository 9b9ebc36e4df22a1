import sys
sys.path.insert(0, __import__("os").path.dirname(__file__))
import numpy as np, trimesh
import cutstrain
from engine import simulate
from engine.pipeline import Functions
on = sys.argv[1] == "on"
h = float(sys.argv[2]) if len(sys.argv) > 2 else 0.1
cutstrain.G["on"] = on; import os; cutstrain.G["muonly"] = os.environ.get("MUONLY") == "1"; cutstrain.G["order2"] = os.environ.get("ORDER2") == "1"; import os; cutstrain.G["shear"] = os.environ.get("SHEAR") == "1"; cutstrain.G["slice"] = on
cutstrain.configure_from_env()
nu = 0.3; lam, mu = nu / ((1 + nu) * (1 - 2 * nu)), 1 / (2 * (1 + nu)); K = lam + 2 * mu / 3
mesh = trimesh.creation.icosphere(subdivisions=4, radius=1.0); mesh.apply_translation([0.013, -0.021, 0.007])
x = np.random.default_rng(3).uniform(-1, 1, (5000, 3)); x = x[np.linalg.norm(x - mesh.centroid, axis=1) < 0.9][:300]
spec = {"dimension": 3, "geometry": {"mesh": "s.stl"}, "grid": {"cell_size": h, "padding": 1},
        "material": {"youngs_modulus": 1.0, "poisson_ratio": nu}, "method": {"kind": "staggered", "solver": "direct"},
        "boundaries": [{"kind": "pressure", "name": "all", "value": 1.0, "region": {"all": True}}],
        "solver": {"rtol": 1e-12}, "output": {"fields": ["displacement"], "probes": x.tolist(), "surface": False}}
u = simulate(spec, mesh.export(file_type="stl"), filename="s.stl").fields.probes["displacement"]
exact = -(1.0 / (3 * K)) * (x - x.mean(0))
du = u - exact; du -= du.mean(0)
# remove rigid rotation fit
A = np.zeros((len(x) * 3, 3)); xc = x - x.mean(0)
for i in range(3):
    e = np.zeros(3); e[i] = 1; A[:, i] = np.cross(e, xc).ravel()
c = np.linalg.lstsq(A, du.ravel(), rcond=None)[0]; du = du - (A @ c).reshape(-1, 3)
print(on, h, np.abs(du).max() / np.abs(exact).max())
