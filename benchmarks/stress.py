"""Numerical-stability stress suite (issue 6, part 3): hard cases on both methods, a pass/fail table.

    .venv/bin/python -m benchmarks.stress                 # default sizes
    .venv/bin/python -m benchmarks.stress --quick         # smaller grids (~2.5 min on 2 cores)
    .venv/bin/python -m benchmarks stress --quick --json stress.json
    .venv/bin/python -m benchmarks.stress --case offsets --case free_body --method dg
    .venv/bin/python -m benchmarks.stress --case offsets --method staggered --cells 16 4   # refined
    .venv/bin/python -m pytest -q tests/test_stress.py    # the cheap cases as tests

Every case runs on the staggered method and on DG (degree 2, interior penalty, eta = 20); the
sizes set the cells across the bar's width W = 0.25 m per method (quick: staggered W / 6, DG
W / 3; default: W / 8 and W / 4). The part is mostly a 1 m cantilever (E = 1 MPa, nu = 0.3)
clamped at x = 0 and loaded by a traction on its far end face.

- ``poisson``: nu = 0.3, 0.45, 0.49, 0.499, 0.4999: tip deflection over Timoshenko beam theory
  (locking), iterations and condition growth.
- ``youngs``: E = 1, 1e3, 1e9 with the traction scaled with E (displacement identical) and with
  one fixed traction (displacement * E identical); summary rows compare every cell to 1e-8.
- ``offsets``: the cantilever translated by 16 sub-cell offsets (down to 1e-6 of a cell) on a
  pinned grid; the tip deflection must vary by < 5%.
- ``thin_wall``: a closed hollow box with walls 0.3 h thick, each wall inside one cell layer or
  across a grid plane, clamped at its base, pushed sideways; over thin-walled beam theory. The
  staggered grid has one sample across a wall inside a cell layer and nothing resists its
  transverse motion: that run must stop with ``ThinFeatureError`` (a solved job fails the row).
- ``rotated_bar``: a 2 m bar rotated off the grid axes vs the same bar along x and beam theory.
- ``large_strain``: bending to 10% surface strain, linear and corotated, vs the elastica.
- ``dynamic``: backward-Euler steps of 1e-5 s to 1 s after a sudden tip load, vs the static tip.
- ``hole``: a plate with a through hole (genus 1, made with a manifold3d boolean), pulled.
- ``free_body``: the 2 m bar without displacement boundaries pulled at both ends, along x and
  rotated (balanced: solved off the rigid modes with a warning; any error fails), and at one end
  (``UnbalancedLoadError`` "do not balance" required).
- ``exact_faces``: the cantilever's load (and DG clamp) regions exactly on its end faces instead
  of FACE_SLACK h past them; the tip must not change (to 1e-6).

A run passes when its fields (cells holding material, probes, surface, every time step) are
finite and the solve converged: staggered, every solve's relative residual within the requested
``solver.rtol``; DG (a direct solve), within ``DG_RESIDUAL_LIMIT``. A run that stops with a
``VoxelasticError`` whose message starts with the field it names (``solver: ...``,
``material.model: ...``) passes as a named error, except where the job is valid by construction
(free_body balanced, exact_faces); any other exception fails. Sweeps add a summary row: the
offsets' tip deflections must agree to 5%, the E sweep's displacements to 1e-8. Locking and the
beam-theory ratios are findings, recorded in the quantity column, not failures.

Conditioning: DG reports ``DGElasticity.condition_estimate()`` (2-norm condition of its matrix);
the staggered column is the same estimate for its operator on the free DOFs (Lanczos on A for the
largest eigenvalue, LOBPCG preconditioned by the method's own V-cycle for the smallest). Both are
n/a (NaN) when free rigid modes are bordered out or projected off.

The stages are the pipeline's own (surface loading, grid, fractions / slicing, ``make_staggered``
/ ``make_dg``, ``engine.analysis.run_analysis``), called one by one so that the method object
stays available (condition estimate, per-step solver statistics) and the offset and thin-wall
cases can pin the grid (``engine.pipeline.run`` centres the grid on the part).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from engine.errors import VoxelasticError

if TYPE_CHECKING:
    from engine.grid import Grid

# Relative residual a direct DG solve must reach: above it the factorisation lost more than 10
# of 16 digits (backward-stable Cholesky gives ~1e-16 times the condition number).
DG_RESIDUAL_LIMIT = 1e-6
OFFSET_SPREAD_LIMIT = 0.05  # (max - min) / |mean| of the tip deflection over the offsets
SCALING_LIMIT = 1e-8  # relative difference of the E sweep's (scaled) displacements
RTOL = 1e-8  # solver.rtol of every job (the schema's default)
MAX_ITERATIONS = 5000

# The cantilever of most cases: 1 m long, 0.25 m square, E = 1 MPa, clamped at x = 0.
LENGTH, WIDTH = 1.0, 0.25
LONG = 2.0  # the rotated bar and the free body: aspect ratio 8
E0, NU0, RHO = 1.0e6, 0.3, 1000.0
TIP_TRACTION = 1.0e2  # [Pa] on the end face: tip deflection ~6e-3 m, bending strain <= 2.4e-3
OFFSETS = (0.0, 1e-6, 1e-4, 1e-2, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99, 1 - 1e-4, 1 - 1e-6)
# Load regions reach this many cells past the face they select. A closed region placed exactly on
# a face keeps it only up to round-off: rotated faces have vertices 1e-17 m on either side, DG's
# sliced boundary triangles sit on the grid plane or 1e-14 m off (the exact_faces case measures it).
FACE_SLACK = 1e-9


@dataclass(frozen=True)
class Size:
    """How large a suite run is: cells across the bar's width W = 0.25 m per method (h = W / n),
    the DG degree, and the sweeps' values."""

    name: str
    staggered_cells: int
    dg_cells: int
    dg_degree: int
    poisson: tuple[float, ...] = (0.3, 0.45, 0.49, 0.499, 0.4999)
    youngs: tuple[float, ...] = (1.0, 1e3, 1e9)
    offsets: tuple[float, ...] = OFFSETS
    time_steps: tuple[float, ...] = (1e-5, 1e-3, 1e-1, 1.0)
    steps: int = 4


