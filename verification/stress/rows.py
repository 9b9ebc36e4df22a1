"""Rows of the stress suite's table, and how a run is judged.

A run passes when its fields (cells holding material, probes, surface, every time step) are
finite and the solve converged: staggered, every solve's relative residual within the requested
``solver.rtol``; DG (a direct solve), within ``DG_RESIDUAL_LIMIT``. A run that stops with a
``VoxelasticError`` whose message starts with the field it names (``solver: ...``,
``material.model: ...``) passes as a named error, except where the job is valid by construction
(free_body balanced, exact_faces); any other exception fails. Sweeps add a summary row: the
offsets' tip deflections must agree to 5%, the E sweep's displacements to 1e-8. Locking and the
beam-theory ratios are findings, recorded in the quantity column, not failures.
"""

from __future__ import annotations

import re
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from engine.errors import VoxelasticError
from verification.parts import OFFSETS

if TYPE_CHECKING:
    from verification.stress.running import Solved

# Relative residual a direct DG solve must reach: above it the factorisation lost more than 10
# of 16 digits (backward-stable Cholesky gives ~1e-16 times the condition number).
DG_RESIDUAL_LIMIT = 1e-6
OFFSET_SPREAD_LIMIT = 0.02  # (max - min) / |mean| of the tip deflection over the offsets (issue 17's floor)
SCALING_LIMIT = 1e-8  # relative difference of the E sweep's (scaled) displacements
RTOL = 1e-8  # solver.rtol of every job (the schema's default)
MAX_ITERATIONS = 5000


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
        """The result column: "FAIL", "pass", or "pass (error)" for a named error that passed."""
        if not self.passed:
            return "FAIL"
        return "pass (error)" if self.values.get("error") else "pass"


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
        row.note = join_notes(row.note, f"direct-solve residual {row.residual:.2g} above solver.rtol {RTOL:g}")
    row.passed = not problems
    row.note = join_notes("; ".join(problems), row.note)
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
            row.note = join_notes(f"expected {expect.__name__}, but the job was solved", row.note)
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
        row.note = join_notes(why, f"{type(exc).__name__}: {message}")
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


def join_notes(*parts: str) -> str:
    """The non-empty ``parts`` joined by "; " (a row's note grows one finding at a time)."""
    return "; ".join(p for p in parts if p)
