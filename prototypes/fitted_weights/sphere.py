"""Thick sphere, relative L2 error at 500 probes: `sphere.py on|off 0.1,0.05 free|clamped|outer`."""
import sys, os, time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np, trimesh
from engine import simulate
from engine.pipeline import Functions
from engine.geometry.cache import GeometryCache
on = sys.argv[1] == "on"
if on:
    import fit; fit.install()
case = sys.argv[3] if len(sys.argv) > 3 else "clamped"
free = case in ("free", "outer")
hs = [float(x) for x in sys.argv[2].split(",")]
a, b, nu = 0.5, 1.0, 0.3
lam, mu = nu / ((1 + nu) * (1 - 2 * nu)), 1 / (2 * (1 + nu))
B = 1.0 / ((3 * lam + 2 * mu) + 4 * mu / a**3)
outer = trimesh.creation.icosphere(subdivisions=5, radius=b)
inner = trimesh.creation.icosphere(subdivisions=5, radius=a)
inner.invert()
mesh = trimesh.util.concatenate([outer, inner]).export(file_type="stl")
x = np.random.default_rng(3).uniform(-1, 1, (20000, 3))
r = np.linalg.norm(x, axis=1)
probes = x[(r > 0.55) & (r < 0.95)][:500]
rp = np.linalg.norm(probes, axis=1)
if case == "outer":
    A = -1.0 / ((3 * lam + 2 * mu) * (1 - a**3 / b**3)); B = (3 * lam + 2 * mu) * A * a**3 / (4 * mu)
elif free:
    B = 1.0 / (4 * mu * (1 / a**3 - 1 / b**3)); A = 4 * mu * B / ((3 * lam + 2 * mu) * b**3)
else:
    A = -B
exact = ((A * rp + B / rp**2) / rp)[:, None] * probes
for h in hs:
    t = time.time()
    spec = {"dimension": 3, "geometry": {"mesh": "s.stl"}, "grid": {"cell_size": h, "padding": 1},
            "material": {"youngs_modulus": 1.0, "poisson_ratio": nu}, "method": {"kind": "staggered", "solver": "direct" if h > 0.04 else "iterative"},
            "boundaries": ([{"kind": "pressure", "name": "outer", "value": 1.0, "region": {"all": True}}]
                           if case == "outer" else
                           [{"kind": "pressure", "name": "inner", "value": 1.0,
                            "region": {"sphere": {"center": [0, 0, 0], "radius": 0.75}}}]) + ([] if free else [{"kind": "displacement", "name": "clamp", "value": [0, 0, 0], "region": {"all": True}}]),
            "solver": {"rtol": 1e-10}, "output": {"fields": ["displacement"], "probes": probes.tolist(), "surface": False}}
    outer_region = lambda p: np.linalg.norm(p, axis=1) > 0.98  # noqa: E731
    fn = Functions(regions={"outer": outer_region} if case == "outer" else {} if free else {"clamp": outer_region})
    res = simulate(spec, mesh, filename="s.stl", functions=fn, cache=GeometryCache(None))
    u = res.fields.probes["displacement"]
    print(case, h, float(np.sqrt(np.sum((u - exact) ** 2) / np.sum(exact**2))), round(time.time() - t, 1), res.solver.iterations if hasattr(res.solver, "iterations") else "", flush=True)