QUICK = Size("quick", staggered_cells=6, dg_cells=3, dg_degree=2)
DEFAULT = Size("default", staggered_cells=8, dg_cells=4, dg_degree=2)


# ----------------------------------------------------------------------------- rows


@dataclass
class Row:
    """One line of the table. iterations / residual: the largest over the run's solves (CG
    iterations; DG: 1 per direct solve, fixed-point iterations when corotated); condition: 2-norm
    estimate (NaN: n/a); quantity: the checked or reported number as text; values: the numbers
    behind it (for --json and the tests); seconds: wall time of the run without the condition
    estimate [s]."""

    case: str
    method: str
    params: str
    iterations: int | None = None
    residual: float | None = None
    condition: float | None = None
    quantity: str = ""
    passed: bool = False
    note: str = ""
    seconds: float = 0.0
    values: dict = field(default_factory=dict)

    def status(self) -> str:
        if not self.passed:
            return "FAIL"
        return "pass (error)" if self.values.get("error") else "pass"


# ----------------------------------------------------------------------------- geometry


@dataclass(frozen=True)
class Bar:
    """A square bar of ``length`` x ``width`` x ``width`` [m]. ``frame`` [3, 3] rows: the axis, the
    load direction, the third direction (right-handed); ``origin`` [3]: centre of the end face
    at axial coordinate 0 [m]."""

    length: float
    width: float
    frame: np.ndarray
    origin: np.ndarray

    def mesh(self) -> trimesh.Trimesh:
        """The bar's closed surface (12 triangles) in place."""
        w = self.width / 2
        box = trimesh.creation.box(bounds=[[0.0, -w, -w], [self.length, w, w]])
        m = np.eye(4)
        m[:3, :3] = self.frame.T  # columns: where e_x, e_y, e_z of the box go
        m[:3, 3] = self.origin
        box.apply_transform(m)
        return box

    def point(self, axial: float, lateral: float = 0.0) -> list[float]:
        """Position [3] at ``axial`` along the axis, ``lateral`` along the load direction [m]."""
        return (self.origin + axial * self.frame[0] + lateral * self.frame[1]).tolist()

    def beyond(self, axial: float, side: int) -> dict:
        """Spec region: the half-space of axial coordinate <= axial (side -1) or >= axial (+1)."""
        normal = (self.frame[0] if side < 0 else -self.frame[0]).tolist()
        return {"halfspace": {"point": self.point(axial), "normal": normal}}

    def end(self, side: int, slack: float) -> dict:
        """Spec region of the far (side +1) or near (-1) end face, reaching ``slack`` [m] past it."""
        return self.beyond(self.length - slack, +1) if side > 0 else self.beyond(slack, -1)

    def direction(self, k: int, scale: float) -> list[float]:
        """Vector [3]: ``scale`` along frame row k (0 axis, 1 load direction, 2 third)."""
        return (scale * self.frame[k]).tolist()


ALIGNED = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # axis x, load along z
# A generic orientation: 0.5 rad about (1, 2, 3), the DG tests' rotated box.
ROTATION = trimesh.transformations.rotation_matrix(0.5, [1, 2, 3])[:3, :3]
ROTATED = ALIGNED @ ROTATION.T  # each row rotated


def cantilever(length: float = LENGTH, frame: np.ndarray = ALIGNED, origin=(0.0, 0.0, 0.0)) -> Bar:
    """The suite's W x W bar of ``length`` [m] in ``frame``, end face centred at ``origin`` [m]."""
    return Bar(length, WIDTH, np.asarray(frame, dtype=float), np.asarray(origin, dtype=float))


def hollow_box(outer: tuple[float, float, float], wall: float) -> trimesh.Trimesh:
    """Closed box of ``outer`` extents [m] (corner at 0) with a sealed cavity: walls ``wall`` [m]."""
    out = trimesh.creation.box(bounds=[[0, 0, 0], list(outer)])
    cavity = trimesh.creation.box(bounds=[[wall] * 3, [o - wall for o in outer]])
    cavity.invert()
    return trimesh.util.concatenate([out, cavity])


def holed_plate(size: tuple[float, float, float], radius: float) -> trimesh.Trimesh:
    """Plate of ``size`` [m] (corner at 0) with a cylindrical through hole of ``radius`` [m] along z
    at its centre (manifold3d boolean; 48 facets around)."""
    plate = trimesh.creation.box(bounds=[[0, 0, 0], list(size)])
    drill = trimesh.creation.cylinder(radius=radius, height=3 * size[2], sections=48)
    drill.apply_translation([size[0] / 2, size[1] / 2, size[2] / 2])
    holed = plate.difference(drill, engine="manifold")
    if not holed.is_watertight or holed.euler_number != 0:
        raise RuntimeError(f"holed plate: boolean gave watertight={holed.is_watertight}, "
                           f"Euler number {holed.euler_number} (want 0: one through hole)")
    return holed


