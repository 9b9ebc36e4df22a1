"""How many grid cells a solid can occupy, from its surface alone (before any cut-cell work).

Memory estimates run before the geometry is computed (the CLI, the service's admission), and a
method that stores only the cells holding material needs their count, not the grid's: a sphere fills
about half of its bounding grid, a shell about 40%.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage

from engine.geometry.surface import Surface
from engine.geometry.winding import inside
from engine.grid import Grid

# Grids above this many cells get no count: 5 bytes a cell to label the regions, and a method that stores
# only occupied cells (DG: 100 unknowns a cell at degree 2) could not solve a tenth of that grid anyway.
LARGEST_COUNTED = 1 << 24


def occupied_cells_bound(surface: Surface, grid: Grid) -> int:
    """Upper bound on the cells of ``grid`` that hold solid bounded by ``surface``.

    A cell holding solid either has the surface crossing its interior -- then the bounding box of a
    facet, or of a piece of a facet split to the cell size, overlaps it -- or lies wholly inside.
    Cells no such box overlaps form connected regions the surface does not cross, each wholly inside
    or wholly outside a closed surface: one winding-number test per region decides. Open surfaces (solids by winding number, which may pass 1/2 inside such a
    region near a hole) get every cell of the grid, and so do grids above LARGEST_COUNTED cells.
    """
    if not surface.closed or len(surface.faces) == 0 or grid.num_cells > LARGEST_COUNTED:
        return grid.num_cells
    crossed = _crossed_cells(surface.vertices[surface.faces], grid)
    labels, count = ndimage.label(~crossed)
    if count == 0:
        return int(crossed.sum())
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    _, first = np.unique(labels.ravel(), return_index=True)  # one cell of each region (label 0: crossed)
    first = first[1:] if labels.ravel()[first[0]] == 0 else first
    centres = grid.sample_points(np.stack(np.unravel_index(first, grid.shape), axis=1))
    solid = inside(surface.vertices, surface.faces, centres)
    return int(crossed.sum() + sizes[solid].sum())


# Facet pieces split per round, at most: bounds the memory of splitting a coarse mesh on a fine grid.
_CHUNK = 1 << 16


def _crossed_cells(corners: np.ndarray, grid: Grid) -> np.ndarray:
    """Cells [*grid.shape] bool that the bounding box of some facet piece overlaps; facets ``corners``
    [k, d, d] [m] wider than a cell along an axis are split at their edges' midpoints until none is
    (4 children of a triangle, 2 of a segment), so a large slanted facet marks the cells along it,
    not its whole box."""
    d = grid.dim
    top = np.asarray(grid.shape) - 1
    crossed = np.zeros(grid.shape, dtype=bool)
    pending = [corners[i:i + _CHUNK] for i in range(0, len(corners), _CHUNK)]
    while pending:
        piece = pending.pop()
        wide = (np.ptp(piece, axis=1) > grid.spacing).any(axis=1)
        done = piece[~wide]
        lo = np.clip(grid.cell_of(done.min(axis=1)), 0, top)
        hi = np.clip(grid.cell_of(done.max(axis=1)), 0, top)
        for offset in itertools.product((0, 1), repeat=d):  # a box within 2^d cells
            crossed[tuple(np.minimum(lo + offset, hi).T)] = True
        if wide.any():
            split = _halved(piece[wide])
            pending += [split[i:i + _CHUNK] for i in range(0, len(split), _CHUNK)]
    return crossed


def _halved(corners: np.ndarray) -> np.ndarray:
    """The facets [k, d, d] split at their edges' midpoints: [4k, 3, 3] triangles or [2k, 2, 2] segments."""
    if corners.shape[1] == 2:
        mid = corners.mean(axis=1)
        return np.concatenate([np.stack([corners[:, 0], mid], axis=1), np.stack([mid, corners[:, 1]], axis=1)])
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
    return np.concatenate([np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
