"""Partial cell layers along flat faces: how much they stiffen bending, said before the solve.

A face of the solid parallel to a grid plane that falls inside a cell layer leaves every cell of
that layer partly filled. The energy reads those cells' strains at their centres, up to h/2 outside
the solid, so bending across the layers is stiffer by about 6 s (1 - s) (h / W)^2 per partial layer
of fill s in a part W thick (measured: 2.3% per half-filled layer at W = 8 h, the stress suite's
offsets; 7% on the bundled cantilever at its own resolution). ``flat_layers`` moves those strains'
weights to the solid's first moments where the layer's lines end on loaded or held faces normal to
them; where they end on free or curved ones (a cantilever loaded along its length only) the method
warns, with the cell size that fills the layers (docs/design-notes.md, "Partial layers along flat
faces").
"""

from __future__ import annotations

import numpy as np

from .operator import Level

LAYER_WARNING = 0.02  # estimated stiffening of bending (relative) above which the user is told
FLAT = 0.02  # a layer cell's neighbours along the face hold its fill to this
CUT = 1e-9  # fills within this of 0 or 1 are not partial
MIN_CELLS = 8  # fewer layer cells than this on an axis are no flat face
SAMPLE = 2000  # layer cells whose columns are walked per axis (the median needs no more; 256^3 has 4e5)
MIN_THICK = 4.0  # thinner parts (in cells) are the thin-solid warning's: the estimate is asymptotic in h / W
AXES = "xyz"


def fills_at(level: Level, index: np.ndarray) -> np.ndarray:
    """Cell fractions [N] at grid indices [N, d]; 0 outside the kept tiles."""
    pos = level.layout.positions(index)
    return np.where(pos >= 0, level.vc_host[np.maximum(pos, 0)], 0.0)


def run_ends(level: Level, index: np.ndarray, axis: int) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Along ``axis`` through each cell of ``index`` [N, d], the contiguous run of cells holding
    material: (its solid length in cells [N], the fills of its low and high end cells [N] each, the
    grid indices of those end cells [N, d] each)."""
    step = np.eye(level.dim, dtype=np.int64)[axis]
    own = fills_at(level, index)
    total = own.copy()
    fills, ends = [], []
    for sign in (-1, 1):
        here = index.copy()
        last = own.copy()
        going = np.ones(len(index), dtype=bool)
        for _ in range(max(level.layout.box)):
            if not going.any():
                break
            nxt = fills_at(level, here[going] + sign * step)
            alive = nxt > 0
            rows = np.nonzero(going)[0]
            total[rows[alive]] += nxt[alive]
            last[rows[alive]] = nxt[alive]
            here[rows[alive]] += sign * step
            going[rows[~alive]] = False
        fills.append(last)
        ends.append(here)
    return total, fills, ends


def partial_layer_warning(level: Level, corrected: np.ndarray | None = None) -> list[str]:
    """A warning when faces parallel to grid planes leave partial cell layers whose estimated bending
    stiffening 6 sum s (1 - s) (h / W)^2 (median over the faces' cells, worst axis) exceeds
    LAYER_WARNING. ``corrected``: layout positions of cells whose weights ``flat_layers`` moved
    (their layers' bending is corrected, so they do not count)."""
    d, lay, vc, h = level.dim, level.layout, level.vc_host, level.spacing
    pos = np.nonzero((vc > CUT) & (vc < 1.0 - CUT))[0]
    pos = pos[pos < lay.count * lay.tile_size]
    if corrected is not None:
        pos = pos[~np.isin(pos, corrected)]
    if not len(pos):
        return []
    index = lay.index_of(pos).astype(np.int64)
    fill = vc[pos]
    eye = np.eye(d, dtype=np.int64)
    worst = None
    for k in range(d):
        lo, hi = fills_at(level, index - eye[k]), fills_at(level, index + eye[k])
        layer = np.nonzero(((lo >= 1.0 - CUT) & (hi <= 0.0)) | ((hi >= 1.0 - CUT) & (lo <= 0.0)))[0]
        for j in range(d):  # the face's neighbours along it hold the same fill (a flat face, not an edge)
            if j != k:
                for sign in (-1, 1):
                    layer = layer[np.abs(fills_at(level, index[layer] + sign * eye[j]) - fill[layer]) <= FLAT]
        if len(layer) < MIN_CELLS:
            continue
        layer = layer[np.linspace(0, len(layer) - 1, min(len(layer), SAMPLE)).astype(np.int64)]
        cells, (first, last), _ = run_ends(level, index[layer], k)
        keep = cells >= MIN_THICK
        if keep.sum() < MIN_CELLS:
            continue
        cells, first, last, layer = cells[keep], first[keep], last[keep], layer[keep]
        stiffening = 6.0 * (first * (1 - first) + last * (1 - last)) / cells**2
        estimate = float(np.median(stiffening))
        if worst is None or estimate > worst[0]:
            worst = (estimate, k, float(np.median(cells)), float(np.median(fill[layer])))
    if worst is None or worst[0] < LAYER_WARNING:
        return []
    estimate, k, cells, s = worst
    width = cells * h
    whole = width / np.ceil(cells - 1e-9)
    return [f"faces of the solid normal to {AXES[k]} fall inside cell layers (fill {s:.2f}; the solid is {cells:.3g} "
            f"cells thick across them): bending across those layers comes out about {100 * estimate:.1f}% too stiff "
            f"(6 s (1 - s) (h / W)^2 per partial layer); a cell size that divides the {width:.4g} m thickness "
            f"(grid.cell_size {whole:.4g} m puts those faces on grid planes where they bound the part), a finer grid "
            "or method.kind 'dg' removes it"]