# ----------------------------------------------------------------------------- beam theory


def timoshenko_tip(force: float, length: float, width: float, youngs: float, nu: float) -> float:
    """Tip deflection [m] of a square cantilever under an end force [N]: bending P L^3 / (3 E I) plus
    shear P L / (k G A), k = 10 (1 + nu) / (12 + 11 nu) (Cowper's rectangle)."""
    inertia, area = width**4 / 12, width**2
    shear = youngs / (2 * (1 + nu))
    k = 10 * (1 + nu) / (12 + 11 * nu)
    return force * length**3 / (3 * youngs * inertia) + force * length / (k * shear * area)


def elastica_tip(load: float) -> float:
    """Tip deflection / length of an inextensible cantilever under a dead end load, transverse to the
    undeformed axis, with load = P L^2 / (E I): theta'' = -load cos(theta), theta(0) = 0,
    theta'(1) = 0, deflection = int_0^1 sin(theta) ds (shooting on theta(1))."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    def shoot(tip_angle: float) -> tuple[float, float]:
        # integrate from the free end back: theta(1) = tip_angle, theta'(1) = 0
        sol = solve_ivp(lambda s, y: [y[1], -load * np.cos(y[0]), np.sin(y[0])], (1.0, 0.0),
                        [tip_angle, 0.0, 0.0], rtol=1e-11, atol=1e-13)
        return sol.y[0, -1], -sol.y[2, -1]

    angle = brentq(lambda a: shoot(a)[0], 1e-9, np.pi / 2 - 1e-9, xtol=1e-13)
    return shoot(angle)[1]


# ----------------------------------------------------------------------------- running one job


def method_spec(method: str, size: Size) -> dict:
    """The job spec's ``method`` for "staggered" or "dg" (the size's degree, IP flux, eta 20)."""
    if method == "staggered":
        return {"kind": "staggered"}
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
    def final(self):
        return self.outcome.final

    @property
    def warnings(self) -> list[str]:
        return list(self.geometry.warnings) + list(self.method.warnings)

    def probe(self, name: str = "displacement") -> np.ndarray:
        return np.asarray(self.final.probes[name])


def solve(spec: dict, mesh: trimesh.Trimesh, *, grid: Grid | None = None, condition: bool = True) -> Solved:
    """Run one job through the pipeline's stages (see the module docstring); ``grid``: a pinned
    ``engine.grid.Grid`` instead of the spec's centred one. Raises what the engine raises."""
    from engine.analysis import run_analysis
    from engine.dg.problem import make_dg
    from engine.geometry.fractions import volume_fractions
    from engine.geometry.loading import load_surface
    from engine.grid import make_grid
    from engine.pipeline import Functions, Geometry
    from engine.runtime import init
    from engine.staggered.problem import make_staggered
    from schemas import parse_job

    parsed = parse_job(spec)
    init(parsed.solver.arch, parsed.solver.precision)
    t0 = time.perf_counter()
    surface = load_surface(mesh, filename=parsed.geometry.mesh)
    if grid is None:
        g = parsed.grid
        grid = make_grid(*surface.bounds, cell_size=g.cell_size, resolution=g.resolution, padding=g.padding)
    geo = Geometry(surface=surface, grid=grid, warnings=list(surface.warnings))
    if parsed.method.kind == "dg":
        from engine.geometry.slicing import slice_cells

        geo.cut_cells = slice_cells(surface, grid)
        geo.warnings += list(geo.cut_cells.warnings)
        method = make_dg(parsed, geo, Functions())
    else:
        geo.fractions = volume_fractions(surface, grid)
        geo.warnings += list(geo.fractions.warnings)
        method = make_staggered(parsed, geo, Functions())
    stats: list = []
    inner = method.solve

    def recorded(*args, **kwargs):
        state = inner(*args, **kwargs)
        stats.append(state.stats)
        return state

    method.solve = recorded  # every step's solve statistics, not only the last one's
    outcome = run_analysis(method, parsed.analysis, parsed.output, lambda *a: None)
    seconds = time.perf_counter() - t0
    t1 = time.perf_counter()
    cond = condition_number(method) if condition else math.nan
    return Solved(parsed, geo, method, outcome, stats, cond, seconds, time.perf_counter() - t1)


def condition_number(method) -> float:
    """2-norm condition estimate of the solved operator (NaN where rigid modes are free)."""
    if hasattr(method, "condition_estimate"):
        return float(method.condition_estimate())
    return staggered_condition(method)


def staggered_condition(m, tol: float = 1e-3) -> float:
    """kappa_2 of the staggered operator A (with its backward-Euler shift, if set) on the free DOFs:
    the largest eigenvalue by Lanczos on A, the smallest by LOBPCG on A / lambda_max preconditioned
    by the method's V-cycle, its residual tolerance tightened to 3% of the eigenvalue found until
    two passes agree to ``tol`` (relative; scale-free, so E does not change it). NaN when free rigid
    modes are projected off."""
    import scipy.sparse.linalg as spla

    from engine.staggered.operator import device_array

    if m.modes:
        return math.nan
    level = m.level
    idx = np.flatnonzero(level.free)
    n, shape = len(idx), (level.dim, level.size)
    out = level.zeros()

    def device(v: np.ndarray):
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


# ----------------------------------------------------------------------------- judging a run


FIELD_MESSAGE = re.compile(r"^[a-z_][\w.\[\]]*: \S")  # "solver: ...", "material.model: ...", "boundaries: ..."


