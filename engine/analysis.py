"""Static, quasi-static and dynamic (backward Euler) drivers shared by the methods.

A method supplies ``solve(load_scale, value_scale, x0, inertia, on_iteration) -> state`` (a state
has ``u``, the solved DOF array, and ``stats``), ``set_time_step(dt)`` and ``fields(state, names,
probes, surface, time_value, velocity) -> FieldData``. The drivers own the stepping: quasi-static
runs scale loads and prescribed displacements by k / n and warm-start each step from the last;
dynamic runs minimise (1 / 2 dt^2) |u - u_hat|_M^2 + E(u) per step (thesis section 4.4) with
u_hat = u^k + dt v^k and v^{k+1} = (u^{k+1} - u^k) / dt. Static runs never build a mass.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .method import Method
from .output import FieldData

Progress = Callable[[str, float, dict], None]
# A finished step is reported when this long [s] has passed since the last report: a direct solve
# takes one CG step, so the every-10-iterations reports never came during a 400-step dynamic run
STEP_REPORT_SECONDS = 0.5


@dataclass
class AnalysisResult:
    """final: the last state's fields; steps: one FieldData per kept step (``output.every``; empty
    for static runs);
    iterations / residual: of the last solve; total_iterations over all steps; solve_seconds."""

    final: FieldData
    steps: list[FieldData] = field(default_factory=list)
    iterations: int = 0
    residual: float = 0.0
    total_iterations: int = 0
    solve_seconds: float = 0.0


def run_analysis(method: Method, analysis, output, progress: Progress, start: float = 0.4,
                 end: float = 0.95) -> AnalysisResult:
    """Drive ``method`` through ``analysis`` (a schemas analysis model) producing ``output``'s fields."""
    names = list(output.fields)
    probes = np.asarray(output.probes, dtype=float) if output.probes else None
    kind = analysis.kind
    steps = 1 if kind == "static" else analysis.steps
    result = AnalysisResult(final=FieldData())

    def kept(k: int) -> bool:  # output.every: steps n, 2n, ... and the last; the others' fields never made
        return (k + 1) % output.every == 0 or k + 1 == steps

    def report(k: int):
        def on_iteration(it: int, residual: float) -> None:
            if it % 10 == 0:
                progress("solve", start + (end - start) * (k + min(it / 200, 0.99)) / steps,
                         {"step": k + 1, "steps": steps, "iterations": it, "residual": residual})
        return on_iteration

    last_report = [time.perf_counter()]

    def record(state, k: int) -> None:
        result.iterations, result.residual = state.stats.iterations, state.stats.residual
        result.total_iterations += state.stats.iterations
        result.solve_seconds += state.seconds
        if k + 1 < steps and time.perf_counter() - last_report[0] >= STEP_REPORT_SECONDS:
            last_report[0] = time.perf_counter()
            progress("solve", start + (end - start) * (k + 1) / steps,
                     {"step": k + 1, "steps": steps, "iterations": result.iterations, "residual": result.residual})

    if kind == "static":
        state = method.solve(1.0, 1.0, on_iteration=report(0))
        record(state, 0)
        result.final = method.fields(state, names, probes, output.surface)
    elif kind == "quasistatic":
        prev = None
        for k in range(steps):
            s = (k + 1) / steps
            state = method.solve(s, s, x0=prev, on_iteration=report(k))
            record(state, k)
            prev = state.u
            if kept(k):
                result.steps.append(method.fields(state, names, probes, output.surface, time_value=s))
        result.final = _without_time(result.steps[-1])
    else:
        dt = analysis.time_step
        method.set_time_step(dt)
        u = v = None
        for k in range(steps):
            predicted = None if u is None else u + dt * v
            state = method.solve(1.0, 1.0, x0=predicted, inertia=predicted if predicted is not None else 0.0,
                                 on_iteration=report(k))
            record(state, k)
            v = (state.u - (u if u is not None else 0.0)) / dt
            u = state.u
            if kept(k):
                result.steps.append(method.fields(state, names, probes, output.surface, time_value=(k + 1) * dt,
                                                  velocity=v))
        result.final = _without_time(result.steps[-1])
    progress("solve", end, {"iterations": result.iterations, "residual": result.residual})
    return result


def _without_time(level: FieldData) -> FieldData:
    return FieldData(cells=level.cells, probes=level.probes, surface=level.surface, time=None)
