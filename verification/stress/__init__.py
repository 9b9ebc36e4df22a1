"""The numerical-stability stress suite's cases (issue 6, part 3), one module per family.

Every case runs on the staggered method or on DG (degree 2, interior penalty, eta = 20) at a
:class:`Size` (cells across the bar's width per method) and returns judged :class:`Row` s:

- :mod:`.rows`: the row, the sizes, the limits, and how a run is judged (:func:`judge`, :func:`guarded`);
- :mod:`.running`: one job through the pipeline's stages (:func:`solve`), the condition estimate,
  the cantilever's job;
- :mod:`.materials`: ``poisson``, ``youngs``, ``large_strain``;
- :mod:`.placement`: ``offsets``, ``rotated_bar``, ``exact_faces``;
- :mod:`.shapes`: ``thin_wall``, ``hole``;
- :mod:`.free_body`: ``free_body``;
- :mod:`.dynamics`: ``dynamic``.

``python -m benchmarks.stress`` runs the whole suite and prints the table; tests/test_stress.py
runs the cheap cases.
"""

from verification.stress.dynamics import dynamic_case
from verification.stress.free_body import free_body_case, free_body_run
from verification.stress.materials import large_strain_case, poisson_case, youngs_case
from verification.stress.placement import EXACT_SETUPS, exact_faces_case, exact_faces_run, offsets_case, rotated_case
from verification.stress.rows import (
    DEFAULT,
    DG_RESIDUAL_LIMIT,
    MAX_ITERATIONS,
    OFFSET_SPREAD_LIMIT,
    QUICK,
    RTOL,
    SCALING_LIMIT,
    Row,
    Size,
    guarded,
    judge,
)
from verification.stress.running import (
    FACE_SLACK,
    Solved,
    cantilever_job,
    cell_size,
    job,
    method_label,
    method_spec,
    solve,
    tip_deflection,
)
from verification.stress.shapes import hole_case, thin_wall_case

__all__ = [
    "DEFAULT", "DG_RESIDUAL_LIMIT", "EXACT_SETUPS", "FACE_SLACK", "MAX_ITERATIONS", "OFFSET_SPREAD_LIMIT", "QUICK",
    "RTOL", "SCALING_LIMIT", "Row", "Size", "Solved", "cantilever_job", "cell_size", "dynamic_case",
    "exact_faces_case", "exact_faces_run", "free_body_case", "free_body_run", "guarded", "hole_case", "job",
    "judge", "large_strain_case", "method_label", "method_spec", "offsets_case", "poisson_case", "rotated_case",
    "solve", "thin_wall_case", "tip_deflection", "youngs_case",
]