def nonfinite(solved: Solved) -> list[str]:
    """Where the returned fields hold NaN/Inf: cells holding material, probes, surface, every step."""
    material = solved.material
    levels = [("final", solved.final)] + [(f"step {k + 1}", s) for k, s in enumerate(solved.outcome.steps)]
    bad = []
    for label, data in levels:
        for name, arr in data.cells.items():
            vals = np.asarray(arr)[material].reshape(int(material.sum()), -1)
            if not np.all(np.isfinite(vals)):
                bad.append(f"{label} cells/{name}: {int((~np.isfinite(vals)).any(axis=1).sum())} "
                           f"of {len(vals)} material cells")
        for where, group in (("probes", data.probes), ("surface", data.surface)):
            for name, arr in group.items():
                arr = np.asarray(arr)
                if not np.all(np.isfinite(arr)):
                    bad.append(f"{label} {where}/{name}: {int((~np.isfinite(arr)).sum())} of {arr.size} values")
    return bad


def judge(row: Row, solved: Solved) -> Row:
    """Fill the solver columns and the pass/fail of a finished run (finite fields, converged)."""
    stats = solved.stats
    row.iterations = max(s.iterations for s in stats)
    row.residual = max(s.residual for s in stats)
    row.condition = solved.condition
    row.seconds = solved.seconds
    row.values.update(iterations=row.iterations, residual=row.residual, condition=row.condition,
                      solves=len(stats), total_iterations=sum(s.iterations for s in stats),
                      condition_seconds=solved.condition_seconds, warnings=solved.warnings)
    problems = []
    bad = nonfinite(solved)
    if bad:
        problems.append("non-finite: " + "; ".join(bad))
    staggered = solved.spec.method.kind == "staggered"
    limit = RTOL if staggered else DG_RESIDUAL_LIMIT
    if not row.residual <= limit:
        what = "solver.rtol" if staggered else "DG_RESIDUAL_LIMIT"
        problems.append(f"returned with residual {row.residual:.3g} above {what} = {limit:g}, no error raised")
    elif not staggered and row.residual > RTOL:
        row.note = _join(row.note, f"direct-solve residual {row.residual:.2g} above solver.rtol {RTOL:g}")
    row.passed = not problems
    row.note = _join("; ".join(problems), row.note)
    return row


def guarded(row: Row, body: Callable[[Row], None], *, errors_allowed: bool = True, expect: type | None = None,
            match: str = "") -> Row:
    """Run ``body(row)`` (which solves and judges). A ``VoxelasticError`` whose message starts with
    the field it names passes as a named error (with ``errors_allowed``; ``expect``: only that class
    with ``match`` in its message passes, and a solved job fails); any other exception fails."""
    t0 = time.perf_counter()
    try:
        body(row)
        if expect is not None:
            row.passed = False
            row.note = _join(f"expected {expect.__name__}, but the job was solved", row.note)
    except VoxelasticError as exc:
        message = str(exc)
        row.seconds = time.perf_counter() - t0
        row.values["error"] = f"{type(exc).__name__}: {message}"
        if expect is not None:
            row.passed = isinstance(exc, expect) and match in message
        else:
            row.passed = errors_allowed and bool(FIELD_MESSAGE.match(message))
        row.quantity = row.quantity or type(exc).__name__
        why = "" if row.passed else ("(error does not name a field)" if errors_allowed and expect is None
                                     else "(the job is valid: no error expected)" if expect is None
                                     else f"(expected {expect.__name__} '{match}')")
        row.note = _join(why, f"{type(exc).__name__}: {message}")
    except Exception as exc:  # noqa: BLE001 -- an unclear error is a finding, reported as a failure
        row.seconds = time.perf_counter() - t0
        row.passed = False
        row.values["error"] = "".join(traceback.format_exception(exc))
        row.quantity = row.quantity or type(exc).__name__
        row.note = f"unclear error {type(exc).__name__}: {exc} (at {_origin(exc)})"
    return row


def _origin(exc: BaseException) -> str:
    """file:line of the innermost frame inside the project where ``exc`` was raised."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "/site-packages/" not in f.filename]
    f = frames[-1] if frames else traceback.extract_tb(exc.__traceback__)[-1]
    return f"{Path(f.filename).name}:{f.lineno}"


def _join(*parts: str) -> str:
    return "; ".join(p for p in parts if p)


# ----------------------------------------------------------------------------- cantilever cases


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


def _h_label(h: float) -> str:
    return f"h=W/{round(WIDTH / h)}"


def poisson_case(method: str, size: Size, nu: float) -> Row:
    """Cantilever at Poisson's ratio nu: tip deflection over Timoshenko beam theory (locking shows
    as a ratio falling with nu; beam theory itself ignores the clamp's 3D constraint)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    row = Row("poisson", method_label(spec_m), f"nu={nu:g} {_h_label(h)}")

    def body(row: Row) -> None:
        s = solve(cantilever_job(spec_m, h, bar, nu=nu), bar.mesh())
        beam = timoshenko_tip(TIP_TRACTION * WIDTH**2, LENGTH, WIDTH, E0, nu)
        tip = tip_deflection(s, bar)
        row.values.update(tip=tip, beam=beam, ratio=tip / beam)
        row.quantity = f"tip/beam={tip / beam:.4f}"
        judge(row, s)

    return guarded(row, body)


