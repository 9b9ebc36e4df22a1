"""Where the grid cuts the cantilever: sub-cell offsets, a bar rotated off the axes, load regions
exactly on the end faces.

- ``offsets``: the cantilever translated by 16 sub-cell offsets (down to 1e-6 of a cell) on a
  pinned grid; the tip deflection must vary by < 2%.
- ``rotated_bar``: a 2 m bar rotated off the grid axes vs the same bar along x and beam theory.
- ``exact_faces``: the cantilever's load (and DG clamp) regions exactly on its end faces instead
  of FACE_SLACK h past them; the tip must not change (to 1e-6).
"""

from __future__ import annotations

import math

import numpy as np

from verification.parts import (
    ALIGNED,
    E0,
    LENGTH,
    LONG,
    NU0,
    ROTATED,
    TIP_TRACTION,
    WIDTH,
    cantilever,
    offset_bar,
    offset_grid,
    timoshenko_tip,
)
from verification.stress.rows import OFFSET_SPREAD_LIMIT, Row, Size, guarded, join_notes, judge
from verification.stress.running import cantilever_job, cell_size, h_label, method_label, method_spec, solve, tip_deflection

def offsets_case(method: str, size: Size, offsets: tuple[float, ...] | None = None) -> list[Row]:
    """Cantilever translated by offset * h * (1, 0.6, 0.3) on one pinned grid; a summary row with the
    tip deflection's spread (max - min) / |mean| (must be < 2%)."""
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
    summary = Row("offsets", method_label(spec_m), f"{len(offsets)} offsets, {h_label(h)}")
    if len(tips) == len(offsets):
        tips_a, cond = np.asarray(tips), np.asarray(conds)
        spread = float((tips_a.max() - tips_a.min()) / abs(tips_a.mean()))
        summary.quantity = f"tip spread={100 * spread:.2f}%"
        summary.passed = spread < OFFSET_SPREAD_LIMIT
        summary.condition = float(np.nanmax(cond)) if np.isfinite(cond).any() else math.nan
        summary.values.update(spread=spread, tips=tips, conditions=conds, offsets=list(offsets))
        summary.note = join_notes("" if summary.passed else f"spread above {100 * OFFSET_SPREAD_LIMIT:g}%",
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
        row = Row("rotated_bar", method_label(spec_m), f"{label} L={LONG:g} {h_label(h)}")

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
            row.note = join_notes(f"the exact regions changed the tip by {100 * (ratio - 1):+.3g}%", row.note)

    return guarded(row, body, errors_allowed=False)


def exact_faces_case(method: str, size: Size) -> list[Row]:
    return [exact_faces_run(method, size, setup) for setup in EXACT_SETUPS]
