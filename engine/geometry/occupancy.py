"""How many grid cells a solid can occupy, from its surface alone (before any cut-cell work).

Memory estimates run before the geometry is computed (the CLI, the service's admission), and a
method that stores only the cells holding material needs their count, not the grid's: a sphere fills
about half of its bounding grid, a shell about 40%.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy import ndimage

from engine.geometry.surface import Surface
from engine.geometry.winding import inside
from engine.grid import Grid

# Grids above this many cells are counted on a grid coarsened by a power of two (5 bytes a cell to label
# its regions): the bound then holds each fine cell of a coarse cell that may hold solid.
LARGEST_COUNTED = 1 << 24


def occupied_cells(surface: Surface, grid: Grid) -> tuple[np.ndarray, int] | None:
    """(mask, factor): the cells that may hold solid bounded by ``surface``, as a bool mask over ``grid``
    coarsened by ``factor`` (1, 2, 4 ...: the least that keeps the mask within LARGEST_COUNTED cells;
    coarse cell J covers the fine cells factor J ... factor J + factor - 1 along each axis); None for an
    open surface (a solid by winding number, which may pass 1/2 inside a region near a hole) or none.

    A cell holding solid either has the surface crossing its interior -- then the bounding box of a
    facet, or of a piece of a facet split to the cell size, overlaps it -- or lies wholly inside.
    Cells no such box overlaps form connected regions the surface does not cross, each wholly inside
    or wholly outside a closed surface: one winding-number test per region decides.
    """
    if not surface.closed or len(surface.faces) == 0:
        return None
    factor = 1
    while math.prod(-(-n // factor) for n in grid.shape) > LARGEST_COUNTED:
        factor *= 2
    if factor > 1:
        grid = Grid(origin=grid.origin, spacing=grid.spacing * factor, shape=tuple(-(-n // factor) for n in grid.shape))
    mask = _crossed_cells(surface.vertices[surface.faces], grid)
    labels, count = ndimage.label(~mask)
    if count == 0:
        return mask, factor
    _, first = np.unique(labels.ravel(), return_index=True)  # one cell of each region (label 0: crossed)
    first = first[1:] if labels.ravel()[first[0]] == 0 else first
    centres = grid.sample_points(np.stack(np.unravel_index(first, grid.shape), axis=1))
    solid = np.concatenate([[False], inside(surface.vertices, surface.faces, centres)])
    mask |= solid[labels]
    return mask, factor


def occupied_cells_bound(surface: Surface, grid: Grid) -> int:
    """Upper bound on the cells of ``grid`` that hold solid bounded by ``surface`` (``occupied_cells``);
    every cell of the grid for an open surface."""
    found = occupied_cells(surface, grid)
    if found is None:
        return grid.num_cells
    mask, factor = found
    # fine cells of the grid inside each coarse cell, per axis (the last coarse cell may hang over)
    weight = np.ones(mask.shape)
    for a, n in enumerate(grid.shape):
        along = np.minimum(factor, n - factor * np.arange(mask.shape[a]))
        weight = weight * along.reshape([-1 if k == a else 1 for k in range(grid.dim)])
    return int(weight[mask].sum())


def occupied_tiles_bound(surface: Surface, grid: Grid, tile: int) -> int:
    """Upper bound on the tiles of ``tile``^d samples of the staggered index box (n + 1 per axis: a cell
    and its faces and edges on its low sides share an index) that hold a sample of a cell that may hold
    solid: the tiles a method storing only those stores. Every tile of the box for an open surface."""
    box = [n + 1 for n in grid.shape]
    found = occupied_cells(surface, grid)
    if found is None or tile % found[1]:
        return math.prod(-(-n // tile) for n in box)
    mask, factor = found
    # a cell's samples reach one index past it on each axis: pad one ahead, dilate by one cell upward
    reach = np.pad(mask, [(0, 1)] * grid.dim)
    for a in range(grid.dim):
        below = np.roll(reach, 1, axis=a)
        below[tuple(0 if k == a else slice(None) for k in range(grid.dim))] = False
        reach |= below
    k = tile // factor  # coarse cells per tile along an axis
    reach = np.pad(reach, [(0, -n % k) for n in reach.shape])
    blocks = reach.reshape([x for n in reach.shape for x in (n // k, k)])
    return int(blocks.any(axis=tuple(range(1, 2 * grid.dim, 2))).sum())


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