def youngs_case(method: str, size: Size) -> list[Row]:
    """E sweep: traction scaled with E (the displacement must not change) and one fixed traction
    (displacement * E must not change); a summary row per variant compares every material cell's
    displacement and the probes with the first E's, relative to its largest value."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    rows = []
    for variant in ("scaled", "fixed"):
        fields: list[np.ndarray] = []
        for E in size.youngs:
            traction = TIP_TRACTION * E / E0 if variant == "scaled" else TIP_TRACTION
            row = Row("youngs", method_label(spec_m), f"E={E:g} T={traction:g}")

            def body(row: Row, E=E, traction=traction, variant=variant) -> None:
                s = solve(cantilever_job(spec_m, h, bar, youngs=E, traction=traction), bar.mesh())
                scale = 1.0 if variant == "scaled" else E / E0  # both: the E0 run's displacement
                u = np.concatenate([s.final.cells["displacement"][s.material].ravel(), s.probe().ravel()]) * scale
                fields.append(u)
                tip = tip_deflection(s, bar) * scale
                row.values["tip"] = tip
                row.quantity = f"tip={tip:.6e}" if variant == "scaled" else f"tip*E/E0={tip:.6e}"
                judge(row, s)

            rows.append(guarded(row, body))
        what = "u" if variant == "scaled" else "u*E"
        summary = Row("youngs", method_label(spec_m), f"{variant} T: {what} over E={','.join(f'{e:g}' for e in size.youngs)}")
        if len(fields) == len(size.youngs):
            ref = fields[0]
            diff = max(float(np.abs(u - ref).max() / np.abs(ref).max()) for u in fields[1:])
            summary.quantity = f"max rel diff={diff:.2e}"
            summary.passed = diff <= SCALING_LIMIT
            summary.values.update(max_relative_difference=diff)
            summary.note = "" if summary.passed else f"above {SCALING_LIMIT:g}"
        else:
            summary.note = f"{len(size.youngs) - len(fields)} run(s) failed; nothing to compare"
        rows.append(summary)
    return rows


def offset_grid(bar_cells: tuple[int, int, int], h: float) -> Grid:
    """Pinned grid (spacing h [m]) holding the bar, whose corner sits at offset * h * (1, 0.6, 0.3)
    with offset in [0, 1): origin at -h, one padding cell plus one for the offset per axis."""
    from engine.grid import Grid

    return Grid(origin=(-h, -h, -h), spacing=h, shape=tuple(n + 3 for n in bar_cells))


def offset_bar(offset: float, h: float) -> Bar:
    """The cantilever with its corner at offset * h * (1, 0.6, 0.3) [m]."""
    return cantilever(origin=np.array([0.0, WIDTH / 2, WIDTH / 2]) + offset * h * np.array([1.0, 0.6, 0.3]))


def offsets_case(method: str, size: Size, offsets: tuple[float, ...] | None = None) -> list[Row]:
    """Cantilever translated by offset * h * (1, 0.6, 0.3) on one pinned grid; a summary row with the
    tip deflection's spread (max - min) / |mean| (must be < 5%)."""
    offsets = size.offsets if offsets is None else offsets
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    grid = offset_grid((round(LENGTH / h), round(WIDTH / h), round(WIDTH / h)), h)
    rows, tips, conds = [], [], []
    for off in offsets:
        bar = offset_bar(off, h)
        row = Row("offsets", method_label(spec_m), f"offset={off:g} h")

        def body(row: Row, bar=bar) -> None:
            s = solve(cantilever_job(spec_m, h, bar), bar.mesh(), grid=grid)
            tip = tip_deflection(s, bar)
            tips.append(tip)
            conds.append(s.condition)
            u = s.final.cells["displacement"][s.material]
            row.values.update(tip=tip, max_cell_displacement=float(np.abs(u).max()))
            row.quantity = f"tip={tip:.6e}"
            judge(row, s)

        rows.append(guarded(row, body))
    summary = Row("offsets", method_label(spec_m), f"{len(offsets)} offsets, {_h_label(h)}")
    if len(tips) == len(offsets):
        tips_a, cond = np.asarray(tips), np.asarray(conds)
        spread = float((tips_a.max() - tips_a.min()) / abs(tips_a.mean()))
        summary.quantity = f"tip spread={100 * spread:.2f}%"
        summary.passed = spread < OFFSET_SPREAD_LIMIT
        summary.condition = float(np.nanmax(cond)) if np.isfinite(cond).any() else math.nan
        summary.values.update(spread=spread, tips=tips, conditions=conds, offsets=list(offsets))
        summary.note = _join("" if summary.passed else f"spread above {100 * OFFSET_SPREAD_LIMIT:g}%",
                             f"tips {tips_a.min():.4e} .. {tips_a.max():.4e}; condition {np.nanmin(cond):.3g} .. "
                             f"{np.nanmax(cond):.3g}")
    else:
        summary.note = f"{len(offsets) - len(tips)} run(s) failed; no spread"
    rows.append(summary)
    return rows


