"""The Python API in one go: build a job spec, run it with ``engine.simulate``, read fields, make a
picture. Run from the repository root: ``python examples/python_api.py [output directory]``."""

import sys
from pathlib import Path

import numpy as np

import engine
from engine.output import write_result
from engine.preview import render_preview

here = Path(__file__).resolve().parent
out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(".")

# A 1 m x 0.2 m x 0.2 m bar clamped at x = 0, loaded down at its tip (SI units throughout).
spec = {
    "dimension": 3,
    "geometry": {"mesh": "cantilever.stl"},
    "grid": {"resolution": 24},
    "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000},
    "boundaries": [
        {"kind": "displacement", "name": "clamp", "region": {"box": [[-0.1, -0.2, -0.2], [0.05, 0.2, 0.2]]},
         "value": [0, 0, 0]},
        {"kind": "traction", "name": "tip", "region": {"box": [[1.0, -0.2, -0.2], [1.1, 0.2, 0.2]]},
         "value": [0, 0, -1000]},
    ],
    "output": {"fields": ["displacement", "von_mises"], "probes": [[0.99, 0.0, 0.0]], "surface": True},
}
result = engine.simulate(spec, here / "cantilever.stl")

tip = result.fields.probes["displacement"][0]  # [m] at the probe
print(f"tip deflection {tip[2]:.4e} m")
print(f"largest von Mises stress {np.nanmax(result.fields.cells['von_mises']):.4e} Pa")

fields = result.to_xarray()  # named dimensions x, y, z, component; units as attributes
mid = fields["displacement"].sel(x=0.5, y=0.0, z=0.0, method="nearest").sel(component="z")
print(f"{mid.item():.4e} m at mid-span (cell centre)")

write_result(result, out / "bar.h5")  # + bar.vtkhdf (PyVista, ParaView), bar.solid.xdmf (meshio) ...
render_preview(result, out / "bar.png")  # the deformed surface coloured by von Mises
print(f"wrote {out / 'bar.h5'} and {out / 'bar.png'}")
