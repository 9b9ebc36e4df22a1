"""Job spec (+ Python-API callables) -> a ready ``StaggeredElasticity``."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..boundary import make_boundaries
from ..errors import MethodUnavailableError
from ..geometry.occupancy import occupied_tiles_bound
from ..grid import Grid
from ..material import Material
from ..method import Setup
from .layout import TILE

if TYPE_CHECKING:
    from .elasticity import StaggeredElasticity


# "auto" factorises the whole problem instead of building a V-cycle when the grid's index box holds
# at most this many samples (d prod(n + 1); the unknowns are those beside material, fewer): the
# factor then costs less than the hierarchy's setup and CG's iterations (benchmarks.direct_solve,
# warm jobs, direct / multigrid: bundled cantilever 5,285 unknowns 0.20 / 0.62 s, 34,593 (51,456
# samples) 0.87 / 1.78 s, 64,736 (89,889) 1.54 / 1.60 s; a clamped ball 26,964 (59,049) 0.59 /
# 0.60 s, 61,200 (128,625) 1.79 / 0.90 s: a compact body's factor fills faster; docs/benchmarks.md,
# "Small jobs solved directly"). Decided from the grid alone, so the memory estimate knows it.
DIRECT_SAMPLES = 60_000
# PARDISO's factor (its permanent and factorisation memory) of the staggered operator, measured on
# a clamped ball (8,856 ... 115,644 unknowns: 22, 91, 264, 682 MB) and the cantilever (15,640 ...
# 120,200: 33, 93, 508 MB): below FACTOR_BYTES n^1.4, with a margin of 1.2 or more; the sparse
# assembly over the dense index box (``assembly.stiffness``): ASSEMBLY_BYTES per position
FACTOR_BYTES = 70.0
ASSEMBLY_BYTES = 600
# A job's peak resident memory (``estimate_memory``), fitted above whole jobs' peaks, each in a fresh
# process (benchmarks.staggered_memory: cubes filling their grids, a ball, a shell and a plate at 64^3 to
# 256^3, a 2D annulus at 1024^2 to 4096^2; static and dynamic, nu 0.3 and 0.4999, displacement or every
# field; docs/benchmarks.md, "The staggered memory estimate against whole jobs"): the process with
# NumPy, SciPy and Taichi loaded (a direct solve of a small job peaks at ~240 MiB), the first V-cycle's
# kernels in a process, per kept sample position (the fractions, the levels, CG's vectors, the curl
# path's edge arrays and band inverses, the surface terms) and per grid cell (the fields written).
BASE_BYTES = 300 * 2**20
KERNEL_BYTES = 250 * 2**20
POSITION_BYTES = {2: 315, 3: 734}
CELL_BYTES = {2: 165, 3: 160}


def solves_directly(grid: Grid, solver: str = "auto") -> bool:
    """Whether a job on ``grid`` with ``method.solver`` factorises the whole problem."""
    return solver == "direct" or (solver == "auto" and grid.dim * _positions(grid) <= DIRECT_SAMPLES)


def direct_bytes(grid: Grid) -> int:
    """Upper estimate [bytes] of a direct solve's own memory on ``grid``: the factor of every
    sample of its index box (the unknowns are fewer) and the sparse assembly over the box."""
    positions = _positions(grid)
    return int(FACTOR_BYTES * (grid.dim * positions) ** 1.4 + ASSEMBLY_BYTES * positions)


def _positions(grid: Grid) -> int:
    return math.prod(n + 1 for n in grid.shape)


def estimate_memory(grid: Grid, method_spec=None, surface=None, occupied: int | None = None) -> int:
    """Upper estimate of a job's peak resident memory [bytes], process included: BASE_BYTES, the
    kernels' compilation when the job builds a V-cycle (KERNEL_BYTES), POSITION_BYTES per sample
    position of the tiles the fine level keeps (``occupied_tiles_bound`` of ``surface``; every tile of
    the index box without it), CELL_BYTES per grid cell for the dense output fields, and the factor of
    a direct solve (``solves_directly``). The material and the fields asked for are not known here, so
    it holds for the worst of them: nu near 1/2 (the curl path's arrays) and every stress field, in a
    dynamic run. ``occupied`` (cut-cell pieces) is not used."""
    d = grid.dim
    if surface is not None:
        tiles = occupied_tiles_bound(surface, grid, TILE)
    else:
        tiles = math.prod(-(-(n + 1) // TILE) for n in grid.shape)
    need = BASE_BYTES + POSITION_BYTES[d] * tiles * TILE**d + CELL_BYTES[d] * grid.num_cells
    if solves_directly(grid, getattr(method_spec, "solver", "auto")):
        need += direct_bytes(grid)
    else:
        need += KERNEL_BYTES
    return int(need)


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
        time_step=spec.analysis.time_step if spec.analysis.kind == "dynamic" else None,
        solver=spec.method.solver,
    )