def rotated_case(method: str, size: Size) -> list[Row]:
    """Long bar (aspect 8) along x and rotated 0.5 rad about (1, 2, 3): tip deflection over beam
    theory, and rotated over aligned (the grid's anisotropy and the staircase clamp)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    beam = timoshenko_tip(TIP_TRACTION * WIDTH**2, LONG, WIDTH, E0, NU0)
    rows, tips = [], {}
    for label, frame in (("aligned", ALIGNED), ("rotated", ROTATED)):
        bar = cantilever(LONG, frame)
        row = Row("rotated_bar", method_label(spec_m), f"{label} L={LONG:g} {_h_label(h)}")

        def body(row: Row, bar=bar, label=label) -> None:
            s = solve(cantilever_job(spec_m, h, bar), bar.mesh())
            tip = tip_deflection(s, bar)
            tips[label] = tip
            row.values.update(tip=tip, beam=beam, ratio=tip / beam)
            row.quantity = f"tip/beam={tip / beam:.4f}"
            judge(row, s)

        rows.append(guarded(row, body))
    if len(tips) == 2:
        rows[-1].values["rotated_over_aligned"] = tips["rotated"] / tips["aligned"]
        rows[-1].quantity += f" rotated/aligned={tips['rotated'] / tips['aligned']:.4f}"
    return rows


def large_strain_case(method: str, size: Size) -> list[Row]:
    """Bending to 10% surface strain at the clamp (linear beam theory) under a dead tip load, linear
    and corotated: tip deflection over linear beam theory and over the elastica (inextensible,
    no shear), and the largest normal strain at a cell centre (half a cell inside the surface)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    inertia = WIDTH**4 / 12
    force = 0.1 * E0 * inertia / (LENGTH * WIDTH / 2)  # M c / (E I) = 10% at the clamp
    traction = force / WIDTH**2
    beam = timoshenko_tip(force, LENGTH, WIDTH, E0, NU0)
    elastica = elastica_tip(force * LENGTH**2 / (E0 * inertia)) * LENGTH
    rows = []
    for model in ("linear", "corotated"):
        row = Row("large_strain", method_label(spec_m), f"{model} T={traction:.4g}")

        def body(row: Row, model=model) -> None:
            s = solve(cantilever_job(spec_m, h, bar, traction=traction, model=model,
                                     fields=("displacement", "strain", "stress")), bar.mesh())
            tip = tip_deflection(s, bar)
            strain = float(np.abs(s.final.cells["strain"][s.material][:, :3]).max())
            row.values.update(tip=tip, beam=beam, elastica=elastica, max_strain=strain)
            row.quantity = f"tip/beam={tip / beam:.3f} tip/elastica={tip / elastica:.3f} max|eps|={strain:.3f}"
            judge(row, s)

        rows.append(guarded(row, body))
    return rows


def dynamic_case(method: str, size: Size) -> list[Row]:
    """Sudden tip load on the cantilever at rest, backward Euler at each time step: the tip deflection
    over the steps relative to the static one (a static run first). Backward Euler dissipates, so it
    stays within [0, 2]; at dt >> the first bending period (0.8 s) it relaxes to 1."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    rows, static = [], {}
    ref = Row("dynamic", method_label(spec_m), "static reference")

    def reference(row: Row) -> None:
        s = solve(cantilever_job(spec_m, h, bar), bar.mesh())
        static["tip"] = tip_deflection(s, bar)
        row.values["tip"] = static["tip"]
        row.quantity = f"tip={static['tip']:.4e}"
        judge(row, s)

    rows.append(guarded(ref, reference))
    for dt in size.time_steps:
        row = Row("dynamic", method_label(spec_m), f"dt={dt:g} steps={size.steps}")

        def body(row: Row, dt=dt) -> None:
            analysis = {"kind": "dynamic", "time_step": dt, "steps": size.steps}
            s = solve(cantilever_job(spec_m, h, bar, analysis=analysis), bar.mesh())
            tips = np.array([float(np.asarray(st.probes["displacement"])[0] @ bar.frame[1]) for st in s.outcome.steps])
            row.values.update(tips=tips.tolist())
            if "tip" in static:
                ratio = tips / static["tip"]
                row.values.update(ratio_max=float(ratio.max()), ratio_min=float(ratio.min()), ratio_last=float(ratio[-1]))
                row.quantity = f"tip/static max={ratio.max():.3g} last={ratio[-1]:.3g}"
                if ratio.max() > 2.0 + 1e-6 or ratio.min() < -1e-6:
                    row.note = "tip outside [0, 2] x static: backward Euler should not overshoot"
            judge(row, s)

        rows.append(guarded(row, body))
    return rows


EXACT_SETUPS = {
    "aligned": "aligned L=2: end faces on grid planes",
    "offset": "offset 1e-6 h: end faces 1e-6 h past grid planes",
    "rotated": "rotated L=2: end faces off the axes",
}


def exact_faces_run(method: str, size: Size, setup: str) -> Row:
    """A cantilever whose tip load region (and DG clamp region) lies exactly on the end face, against
    the same job with regions FACE_SLACK h past it. Closed regions promise to hold a face lying on
    their boundary: the run passes when it is solved and its tip deflection equals the slack run's
    to 1e-6 (any error fails: the job is valid). Setups: EXACT_SETUPS."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    if setup == "offset":
        bar, grid = offset_bar(1e-6, h), offset_grid((round(LENGTH / h), round(WIDTH / h), round(WIDTH / h)), h)
    else:
        bar, grid = cantilever(LONG, ROTATED if setup == "rotated" else ALIGNED), None
    row = Row("exact_faces", method_label(spec_m), EXACT_SETUPS[setup])

    def body(row: Row) -> None:
        ref = solve(cantilever_job(spec_m, h, bar), bar.mesh(), grid=grid, condition=False)
        s = solve(cantilever_job(spec_m, h, bar, exact_faces=True), bar.mesh(), grid=grid, condition=False)
        ratio = tip_deflection(s, bar) / tip_deflection(ref, bar)
        row.values.update(ratio=ratio)
        row.quantity = f"tip exact/slack={ratio:.6f}"
        judge(row, s)
        if abs(ratio - 1) > 1e-6:
            row.passed = False
            row.note = _join(f"the exact regions changed the tip by {100 * (ratio - 1):+.3g}%", row.note)

    return guarded(row, body, errors_allowed=False)


