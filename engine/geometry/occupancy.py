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
    or wholly outside a closed surface: one winding-number test per region decides. Open surfaces
    (solids by winding number, which may pass 1/2 inside such a region near a hole) get every cell of
    the grid, and so do grids above LARGEST_COUNTED cells.
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
# Pieces per grid cell beyond which splitting stops and every cell counts as crossed (the bound is then
# the grid's own): a coarse mesh of large slanted facets on a fine grid need not cost more than this.
_PIECES_PER_CELL = 16


def _crossed_cells(corners: np.ndarray, grid: Grid) -> np.ndarray:
    """Cells [*grid.shape] bool that the bounding box of some facet piece overlaps; facets ``corners``
    [k, d, d] [m] wider than a cell along an axis are bisected at their longest edge until none is, so
    a large slanted facet marks the cells along it, not its whole box."""
    d = grid.dim
    top = np.asarray(grid.shape) - 1
    crossed = np.zeros(grid.shape, dtype=bool)
    budget = len(corners) + _PIECES_PER_CELL * grid.num_cells
    pending = [corners[i:i + _CHUNK] for i in range(0, len(corners), _CHUNK)]
    while pending:
        piece = pending.pop()
        budget -= len(piece)
        if budget < 0:
            crossed[...] = True
            return crossed
        wide = (np.ptp(piece, axis=1) > grid.spacing).any(axis=1)
        done = piece[~wide]
        lo = np.clip(grid.cell_of(done.min(axis=1)), 0, top)
        hi = np.clip(grid.cell_of(done.max(axis=1)), 0, top)
        for offset in itertools.product((0, 1), repeat=d):  # a box within 2^d cells
            crossed[tuple(np.minimum(lo + offset, hi).T)] = True
        if wide.any():
            split = _bisected(piece[wide])
            pending += [split[i:i + _CHUNK] for i in range(0, len(split), _CHUNK)]
    return crossed


def _bisected(corners: np.ndarray) -> np.ndarray:
    """The facets [k, d, d] (triangles or segments) split in two at the midpoint of their longest edge:
    [2k, d, d]."""
    d = corners.shape[1]
    if d == 2:
        mid = corners.mean(axis=1)
        return np.concatenate([np.stack([corners[:, 0], mid], axis=1), np.stack([mid, corners[:, 1]], axis=1)])
    # rotate each triangle's corners so that its longest edge runs from corner 0 to corner 1
    edge = np.stack([np.linalg.norm(corners[:, (j + 1) % 3] - corners[:, j], axis=1) for j in range(3)], axis=1)
    first = edge.argmax(axis=1)
    order = (first[:, None] + np.arange(3)[None, :]) % 3
    a, b, c = (np.take_along_axis(corners, order[:, j, None, None], axis=1)[:, 0] for j in range(3))
    m = (a + b) / 2
    return np.concatenate([np.stack([a, m, c], axis=1), np.stack([m, b, c], axis=1)])
