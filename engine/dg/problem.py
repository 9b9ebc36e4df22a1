"""Job spec (+ Python-API callables) -> a ready ``DGElasticity``."""

from __future__ import annotations

from ..boundary import make_boundaries
from ..material import Material
from .elasticity import DGElasticity


def make_dg(spec, geo, functions) -> DGElasticity:
    """The DG discretization of a validated job on its sliced geometry."""
    material = Material.from_spec(spec.material)
    b = make_boundaries(spec, functions, material)
    m = spec.method
    return DGElasticity(cut=geo.cut_cells, surface=geo.surface, material=material, degree=m.degree, flux=m.flux,
                        penalty=m.penalty, prescribed=b.prescribed, surface_loads=b.loads, body_force=b.body_force)