def exact_faces_case(method: str, size: Size) -> list[Row]:
    return [exact_faces_run(method, size, setup) for setup in EXACT_SETUPS]


# ----------------------------------------------------------------------------- other geometries


def thin_wall_case(method: str, size: Size, placement: str) -> Row:
    """Closed hollow box (2 W + 0.3 h) x (2 W + 0.3 h) x (4 W + 0.3 h) with walls 0.3 h, on a pinned
    grid: every wall ``inside`` one cell layer (0.35 h .. 0.65 h of it) or ``across`` a grid plane
    (-0.15 h .. 0.15 h about it). Clamped at its base, pushed sideways on its top; top deflection
    over thin-walled beam theory (bending + shear of the two webs)."""
    from engine.grid import Grid

    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    t = 0.3 * h
    b, height = 2 * WIDTH + t, 4 * WIDTH + t  # far walls sit like the near ones: b / h = n + 0.3
    start = {"inside": 0.35, "across": 0.85}[placement]  # wall start past the first cell face [h]
    mesh = hollow_box((b, b, height), t)
    n_xy, n_z = (int(math.ceil(v / h + start)) + 2 for v in (b, height))
    grid = Grid(origin=(-(1 + start) * h,) * 3, spacing=h, shape=(n_xy, n_xy, n_z))
    boundaries = [
        {"kind": "displacement", "name": "base", "region": {"box": [[-1, -1, -1], [2, 2, clamp_depth(spec_m, h)]]},
         "value": [0, 0, 0]},
        {"kind": "traction", "name": "push", "region": {"box": [[-1, -1, height - FACE_SLACK * h], [2, 2, 2]]},
         "value": [TIP_TRACTION, 0, 0]},
    ]
    probes = [[b / 2, b / 2, height - t / 2], [t / 2, b / 2, height / 2]]
    inertia = (b**4 - (b - 2 * t) ** 4) / 12
    force = TIP_TRACTION * b * b
    beam = force * height**3 / (3 * E0 * inertia) + force * height / (E0 / (2 * (1 + NU0)) * 2 * b * t)
    row = Row("thin_wall", method_label(spec_m), f"walls 0.3h {placement} a cell, {_h_label(h)}")

    def body(row: Row) -> None:
        s = solve(job(spec_m, h, boundaries, probes=probes), mesh, grid=grid)
        top = float(s.probe()[0][0])
        row.values.update(top=top, beam=beam, ratio=top / beam)
        row.quantity = f"top/beam={top / beam:.3f}"
        judge(row, s)

    if method == "staggered" and placement == "inside":
        # one sample across each wall: nothing resists its transverse motion (957 zero-energy
        # motions at h = W/6, all found); the job must stop with the error that says so
        from engine.errors import ThinFeatureError

        return guarded(row, body, expect=ThinFeatureError, match="thinner than a grid cell")
    return guarded(row, body)


