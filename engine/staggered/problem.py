"""Job spec (+ Python-API callables) -> a ready ``StaggeredElasticity``."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..errors import MethodUnavailableError
from ..material import Material
from ..regions import make_region
from .elasticity import Prescribed, StaggeredElasticity, SurfaceLoad


class PredicateRegion:
    """A region given by a callable mask points [N, d] -> bool [N] (Python API). Surface facets
    count by their centroid, so patches are resolved to the facet size."""

    def __init__(self, mask: Callable[[np.ndarray], np.ndarray]) -> None:
        self.mask = mask

    def contains(self, points: np.ndarray, slack: float = 0.0) -> np.ndarray:
        return np.asarray(self.mask(np.asarray(points, dtype=float)), dtype=bool).reshape(len(points))

    def clip(self, facets: np.ndarray, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        keep = np.nonzero(self.contains(np.asarray(facets).mean(axis=1)))[0]
        return np.asarray(facets)[keep], keep


def make_staggered(spec, geo, functions) -> StaggeredElasticity:
    """The staggered discretization of a validated job on its prepared geometry."""
    material = Material.from_spec(spec.material)
    if material.model != "linear":
        raise MethodUnavailableError(
            f"material.model: '{material.model}' is not available with the staggered method (linear elasticity "
            "only); use 'linear'"
        )
    d = spec.dimension
    prescribed, loads = [], []
    for i, b in enumerate(spec.boundaries):
        name = b.name or f"boundaries.{i}"
        region = PredicateRegion(functions.regions[name]) if name in functions.regions else make_region(b.region, d)
        if b.kind == "displacement":
            value = functions.displacement.get(name, b.value)
            components = tuple(v is not None for v in b.value)
            prescribed.append(Prescribed(region, value, name, components))
        elif b.kind == "traction":
            if name in functions.stress:
                loads.append(SurfaceLoad(region, name, stress=functions.stress[name], form=functions.stress_form))
            else:
                loads.append(SurfaceLoad(region, name, traction=functions.traction.get(name, np.asarray(b.value, dtype=float))))
        else:
            loads.append(SurfaceLoad(region, name, pressure=float(b.value), form=functions.pressure_form))
    body = functions.body_force
    if body is None and spec.loads.gravity is not None and any(g != 0 for g in spec.loads.gravity):
        body = material.density * np.asarray(spec.loads.gravity, dtype=float)
    return StaggeredElasticity(
        fractions=geo.fractions,
        surface=geo.surface,
        material=material,
        prescribed=prescribed,
        surface_loads=loads,
        body_force=body,
        rtol=spec.solver.rtol,
        max_iterations=spec.solver.max_iterations,
    )
