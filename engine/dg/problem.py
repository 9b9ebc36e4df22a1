"""Job spec (+ Python-API callables) -> a ready ``DGElasticity``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..boundary import make_boundaries
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


def estimate_memory(grid: Grid, method_spec) -> int:
    """Upper estimate of a job's peak memory [bytes] from the grid alone, for the solver the job will
    use (``method.solver``; "auto" can be either, so the larger of the two, the direct one at most at
    its size limit for a nearly incompressible material). Per cell 7 blocks (element + 6 faces) of (d *
    basis)^2 doubles; the direct solve holds them 4 times over (assembly copies) times the sparse
    Cholesky factor's fill, which grows like the grid's side in 3D (nested dissection); the iterative
    one holds them twice and factorises only its degree k - 1 coarse level, or above COARSE_DIRECT
    unknowns holds that level twice and factorises the constants below it. Measured peaks on the sphere
    shell (`python -m benchmarks scaling`), direct, grids 18^3 / 26^3 / 34^3: k = 2 1.51 / 5.34 / 14.5
    GiB, k = 1 0.48 / 1.11 / 2.60 GiB (this estimate 1.0-1.4x); iterative at 34^3: k = 2 3.81 GiB, k = 1
    0.71 GiB (estimate for "auto" 1.45x, and 3.8x for k = 1, which must cover a Cholesky of 400k
    unknowns should the material be nearly incompressible), at 50^3 k = 2 with three levels 5.80 GiB
    (estimate 2.5x: the shell fills 38% of its cells, the estimate counts them all)."""
    d, cells, degree = grid.dim, grid.num_cells, method_spec.degree
    size = {1: 4, 2: 10}[degree] if d == 3 else {1: 3, 2: 6}[degree]
    low = {1: 1, 2: 4}[degree] if d == 3 else {1: 1, 2: 3}[degree]

    def direct(count: float, basis: int) -> float:
        fill = max(1.0, count ** (1 / d) / 12) if d == 3 else 1.0
        return count * 7 * (d * basis) ** 2 * 8 * 4 * fill

    # the k - 1 level factorised (at most COARSE_DIRECT unknowns of it), or cycled over the constants
    bottom = direct(min(cells, COARSE_DIRECT / (d * low)), low)
    if degree == 2 and cells * d * low > COARSE_DIRECT:
        bottom = max(bottom, cells * 7 * (d * low) ** 2 * 8 * 2 + direct(cells, 1))
    iterative = cells * 7 * (d * size) ** 2 * 8 * 2 + bottom
    kind = method_spec.solver
    if kind == "direct":
        return int(direct(cells, size))
    if kind == "iterative":
        return int(iterative)
    # the material is not known here: the direct solve at the larger of its limits
    limit = max(DIRECT_LIMIT[degree], DIRECT_LIMIT_INCOMPRESSIBLE[degree])
    return int(max(iterative, direct(min(cells, limit / (d * size)), size)))


def make_dg(spec, geo, functions, progress: Setup | None = None) -> DGElasticity:
    """The DG discretization of a validated job on its sliced geometry."""
    from .elasticity import DGElasticity  # the method's modules load when a job builds it

    material = Material.from_spec(spec.material)
    b = make_boundaries(spec, functions, material)
    m = spec.method
    return DGElasticity(cut=geo.cut_cells, surface=geo.surface, material=material, degree=m.degree, flux=m.flux,
                        penalty=m.penalty, prescribed=b.prescribed, surface_loads=b.loads, body_force=b.body_force,
                        solver_kind=m.solver, rtol=spec.solver.rtol, max_iterations=spec.solver.max_iterations,
                        progress=progress)