def hole_case(method: str, size: Size) -> Row:
    """Plate 1 x 0.5 x 0.125 m with a 0.2 m through hole (genus 1), clamped at x = 0, pulled at
    x = 1: end displacement over the holeless plate's T L / E, and the largest cell-centre sigma_xx
    over T (the net-section Kt at d / W = 0.4 is ~2.2, ~3.6 on the gross section; cell centres
    smear the peak)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    L, W, T = 1.0, 2 * WIDTH, WIDTH / 2
    mesh = holed_plate((L, W, T), 0.1)
    boundaries = [
        {"kind": "displacement", "name": "clamp", "region": {"box": [[-1, -1, -1], [clamp_depth(spec_m, h), 2, 2]]},
         "value": [0, 0, 0]},
        {"kind": "traction", "name": "pull", "region": {"box": [[L - FACE_SLACK * h, -1, -1], [2, 2, 2]]},
         "value": [TIP_TRACTION, 0, 0]},
    ]
    probes = [[L - 1e-3 * h, W / 2, T / 2], [L / 2, 0.05, T / 2]]
    row = Row("hole", method_label(spec_m), f"plate with a hole, {_h_label(h)}")

    def body(row: Row) -> None:
        s = solve(job(spec_m, h, boundaries, probes=probes), mesh)
        end = float(s.probe()[0][0])
        holeless = TIP_TRACTION * L / E0
        kt = float(np.abs(s.final.cells["stress"][s.material][:, 0]).max() / TIP_TRACTION)
        row.values.update(end=end, holeless=holeless, ratio=end / holeless, max_sxx_over_T=kt)
        row.quantity = f"end/(TL/E)={end / holeless:.3f} max sxx/T={kt:.2f}"
        judge(row, s)

    return guarded(row, body)


def free_body_run(method: str, size: Size, rotated: bool, balanced: bool) -> Row:
    """The long bar (along x or rotated) without displacement boundaries, pulled at both end faces
    by equal and opposite tractions (balanced: it must be solved off the rigid modes with a
    warning, and any error fails; elongation between the end probes over T L / E) or at its far
    end only (``UnbalancedLoadError`` with "do not balance" is required)."""
    from engine.solvers.rigid import UnbalancedLoadError

    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    label = "rotated" if rotated else "aligned"
    bar = cantilever(LONG, ROTATED if rotated else ALIGNED)
    far = {"kind": "traction", "name": "pull_far", "region": bar.end(+1, FACE_SLACK * h),
           "value": bar.direction(0, TIP_TRACTION)}
    near = {"kind": "traction", "name": "pull_near", "region": bar.end(-1, FACE_SLACK * h),
            "value": bar.direction(0, -TIP_TRACTION)}
    probes = [bar.point(1e-3 * h), bar.point(LONG - 1e-3 * h)]
    row = Row("free_body", method_label(spec_m), f"{'balanced' if balanced else 'unbalanced'}, {label} L={LONG:g}")

    def pulled(row: Row) -> None:
        s = solve(job(spec_m, h, [far, near] if balanced else [far], probes=probes), bar.mesh(), condition=balanced)
        u = s.probe()
        stretch = float((u[1] - u[0]) @ bar.frame[0])
        exact = TIP_TRACTION / E0 * (LONG - 2e-3 * h)
        warned = any("rigid-body mode" in w for w in s.warnings)
        row.values.update(stretch=stretch, exact=exact, ratio=stretch / exact, warned=warned)
        row.quantity = f"stretch/(TL/E)={stretch / exact:.4f}"
        judge(row, s)
        if warned:
            row.note = _join(row.note, "warned: rigid modes free, solved off them")
        else:
            row.passed = False
            row.note = _join("no rigid-body-mode warning", row.note)

    if balanced:
        return guarded(row, pulled, errors_allowed=False)
    return guarded(row, pulled, expect=UnbalancedLoadError, match="do not balance")


def free_body_case(method: str, size: Size) -> list[Row]:
    """Balanced along x and rotated, unbalanced rotated (see :func:`free_body_run`)."""
    return [free_body_run(method, size, False, True), free_body_run(method, size, True, True),
            free_body_run(method, size, True, False)]


# ----------------------------------------------------------------------------- the suite


CASES: dict[str, Callable[[str, Size], list[Row]]] = {
    "poisson": lambda method, size: [poisson_case(method, size, nu) for nu in size.poisson],
    "youngs": youngs_case,
    "offsets": offsets_case,
    "thin_wall": lambda method, size: [thin_wall_case(method, size, p) for p in ("inside", "across")],
    "rotated_bar": rotated_case,
    "large_strain": large_strain_case,
    "dynamic": dynamic_case,
    "hole": lambda method, size: [hole_case(method, size)],
    "free_body": free_body_case,
    "exact_faces": exact_faces_case,
}
METHODS = ("staggered", "dg")


def run_suite(size: Size, cases: list[str], methods: list[str], echo: Callable[[Row], None] | None = None) -> list[Row]:
    """Every case on every method, in order; ``echo`` sees each row as it is finished."""
    rows: list[Row] = []
    for name in cases:
        for method in methods:
            for row in CASES[name](method, size):
                rows.append(row)
                if echo is not None:
                    echo(row)
    return rows


COLUMNS = ("case", "method", "parameters", "its", "residual", "cond", "quantity", "result", "s", "note")


def _cells(row: Row, note_width: int) -> list[str]:
    def num(v, fmt: str) -> str:
        return "" if v is None else ("n/a" if isinstance(v, float) and math.isnan(v) else format(v, fmt))

    note = row.note if len(row.note) <= note_width else row.note[: note_width - 3] + "..."
    return [row.case, row.method, row.params, num(row.iterations, "d"), num(row.residual, ".1e"),
            num(row.condition, ".1e"), row.quantity, row.status(), f"{row.seconds:.1f}", note]


def table(rows: list[Row], note_width: int = 110) -> str:
    """The pass/fail table as aligned text (notes cut at ``note_width``; --json has them whole)."""
    body = [_cells(r, note_width) for r in rows]
    widths = [max([len(c)] + [len(b[i]) for b in body]) for i, c in enumerate(COLUMNS)]

    def line(cells: list[str]) -> str:
        return " | ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()

    return "\n".join([line(list(COLUMNS)), "-+-".join("-" * w for w in widths)] + [line(b) for b in body])


def _jsonable(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None if math.isnan(v) else str(v)
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return _jsonable(v.item())
    return v


def main(argv: list[str] | None = None) -> int:
    """Run the suite and print the table; exit status 1 when any row failed, else 0."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.stress", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller grids (the whole suite in ~3 min on 2 cores)")
    ap.add_argument("--json", type=Path, help="write every row, with its numbers and full notes, to this file")
    ap.add_argument("--case", action="append", choices=list(CASES), help="run only these cases (repeatable)")
    ap.add_argument("--method", action="append", choices=list(METHODS), help="run only these methods (repeatable)")
    ap.add_argument("--cells", type=int, nargs=2, metavar=("STAGGERED", "DG"),
                    help="cells across the bar's width per method instead of the size's (a refinement study)")
    a = ap.parse_args(argv)
    size = QUICK if a.quick else DEFAULT
    if a.cells:
        if min(a.cells) < 1:
            ap.error(f"--cells: expected two positive cell counts, got {a.cells}")
        size = replace(size, name=f"{size.name}, cells {a.cells[0]} / {a.cells[1]}", staggered_cells=a.cells[0],
                       dg_cells=a.cells[1])
    t0 = time.perf_counter()

    def echo(row: Row) -> None:
        print(f"  {row.status():12s} {row.case} / {row.method} / {row.params}: {row.quantity} ({row.seconds:.1f} s)",
              file=sys.stderr, flush=True)

    rows = run_suite(size, a.case or list(CASES), a.method or list(METHODS), echo)
    total = time.perf_counter() - t0
    print(table(rows))
    failed = [r for r in rows if not r.passed]
    print(f"\n{len(rows)} rows, {len(failed)} failed; size {size.name}; {total:.0f} s")
    if a.json:
        a.json.write_text(json.dumps({"size": _jsonable(asdict(size)), "seconds": total,
                                      "rows": [_jsonable(asdict(r)) for r in rows]}, indent=1))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
