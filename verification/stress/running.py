"""Running one job of the stress suite: the job spec, the pipeline's stages, the condition estimate.

The stages are the pipeline's own (surface loading, grid, ``pipeline.compute_geometry``, the method
registry's builder, ``engine.analysis.run_analysis``), called one by one so that the method object
stays available (condition estimate, per-step solver statistics) and the offset and thin-wall
cases can pin the grid (``engine.pipeline.run`` centres the grid on the part).

Conditioning: DG reports ``DGElasticity.condition_estimate()`` (2-norm condition of its matrix);
the staggered column is the same estimate for its operator on the free DOFs (Lanczos on A for the
largest eigenvalue, LOBPCG preconditioned by the method's own V-cycle for the smallest). Both are
n/a (NaN) when free rigid modes are bordered out or projected off.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from verification.parts import E0, NU0, RHO, TIP_TRACTION, WIDTH, Bar
from verification.stress.rows import MAX_ITERATIONS, RTOL, Size

if TYPE_CHECKING:
    from engine.grid import Grid

# Load regions reach this many cells past the face they select. A closed region placed exactly on
# a face keeps it only up to round-off: rotated faces have vertices 1e-17 m on either side, DG's
# sliced boundary triangles sit on the grid plane or 1e-14 m off (the exact_faces case measures it).
FACE_SLACK = 1e-9


def method_spec(method: str, size: Size) -> dict:
    """The job spec's ``method`` for "staggered" or "dg" (the size's degree, IP flux, eta 20). The
    staggered runs solve iteratively: the suite's small bars would be factorised under "auto", and its
    iteration rows (nu, E, offsets) measure the multigrid V-cycle."""
    if method == "staggered":
        return {"kind": "staggered", "solver": "iterative"}
    return {"kind": "dg", "degree": size.dg_degree, "flux": "ip", "penalty": 20}


def method_label(spec: dict) -> str:
    """Table label of a ``method`` spec."""
    return "staggered" if spec["kind"] == "staggered" else f"dg k={spec['degree']}"


def cell_size(method: str, size: Size) -> float:
    """h [m]: WIDTH over the size's cells across for that method."""
    return WIDTH / (size.staggered_cells if method == "staggered" else size.dg_cells)


def job(method: dict, h: float, boundaries: list, *, youngs: float = E0, nu: float = NU0, model: str = "linear",
        analysis: dict | None = None, probes: list | None = None, fields=("displacement", "stress")) -> dict:
    """A job spec dict on cell size ``h`` [m], SI units (the geometry is the mesh handed to
    :func:`solve`); every field is requested at cells, probes and surface."""
    spec = {
        "dimension": 3,
        "geometry": {"mesh": "part.ply"},
        "grid": {"cell_size": h, "padding": 1},
        "method": method,
        "material": {"youngs_modulus": youngs, "poisson_ratio": nu, "density": RHO, "model": model},
        "boundaries": boundaries,
        "analysis": analysis or {"kind": "static"},
        "solver": {"rtol": RTOL, "max_iterations": MAX_ITERATIONS, "precision": "f64", "arch": "cpu"},
        "output": {"fields": list(fields), "probes": probes or [], "surface": True},
    }
    return spec


def clamp_depth(method: dict, h: float) -> float:
    """Axial depth [m] of a clamp region: both methods hold the surface patch inside it, so the end
    face alone (FACE_SLACK h beyond it)."""
    return FACE_SLACK * h


@dataclass
class Solved:
    """A finished job: the spec, the geometry stages' output, the method object, the analysis
    outcome, every solve's statistics (``stats``), the condition estimate (NaN: n/a) and times [s]."""

    spec: object
    geometry: object
    method: object
    outcome: object
    stats: list
    condition: float
    seconds: float
    condition_seconds: float

    @property
    def material(self) -> np.ndarray:
        """bool [*grid.shape]: cells holding material."""
        from engine.pipeline import cell_fractions

        return cell_fractions(self.geometry) > 0

    @property
    def final(self) -> Any:
        """The analysis outcome's last fields (``cells``, ``probes``, ``surface`` dicts)."""
        return self.outcome.final

    @property
    def warnings(self) -> list[str]:
        """The geometry stages' and the method's warnings, in that order."""
        return list(self.geometry.warnings) + list(self.method.warnings)

    def probe(self, name: str = "displacement") -> np.ndarray:
        """Field ``name`` at the job's probes [n_probes, ...]."""
        return np.asarray(self.final.probes[name])


