"""The method contract: what the pipeline and the analysis drivers ask of a discretization, and the
registry they find methods in.

A method is a package under ``engine/`` providing

    estimate_memory(grid, method_spec, surface=None, occupied=None) -> int
                                                  peak bytes, before any cut-cell work (``surface``: the
                                                  solid's, for methods that store only occupied cells;
                                                  ``occupied``: their count once the geometry knows it)
    a builder (spec, geo, functions, progress) -> Method    the discretization of a validated job

(imported only when a job asks for the method), and one :class:`MethodEntry` in :data:`METHODS`:
the schema's ``method.kind``, the cut-cell geometry it discretizes (``"fractions"``: exact volume
fractions of every staggered control volume; ``"cut_cells"``: every cell's pieces as polyhedra),
the dimensions it supports and where those two functions are (and, optionally, ``checks(spec, grid)``:
limits of its own on a validated job, such as the values its solve precision holds). The pipeline,
the admission checks and the CLI go through the registry and never name a method. Adding one: docs/design-notes.md, "Adding a method".
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from .errors import MethodUnavailableError
from .output import FieldData
from .solvers.linear import SolveStats

if TYPE_CHECKING:
    from .grid import Grid


# progress(part, share) of a method's setup: the part starting now and the share of the setup done
Setup = Callable[[str, float], None]


def no_progress(part: str, share: float) -> None:
    """The Setup of a caller that follows no progress."""


@dataclass
class State:
    """One solve's result: the method's unknowns ``u`` (its own layout: staggered [d, size] face
    samples, DG [E, d, n] coefficients), the solve's statistics and wall time [s]; ``rotations``
    [E, 3, 3] of corotated elements where the method warps its stiffness (else None);
    ``load_scale``: the factor the surface loads had (the tractions the surface stress carries);
    ``value_scale``: the prescribed values' (what a held cell's flux through its wall was)."""

    u: np.ndarray
    stats: SolveStats
    seconds: float
    rotations: np.ndarray | None = None
    load_scale: float = 1.0
    value_scale: float = 1.0


class Method(Protocol):
    """A discretization of one job on its geometry, solved as often as its analysis needs."""

    warnings: list[str]

    def solve(self, load_scale: float = 1.0, value_scale: float = 1.0, x0: np.ndarray | None = None,
              inertia: np.ndarray | None = None, on_iteration: Callable[[int, float], None] | None = None) -> State:
        """The unknowns minimising the energy with loads scaled by ``load_scale`` and prescribed
        values by ``value_scale``, from ``x0``; ``inertia`` the predicted u^k + dt v^k of a
        backward-Euler step (after :meth:`set_time_step`)."""
        ...

    def set_time_step(self, dt: float | None) -> None:
        """Backward Euler with step dt [s] (adds M / dt^2); None goes back to statics."""
        ...

    def fields(self, state: State, names: list[str], probes: np.ndarray | None, surface: bool,
               time_value: float | None = None, velocity: np.ndarray | None = None) -> FieldData:
        """The output fields ``names`` at cells, at ``probes`` [P, d] [m] and on the surface."""
        ...


@dataclass(frozen=True)
class MethodEntry:
    """A method as the registry knows it: ``kind`` (the spec's ``method.kind``), the ``geometry``
    it discretizes, the ``dimensions`` it supports, and where its builder and memory estimate live
    (``"module:function"``, imported when first asked for)."""

    kind: str
    geometry: str
    dimensions: tuple[int, ...]
    builder: str
    memory: str
    checks: str | None = None

    def check_job(self, spec: Any, grid: Grid) -> None:
        """The method's own limits on a validated job on its grid, found before any work (the range of
        values its solve precision holds): a VoxelasticError naming the field."""
        if self.checks is not None:
            _load(self.checks)(spec, grid)

    def estimate_memory(self, grid: Grid, method_spec: Any, surface: Any = None, occupied: int | None = None) -> int:
        """Upper estimate of the job's peak memory [bytes] from the grid, the spec's ``method`` and, when
        given, the solid's ``surface`` or its count of ``occupied`` cells (pieces of cells)."""
        return int(_load(self.memory)(grid, method_spec, surface=surface, occupied=occupied))

    def build(self, spec: Any, geo: Any, functions: Any, progress: Setup | None = None) -> Method:
        """The method's discretization of the validated job ``spec`` on its prepared geometry;
        ``progress(part, share)`` hears of its parts as they start (share of the setup done, 0..1)."""
        return _load(self.builder)(spec, geo, functions, progress=progress)

    def check_dimension(self, dimension: int) -> None:
        """A job of another dimension is an error naming the field and the methods that take it."""
        if dimension not in self.dimensions:
            others = [m.kind for m in METHODS.values() if dimension in m.dimensions]
            raise MethodUnavailableError(
                f"method.kind: '{self.kind}' solves dimension {' or '.join(map(str, self.dimensions))} only; "
                f"for dimension {dimension} use {' or '.join(repr(k) for k in others) or 'none'}"
            )


def _load(target: str) -> Callable:
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


METHODS: dict[str, MethodEntry] = {
    "staggered": MethodEntry("staggered", geometry="fractions", dimensions=(2, 3),
                             builder="engine.staggered.problem:make_staggered",
                             memory="engine.staggered.problem:estimate_memory",
                             checks="engine.staggered.precision:check_job"),
    "dg": MethodEntry("dg", geometry="cut_cells", dimensions=(3,),
                      builder="engine.dg.problem:make_dg", memory="engine.dg.problem:estimate_memory"),
}


def method_entry(kind: str) -> MethodEntry:
    """The registry's entry for ``method.kind`` (an unknown kind is a named error)."""
    try:
        return METHODS[kind]
    except KeyError:
        raise MethodUnavailableError(
            f"method.kind: '{kind}' is not a method of this engine; one of {', '.join(sorted(METHODS))}"
        ) from None
