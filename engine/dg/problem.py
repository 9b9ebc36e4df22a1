"""Job spec (+ Python-API callables) -> a ready ``DGElasticity``."""

from __future__ import annotations

import numpy as np

from ..material import Material
from ..regions import make_region
from ..staggered.elasticity import SurfaceLoad
from ..staggered.problem import PredicateRegion
from .elasticity import DGElasticity, Prescribed


def make_dg(spec, geo, functions) -> DGElasticity:
    """The DG discretization of a validated job on its sliced geometry."""
    material = Material.from_spec(spec.material)
    prescribed, loads = [], []
    for i, b in enumerate(spec.boundaries):
        name = b.name or f"boundaries.{i}"
        region = PredicateRegion(functions.regions[name]) if name in functions.regions else make_region(b.region, 3)
        if b.kind == "displacement":
            value = functions.displacement.get(name, b.value)
            prescribed.append(Prescribed(region, value, name, tuple(v is not None for v in b.value)))
        elif b.kind == "traction":
            if name in functions.stress:
                loads.append(SurfaceLoad(region, name, stress=functions.stress[name]))
            else:
                loads.append(SurfaceLoad(region, name, traction=functions.traction.get(name, np.asarray(b.value, dtype=float))))
        else:
            loads.append(SurfaceLoad(region, name, pressure=float(b.value)))
    body = functions.body_force
    if body is None and spec.loads.gravity is not None and any(g != 0 for g in spec.loads.gravity):
        body = material.density * np.asarray(spec.loads.gravity, dtype=float)
    m = spec.method
    return DGElasticity(cut=geo.cut_cells, surface=geo.surface, material=material, degree=m.degree, flux=m.flux,
                        penalty=m.penalty, prescribed=prescribed, surface_loads=loads, body_force=body)
