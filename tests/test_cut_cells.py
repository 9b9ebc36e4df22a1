"""Where the surface cuts cells: loads and probes that read the samples beyond a face (ghost samples),
on the stress suite's cantilever (1 m x 0.25 m x 0.25 m, clamped at x = 0, a tip traction of 100 Pa
along z; staggered, h = W / 8).

    .venv/bin/python -m pytest -q tests/test_cut_cells.py

Measured before them (commit 4cef26f): 7.14% tip spread over the suite's 16 sub-cell offsets, and
a tip face just past a grid plane read 4.9% more than one on it (the load and the probe took the
samples h/2 inside).
"""

import numpy as np

from verification import parts as P
from verification import stress as S

CELLS = 8  # across the width W
SIZE = S.Size("cut cells", staggered_cells=CELLS, dg_cells=4, dg_degree=2)


def tips(bars, grid) -> np.ndarray:
    spec = S.method_spec("staggered", SIZE)
    h = S.cell_size("staggered", SIZE)
    out = []
    for bar in bars:
        s = S.solve(S.cantilever_job(spec, h, bar), bar.mesh(), grid=grid, condition=False)
        out.append(S.tip_deflection(s, bar))
    return np.asarray(out)


def spread(values: np.ndarray) -> float:
    return float((values.max() - values.min()) / abs(values.mean()))


def test_a_tip_moved_through_its_cell_follows_beam_theory():
    """The clamp stays on a grid plane and the tip face moves through a cell (length L + s h): the tip
    over Timoshenko's for each length stays put: measured 0.986 ... 0.988 (0.26%, the step from s = 0
    to 1e-6); without ghost samples the load and the probe of a tip face past the middle of its cell
    read the samples up to h/2 inside."""
    h = S.cell_size("staggered", SIZE)
    grid = P.offset_grid((round(P.LENGTH / h) + 1, CELLS, CELLS), h)
    lengths = P.LENGTH + h * np.array([0.0, 1e-6, 0.25, 0.5, 0.75, 1 - 1e-6])
    bars = [P.cantilever(length=L, origin=(0.0, P.WIDTH / 2, P.WIDTH / 2)) for L in lengths]
    beam = [P.timoshenko_tip(P.TIP_TRACTION * P.WIDTH**2, L, P.WIDTH, P.E0, P.NU0) for L in lengths]
    ratio = tips(bars, grid) / beam
    assert spread(ratio) < 4e-3, ratio


def test_sixteen_sub_cell_offsets_move_the_tip_by_less_than_3_percent():
    """The stress suite's offsets row at W / 8 (corner at s h (1, 0.6, 0.3)): measured 2.71% (2.78% before
    every body's load got its moment couple, 7.14% before the ghost samples). Not the < 2% the boundary
    issue asks: what is left comes from partial cell layers along the load (their strain read at the
    cell centre stiffens bending; 4.7% over offsets along the load alone) and from a clamp face inside
    a cell (1.5% along the axis alone; docs/benchmarks.md)."""
    h = S.cell_size("staggered", SIZE)
    grid = P.offset_grid((round(P.LENGTH / h), CELLS, CELLS), h)
    assert spread(tips([P.offset_bar(s, h) for s in P.OFFSETS], grid)) < 0.03
