"""The range of Young's modulus a single-precision staggered solve holds (``solver.precision`` f32).

In f32 the solver's device arrays store, per displacement sample, numbers whose size the job
sets: the operator's diagonal ~ k = (lambda + 2 mu) h^(d-2) and its inverse (Jacobi, the
smoothers; on a multigrid's coarsest level h grows up to n h), the loads f on the samples
(rho |g| h^d, |t| h^(d-1), |p| h^(d-1), and k |g_D| for a prescribed displacement g_D), the
displacements (g_D, or about f / k and up to n^4 times that where a slender part bends: a
cantilever's tip over one cell's load, n cells along the longest axis) and the stresses
(k |g_D| / h^(d-1)). CG then carries residuals down to rtol of the loads and corrections down to
rtol of the displacements. k scales with E, so each bounds E from one side. Outside f32's normal
numbers (1.2e-38 .. 3.4e38) the solve broke: E = 1e-40 overflowed the inverse diagonal and ended
in "lost positive definiteness (p.Ap = nan)", 1e40 made it 0.

Measured on a 1 x 0.2 x 0.2 m bar clamped at one end (f32 runs against the f64 solution):

    job                                   solved correctly      this check allows
    gravity, 12 cells, direct, rtol 1e-3  1e-33 .. 1e36 Pa      5.7e-29 .. 4.3e32 Pa
    end traction 1e4 Pa, same             1e-32 .. 1e37         7.0e-28 .. 5.3e33
    end moved 1 cm, same                  1e-32 .. 1e39 (a)     1.0e-28 .. 5.4e33
    gravity, 48 cells, V-cycle, rtol 1e-2 1e-32 .. 1e35         5.8e-28 .. 2.7e32
    end traction, same                    1e-32 .. 1e36         2.8e-26 .. 6.1e33
    end moved, 48 cells, rtol 1e-4        1e-28 .. 1e36 (b)     4.2e-27 .. 6.1e33

(a) 0.5% off at 1e-33, wrong below; (b) 0.6% off at 1e-30, 12% at 1e-32. The gravity jobs broke
where rtol f / k met f32's smallest normal number (1e37 at 12 cells, 1e36 at 48), the others at
the diagonal's or the residual's; :data:`MARGIN` keeps the check 1.6 to 6.4 decades inside.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import PrecisionRangeError
from ..grid import Grid
from ..material import lame_parameters

if TYPE_CHECKING:
    from schemas import JobSpec

F32_TINY = float(np.finfo(np.float32).tiny)  # the smallest normal f32: below it digits are lost
F32_MAX = float(np.finfo(np.float32).max)
MARGIN = 1e4  # kept from each f32 limit (the gravity bars broke within 4x of the bare rtol f / k estimate)


def modulus_range(spec: JobSpec, grid: Grid) -> tuple[float, float]:
    """(lowest, highest) Young's modulus [Pa] whose f32 solve of ``spec`` on ``grid`` keeps every
    stored number within f32's normal range, :data:`MARGIN` inside (see the module docstring)."""
    d, h = grid.dim, grid.spacing
    n = max(grid.shape)
    lam, mu = lame_parameters(1.0, spec.material.poisson_ratio)
    # k per unit E on the finest level and on the coarsest a multigrid may build (spacing <= n h)
    k_fine = (lam + 2 * mu) * h ** (d - 2)
    k_coarse = (lam + 2 * mu) * (n * h) ** (d - 2)
    k_lo, k_hi = min(k_fine, k_coarse), max(k_fine, k_coarse)
    # a quasi-static job's first step carries 1 / steps of the loads
    ramp = spec.analysis.steps if spec.analysis.kind == "quasistatic" else 1
    gravity = float(np.linalg.norm(spec.loads.gravity or (0.0,)))
    tractions = [float(np.linalg.norm(b.value)) if b.kind == "traction" else abs(float(b.value))
                 for b in spec.boundaries if b.kind in ("traction", "pressure")]
    held = [abs(float(v)) for b in spec.boundaries if b.kind == "displacement" for v in b.value if v]
    load = max([spec.material.density * gravity * h**d] + [t * h ** (d - 1) for t in tractions])
    low, high = F32_TINY * MARGIN, F32_MAX / MARGIN
    # CG carries residuals down to rtol of the loads and corrections down to rtol of the displacements
    rtol = spec.solver.rtol
    # the diagonal and its inverse, over the levels
    bounds = [(low / k_lo, min(high, 1.0 / low) / k_hi)]
    if load > 0:  # the loads' displacements: at least about f / k, at most n^4 f / k
        bounds.append((load * n**4 / (high * k_fine), load * rtol / (ramp * low * k_fine)))
    if held:  # the prescribed values' loads k g_D and stresses k g_D / h^(d-1)
        g_lo, g_hi = min(held) / ramp, max(held)
        bounds.append((low / (rtol * k_fine * g_lo * min(1.0, h ** (1 - d))),
                       high / (k_fine * g_hi * max(1.0, h ** (1 - d)))))
    return max(b[0] for b in bounds), min(b[1] for b in bounds)


def check_job(spec: JobSpec, grid: Grid) -> None:
    """PrecisionRangeError naming ``material.youngs_modulus`` and ``solver.precision`` when an f32
    job's modulus lies outside :func:`modulus_range`; nothing for an f64 job."""
    if spec.solver.precision != "f32":
        return
    E = spec.material.youngs_modulus
    lo, hi = modulus_range(spec, grid)
    if lo > hi:
        raise PrecisionRangeError(
            f"material.youngs_modulus: no modulus keeps this job within solver.precision 'f32' on a "
            f"{'x'.join(map(str, grid.shape))} grid of {grid.spacing:.4g} m cells (its loads and held displacements "
            "span more than single precision's range); use solver.precision 'f64'")
    if not lo <= E <= hi:
        raise PrecisionRangeError(
            f"material.youngs_modulus: {E:g} Pa is outside {lo:.2g} .. {hi:.2g} Pa, the range solver.precision "
            f"'f32' holds for this job's loads on its {'x'.join(map(str, grid.shape))} grid of {grid.spacing:.4g} m "
            "cells (the solver's stiffness, loads and displacements must stay within single precision's "
            f"{F32_TINY:.2g} .. {F32_MAX:.2g}); use solver.precision 'f64'")
