"""Job spec (+ Python-API callables) -> a ready ``StaggeredElasticity``."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..boundary import make_boundaries
from ..errors import MethodUnavailableError
from ..geometry.fractions import control_offsets
from ..grid import Grid
from ..material import Material
from ..method import Setup

if TYPE_CHECKING:
    from .elasticity import StaggeredElasticity


# "auto" factorises the whole problem up to this many unknowns instead of building a V-cycle: the
# factor costs less than the hierarchy's setup and CG's iterations there (warm jobs, PARDISO,
# direct / multigrid: bundled cantilever 5,285 unknowns 0.21 / 0.55 s, 34,593 0.69 / 2.1 s,
# 64,736 1.35 / 1.42 s; a clamped ball 26,964 0.54 / 0.75 s, 61,200 1.7 / 1.0 s; a compact body's
# factor fills faster; docs/benchmarks.md, "Small jobs solved directly") ...
DIRECT_DOFS = 30_000
# ... and when the dense index box the sparse assembly spans (``assembly.stiffness``, ~500 bytes
# and 1.7 us per position) is not much larger: a thin part lying across its grid
DIRECT_BOX = 20 * DIRECT_DOFS
# PARDISO's factor (its permanent and factorisation memory) of the staggered operator, measured on
# a clamped ball (8,856 ... 115,644 unknowns: 22, 91, 264, 682 MB) and the cantilever (15,640 ...
# 120,200: 33, 93, 508 MB): below FACTOR_BYTES n^1.4, with a margin of 1.2 or more; the dense-box
# assembly's peak: ASSEMBLY_BYTES per index-box position
FACTOR_BYTES = 70.0
ASSEMBLY_BYTES = 600


def direct_bytes(dofs: int, positions: int) -> int:
    """Upper estimate [bytes] of a direct solve's own memory: the factor of ``dofs`` unknowns and the
    sparse assembly over an index box of ``positions``."""
    return int(FACTOR_BYTES * dofs**1.4 + ASSEMBLY_BYTES * positions)


def estimate_memory(grid: Grid, method_spec=None, surface=None, occupied: int | None = None) -> int:
    """Upper estimate of a job's peak memory [bytes] from the grid alone: per cell, the fractions
    of every control-volume kind plus ~12 solver vectors per displacement component (CG and the
    multigrid hierarchy), and the factor of a direct solve (``method.solver``: "direct" at the grid's
    every sample, "auto" up to DIRECT_DOFS and DIRECT_BOX). ``surface`` and ``occupied`` are not
    used: the fractions and the output fields are dense over the grid."""
    d = grid.dim
    need = grid.num_cells * 8 * (len(control_offsets(d)) + 12 * d)
    positions = math.prod(n + 1 for n in grid.shape)
    solver = getattr(method_spec, "solver", "auto")
    if solver == "direct":
        need += direct_bytes(d * positions, positions)
    elif solver == "auto" and positions <= DIRECT_BOX:
        need += direct_bytes(min(d * positions, DIRECT_DOFS), positions)
    return need


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
        solver=spec.method.solver,
    )
