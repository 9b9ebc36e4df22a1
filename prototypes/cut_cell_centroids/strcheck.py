import sys, os
sys.path.insert(0, __import__("os").path.dirname(__file__))
import numpy as np, trimesh
import cutstrain
from engine import simulate
from engine.staggered import elasticity as el, assembly
h = float(sys.argv[1])
cutstrain.G["on"] = True; cutstrain.G["slice"] = True; cutstrain.configure_from_env()
outer = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
inner = trimesh.creation.icosphere(subdivisions=5, radius=0.5); inner.invert()
mesh = trimesh.util.concatenate([outer, inner]).export(file_type="stl")
rng = np.random.default_rng(0)
Q = rng.normal(size=(3, 3, 3)); Q = (Q + Q.transpose(0, 2, 1)) / 2  # u_a = x^T Q_a x / 2
def u_q(x, a): return 0.5 * np.einsum("ni,ij,nj->n", x, Q[a], x)
def grad(x, a): return x @ Q[a]  # [n, 3]
orig = el.StaggeredElasticity.solve
def solve(self, *args, **kw):
    lv = self.level
    cutstrain.build_proto(lv)
    grid = self.grid
    pts = assembly.dof_positions(grid)
    P = len(pts) // 3
    comp = np.repeat(np.arange(3), P)
    u = np.zeros(len(pts))
    for a in range(3):
        u[comp == a] = u_q(pts[comp == a], a)
    eps = (cutstrain.G["R"] @ u).reshape(3, -1)
    I, cen, n = cutstrain.G["I"], cutstrain.G["cen"], cutstrain.G["n"]
    xb = np.asarray(grid.origin) + grid.spacing * (I + 0.5 + cen[tuple(I.T)])
    exact = np.stack([grad(xb, a)[:, a] for a in range(3)])
    err = np.abs(eps - exact)
    scale = np.abs(Q).max() * 1.0
    print("max err", err.max() / scale, "p99", np.percentile(err, 99) / scale, "n", n)
    bad = np.argsort(-err.max(0))[:5]
    for b in bad:
        print("  cell", I[b], "cen", np.round(cen[tuple(I[b])], 3), "err", np.round(err[:, b] / scale, 4))
    sys.exit(0)
el.StaggeredElasticity.solve = solve
spec = {"dimension": 3, "geometry": {"mesh": "s.stl"}, "grid": {"cell_size": h, "padding": 1},
        "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3}, "method": {"kind": "staggered", "solver": "direct"},
        "boundaries": [{"kind": "pressure", "name": "inner", "value": 1.0, "region": {"sphere": {"center": [0, 0, 0], "radius": 0.75}}}],
        "output": {"fields": ["displacement"], "probes": [[0.7, 0, 0]], "surface": False}}
simulate(spec, mesh, filename="s.stl")
