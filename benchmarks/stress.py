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

How a run is judged (finite fields, a converged solve, named errors): :mod:`verification.stress.rows`;
how it runs and how the condition is estimated: :mod:`verification.stress.running`. The cases
themselves live in :mod:`verification.stress` (installed with the package, so the tests run them
without importing the benchmarks); this module is the command: the case table, the runs, the output.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from verification.stress import (
    DEFAULT,
    QUICK,
    Row,
    Size,
    dynamic_case,
    exact_faces_case,
    free_body_case,
    hole_case,
    large_strain_case,
    offsets_case,
    poisson_case,
    rotated_case,
    thin_wall_case,
    youngs_case,
)

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
    """A row's table cells, in COLUMNS order (NaN prints as n/a, None as blank)."""

    def num(v: float | int | None, fmt: str) -> str:
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


def _jsonable(v: Any) -> Any:
    """``v`` with NaN as null, infinities as text and numpy scalars as Python numbers (strict JSON)."""
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
