"""Job spec (+ Python-API callables) -> a ready ``StaggeredElasticity``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..boundary import make_boundaries
from ..errors import MethodUnavailableError
from ..geometry.fractions import control_offsets
from ..grid import Grid
from ..material import Material
from ..method import Setup

if TYPE_CHECKING:
    from .elasticity import StaggeredElasticity


def estimate_memory(grid: Grid, method_spec=None, surface=None, occupied: int | None = None) -> int:
    """Upper estimate of a job's peak memory [bytes] from the grid alone: per cell, the fractions
    of every control-volume kind plus ~12 solver vectors per displacement component (CG and the
    multigrid hierarchy). ``surface`` and ``occupied`` are not used: the fractions and the output
    fields are dense over the grid."""
    d = grid.dim
    return grid.num_cells * 8 * (len(control_offsets(d)) + 12 * d)


def make_staggered(spec, geo, functions, progress: Setup | None = None) -> StaggeredElasticity:
    """The staggered discretization of a validated job on its prepared geometry."""
    from .elasticity import StaggeredElasticity  # the method's modules load when a job builds it

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
        progress=progress,
        dynamic=spec.analysis.kind == "dynamic",
    )
