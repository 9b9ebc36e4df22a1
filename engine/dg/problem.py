"""Job spec (+ Python-API callables) -> a ready ``DGElasticity``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..boundary import make_boundaries
from ..geometry.occupancy import occupied_cells_bound
from ..grid import Grid
from ..material import Material
from ..method import Setup

if TYPE_CHECKING:
    from .elasticity import DGElasticity

# Above this many unknowns "auto" solves by p-multigrid CG instead of sparse Cholesky, whose fill grows
# superlinearly. Measured on the k = 2 shell, one static solve, assembly + solve (docs/benchmarks.md, "DG
# at scale"): Cholesky / CG to rtol 1e-8 2.4 / 2.0 s at 24k unknowns, 6.2 / 3.4 s at 55k, 38 / 11 s at
# 183k; k = 1 1.1 / 1.2 s at 22k, 3.8 / 4.0 s at 73k, 13 / 7.1 s at 171k. Below the limits the factor,
# reused by every load and time step (0.4 s a solve at 55k against CG's 1.4 s), is the better buy.
DIRECT_LIMIT = {1: 100_000, 2: 50_000}
# Near incompressibility the block-Jacobi smoother misses the divergence-free modes that span elements, and
# CG's iterations grow like sqrt(lambda / mu): the 16^3 k = 2 shell took 23 / 68 / 949 iterations at
# nu 0.3 / 0.49 / 0.4999 (4.2 / 6.3 / 50.2 s, Cholesky 7.4 / 5.9 / 7.7 s; `benchmarks.dg --nu`). Above INCOMPRESSIBLE_RATIO
# "auto" keeps Cholesky up to DIRECT_LIMIT_INCOMPRESSIBLE unknowns (its memory: 5 GiB at 183k for k = 2).
INCOMPRESSIBLE_RATIO = 100.0  # lambda / mu, nu ~ 0.495
DIRECT_LIMIT_INCOMPRESSIBLE = {1: 400_000, 2: 200_000}
# A p-multigrid coarse level with more unknowns than this is itself cycled, not factorised: the k = 1
# level's factor fills superlinearly (170,880 unknowns: 15 s, 1.8 GiB; 567,072: ~150 s, ~10 GiB), while
# cycling it over the constants costs iterations, how many depends on the part (the 32^3 shell: 24 -> 86,
# 26.5 -> 38 s, 3.0 -> 1.8 GiB; the 48^3 shell's 567k level: 91, 162 s and 5.8 GiB against 193 s and 13.7
# GiB factorised; benchmarks.scan's bunny at 2 mm, 301,884: 319 iterations and 287 s against 33 and 101 s,
# 6.75 GiB, factorised). 400k lies between the bunny, where factorising wins 2.8x, and the 48^3 shell.
COARSE_DIRECT = 400_000
# The memory estimate, fitted on whole jobs' measured peaks (`python -m benchmarks.dg_memory`, docs/benchmarks.md
# "The DG memory estimate": the Lame shell and the ball, 720 ... 175,456 elements): the process before any
# block [GiB], and a sparse Cholesky factorisation's peak (blocks, assembly copies and factor) as
# c * unknowns^p [GiB] per degree. k = 1, 2: fitted on direct jobs, c raised until the fit lies above every
# measured peak (1.01x, 1.16x) and by 10% more. k = 0, the constants below a cycled k = 1 level: what k = 1
# iterative jobs hold beyond their blocks, with the nested-dissection exponent 4/3 (the data's own, 1.1, is
# set by its small runs) and c above every run of more than 150k unknowns by 10% (the smaller ones are
# inside BASE_GIB's margin).
BASE_GIB = 0.5
CHOLESKY_GIB = {0: (1.3e-7, 4 / 3), 1: (1.1 * 1.01 * 3.854e-8, 1.476), 2: (1.1 * 1.163 * 3.963e-7, 1.331)}


def estimate_memory(grid: Grid, method_spec, surface=None, occupied: int | None = None) -> int:
    """Upper estimate of a job's peak memory [bytes] for the solver the job will use (``method.solver``;
    "auto" can be either, so the larger of the two, the direct one at most at its size limit for a
    nearly incompressible material), from its elements: ``occupied`` (the cut cells' pieces) when the
    geometry is known, else the bound ``occupied_cells_bound(surface, grid)``, else every grid cell.

    Direct: the fitted Cholesky peak of the job's unknowns (CHOLESKY_GIB). Iterative: the fine blocks
    (element + 6 faces of (3 * basis)^2 doubles per element) twice, and the degree k - 1 level
    factorised, or above COARSE_DIRECT unknowns held twice and cycled over the factorised constants."""
    if occupied is not None:
        elements = occupied
    elif surface is not None:
        elements = occupied_cells_bound(surface, grid)
    else:
        elements = grid.num_cells
    degree = method_spec.degree
    size = {0: 3, 1: 12, 2: 30}  # unknowns per element by degree (3D)

    def cholesky(unknowns: float, fit: int) -> float:
        c, p = CHOLESKY_GIB[fit]
        return c * unknowns**p * 2**30

    def held(k: int) -> float:  # element and face blocks of degree k, twice (matrix and assembly)
        return elements * 7 * size[k] ** 2 * 8 * 2

    low = degree - 1
    if low >= 1 and elements * size[low] <= COARSE_DIRECT:
        bottom = cholesky(elements * size[low], low)
    else:
        bottom = (held(low) if low >= 1 else 0.0) + cholesky(elements * size[0], 0)
    iterative = held(degree) + bottom
    direct = cholesky(elements * size[degree], degree)
    kind = method_spec.solver
    if kind == "auto":  # the material is not known here: the direct solve at the larger of its limits
        limit = max(DIRECT_LIMIT[degree], DIRECT_LIMIT_INCOMPRESSIBLE[degree])
        need = max(iterative, cholesky(min(elements * size[degree], limit), degree))
    else:
        need = direct if kind == "direct" else iterative
    return int(BASE_GIB * 2**30 + need)


F32_IGNORED = ("solver.precision: 'f32' applies to the staggered method; the DG method solves in f64 (its memory "
               "and its result are double precision's)")


def make_dg(spec, geo, functions, progress: Setup | None = None) -> DGElasticity:
    """The DG discretization of a validated job on its sliced geometry."""
    from .elasticity import DGElasticity  # the method's modules load when a job builds it

    material = Material.from_spec(spec.material)
    b = make_boundaries(spec, functions, material)
    m = spec.method
    dg = DGElasticity(cut=geo.cut_cells, surface=geo.surface, material=material, degree=m.degree, flux=m.flux,
                      penalty=m.penalty, prescribed=b.prescribed, surface_loads=b.loads, body_force=b.body_force,
                      solver_kind=m.solver, rtol=spec.solver.rtol, max_iterations=spec.solver.max_iterations,
                      progress=progress,
                      time_step=spec.analysis.time_step if spec.analysis.kind == "dynamic" else None)
    if spec.solver.precision == "f32":  # asked for to halve the memory, which it does not here
        dg.warnings.append(F32_IGNORED)
    return dg