def solve(spec: dict, mesh: trimesh.Trimesh, *, grid: Grid | None = None, condition: bool = True) -> Solved:
    """Run one job through the pipeline's stages (see the module docstring); ``grid``: a pinned
    ``engine.grid.Grid`` instead of the spec's centred one. Raises what the engine raises."""
    from engine.analysis import run_analysis
    from engine.geometry.containment import in_solid
    from engine.geometry.loading import load_surface
    from engine.grid import make_grid
    from engine.method import method_entry
    from engine.pipeline import Functions, compute_geometry, sampled_output, spread_probes
    from engine.runtime import init
    from schemas import parse_job

    parsed = parse_job(spec)
    init(parsed.solver.arch, parsed.solver.precision)
    t0 = time.perf_counter()
    surface = load_surface(mesh, filename=parsed.geometry.mesh)
    if grid is None:
        g = parsed.grid
        grid = make_grid(*surface.bounds, cell_size=g.cell_size, resolution=g.resolution, padding=g.padding)
    geo = compute_geometry(parsed.method.kind, surface, grid)
    method = method_entry(parsed.method.kind).build(parsed, geo, Functions())
    stats: list = []
    inner = method.solve

    def recorded(*args: Any, **kwargs: Any) -> Any:
        state = inner(*args, **kwargs)
        stats.append(state.stats)
        return state

    method.solve = recorded  # every step's solve statistics, not only the last one's
    # as engine.pipeline.run: a probe outside the solid has no values, and the method is not asked
    inside = in_solid(surface, np.asarray(parsed.output.probes, dtype=float), grid.spacing) if parsed.output.probes else None
    outcome = run_analysis(method, parsed.analysis, sampled_output(parsed.output, inside), lambda *a: None)
    if inside is not None and not inside.all():
        spread_probes([outcome.final, *outcome.steps], inside, parsed.dimension)
    seconds = time.perf_counter() - t0
    t1 = time.perf_counter()
    cond = condition_number(method) if condition else math.nan
    return Solved(parsed, geo, method, outcome, stats, cond, seconds, time.perf_counter() - t1)


def condition_number(method: Any) -> float:
    """2-norm condition estimate of the solved operator (NaN where rigid modes are free)."""
    if hasattr(method, "condition_estimate"):
        return float(method.condition_estimate())
    return staggered_condition(method)


def staggered_condition(m: Any, tol: float = 1e-3) -> float:
    """kappa_2 of the staggered operator A (with its backward-Euler shift, if set) on the free DOFs:
    the largest eigenvalue by Lanczos on A, the smallest by LOBPCG on A / lambda_max preconditioned
    by the method's V-cycle, its residual tolerance tightened to 3% of the eigenvalue found until
    two passes agree to ``tol`` (relative; scale-free, so E does not change it). NaN when free rigid
    modes are projected off."""
    import scipy.sparse.linalg as spla

    from engine.runtime import device_array

    if m.modes:
        return math.nan
    level = m.level
    idx = np.flatnonzero(level.free)
    n, shape = len(idx), (level.dim, level.size)
    out = level.zeros()

    def device(v: np.ndarray) -> Any:
        full = np.zeros(shape)
        full.reshape(-1)[idx] = np.asarray(v).reshape(-1)
        return device_array(full)

    def apply(v: np.ndarray) -> np.ndarray:
        level.apply(device(v), out)
        return out.to_numpy().reshape(-1)[idx].astype(np.float64)

    def cycle(v: np.ndarray) -> np.ndarray:
        m.multigrid.precondition(device(v), out)
        return out.to_numpy().reshape(-1)[idx].astype(np.float64)

    def operator(f: Callable[[np.ndarray], np.ndarray]) -> spla.LinearOperator:
        def block(v: np.ndarray) -> np.ndarray:  # LOBPCG hands [n, k] blocks
            return np.column_stack([f(c) for c in np.asarray(v).reshape(n, -1).T])

        return spla.LinearOperator((n, n), matvec=f, matmat=block, dtype=float)

    top = spla.eigsh(operator(apply), k=1, which="LA", tol=tol, return_eigenvectors=False)[0]
    scaled = operator(lambda v: apply(v) / top)
    x = np.random.default_rng(0).standard_normal((n, 1))
    low = 1.0
    for _ in range(8):
        found, x = spla.lobpcg(scaled, x, M=operator(cycle), largest=False, tol=0.03 * low, maxiter=200)
        settled = abs(found[0] - low) <= tol * found[0]
        low = float(found[0])
        if settled:
            break
    return 1.0 / low



def cantilever_job(method: dict, h: float, bar: Bar, *, traction: float = TIP_TRACTION, exact_faces: bool = False,
                   **kw) -> dict:
    """The bar clamped at axial 0 (see :func:`clamp_depth`) under ``traction`` [Pa] along its load
    direction on the far end face; probes on the axis just inside the tip and at mid-length [m].
    ``exact_faces``: the regions lie exactly on the end faces (DG clamp too) instead of reaching
    FACE_SLACK h past them."""
    slack = 0.0 if exact_faces else FACE_SLACK * h
    depth = slack  # both methods hold the end face (the surface patch inside the region)
    boundaries = [
        {"kind": "displacement", "name": "clamp", "region": bar.beyond(depth, -1), "value": [0, 0, 0]},
        {"kind": "traction", "name": "tip", "region": bar.end(+1, slack), "value": bar.direction(1, traction)},
    ]
    probes = [bar.point(bar.length - 1e-3 * h), bar.point(0.5 * bar.length)]
    return job(method, h, boundaries, probes=probes, **kw)


def tip_deflection(solved: Solved, bar: Bar) -> float:
    """Displacement [m] of the tip probe along the bar's load direction."""
    return float(solved.probe()[0] @ bar.frame[1])


def h_label(h: float) -> str:
    """Table label of a cell size: "h=W/n"."""
    return f"h=W/{round(WIDTH / h)}"
