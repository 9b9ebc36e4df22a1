"""Job spec (+ Python-API callables) -> a ready ``StaggeredElasticity``."""

from __future__ import annotations

from ..boundary import make_boundaries
from ..errors import MethodUnavailableError
from ..material import Material
from .elasticity import StaggeredElasticity


def make_staggered(spec, geo, functions) -> StaggeredElasticity:
    """The staggered discretization of a validated job on its prepared geometry."""
    material = Material.from_spec(spec.material)
    if material.model != "linear":
        raise MethodUnavailableError(
            f"material.model: '{material.model}' is not available with the staggered method (linear elasticity "
            "only); use 'linear'"
        )
    b = make_boundaries(spec, functions, material)
    return StaggeredElasticity(
        fractions=geo.fractions,
        surface=geo.surface,
        material=material,
        prescribed=b.prescribed,
        surface_loads=b.loads,
        body_force=b.body_force,
        rtol=spec.solver.rtol,
        max_iterations=spec.solver.max_iterations,
    )
