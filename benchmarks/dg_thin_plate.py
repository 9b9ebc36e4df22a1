"""DG on a cantilever plate thinner than a cell: tip under gravity over Euler-Bernoulli beam theory,
degree 1 and 2, thickness 0.1 ... 2 cells (h = 0.125 m). Backs engine.dg.elasticity.THIN_CELLS.

    PYTHONPATH=. .venv/bin/python -m benchmarks.dg_thin_plate
"""
import sys, numpy as np, trimesh
from engine import simulate
from engine.geometry.cache import GeometryCache
E, rho, g, L = 1e7, 1000.0, 9.81, 1.0
for k in (1, 2):
    for t in (0.0125, 0.03, 0.0625, 0.125, 0.25):
        mesh = trimesh.creation.box(bounds=[[0, 0, 0.3], [L, 0.2, 0.3 + t]]).export(file_type="stl")
        spec = {"dimension": 3, "geometry": {"mesh": "p.stl"}, "grid": {"cell_size": 0.125, "padding": 1},
                "method": {"kind": "dg", "degree": k}, "material": {"youngs_modulus": E, "poisson_ratio": 0.0, "density": rho},
                "loads": {"gravity": [0, 0, -g]},
                "boundaries": [{"kind": "displacement", "name": "c", "region": {"box": [[-1, -1, -1], [0.001, 1, 2]]}, "value": [0, 0, 0]}],
                "output": {"fields": ["displacement"], "probes": [[L - 1e-3, 0.1, 0.3 + t / 2]]}}
        try:
            r = simulate(spec, mesh, filename="p.stl", cache=GeometryCache(None))
            tip = -r.fields.probes["displacement"][0, 2]
            beam = 3 * rho * g * L**4 / (2 * E * t**2)
            print(k, t, f"t/h={t/0.125:.2f}", f"tip/beam={tip/beam:.3f}", flush=True)
        except Exception as e:
            print(k, t, "error", str(e)[:100], flush=True)
