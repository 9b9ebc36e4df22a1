"""Job spec (+ Python-API callables) -> a ready ``DGElasticity``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..boundary import make_boundaries
from ..grid import Grid
from ..material import Material
from ..method import Setup

if TYPE_CHECKING:
    from .elasticity import DGElasticity


def estimate_memory(grid: Grid, method_spec) -> int:
    """Upper estimate of a job's peak memory [bytes] from the grid alone: per cell, 7 blocks
    (element + 6 faces) of (d * basis)^2 doubles, times 4 for assembly copies, times the sparse
    Cholesky factor's fill, which grows like the grid's side in 3D (nested dissection). Measured
    peaks on the sphere shell (`python -m benchmarks scaling`, grids 18^3 / 26^3 / 34^3): k = 2
    1.51 / 5.34 / 14.5 GiB, k = 1 0.48 / 1.11 / 2.60 GiB; this estimate is 1.0-1.4x those from 26^3
    on (below, the process's own ~0.3 GiB dominates; before the fill factor it was 0.5-0.8x)."""
    d, cells, degree = grid.dim, grid.num_cells, method_spec.degree
    basis = {1: 4, 2: 10}[degree] if d == 3 else {1: 3, 2: 6}[degree]
    fill = max(1.0, cells ** (1 / d) / 12) if d == 3 else 1.0
    return int(cells * 7 * (d * basis) ** 2 * 8 * 4 * fill)


def make_dg(spec, geo, functions, progress: Setup | None = None) -> DGElasticity:
    """The DG discretization of a validated job on its sliced geometry."""
    from .elasticity import DGElasticity  # the method's modules load when a job builds it

    material = Material.from_spec(spec.material)
    b = make_boundaries(spec, functions, material)
    m = spec.method
    return DGElasticity(cut=geo.cut_cells, surface=geo.surface, material=material, degree=m.degree, flux=m.flux,
                        penalty=m.penalty, prescribed=b.prescribed, surface_loads=b.loads, body_force=b.body_force,
                        progress=progress)
