"""Each divergence-form row's share of its load's patch.

A row's divergence-form force (``StaggeredElasticity._divergence_load``) is the traction of all the
surface crossing its control volumes, which lie in the support of the row's multilinear hat. Where
some of that surface is not in the load's patch (the patch's rim inside a surface, the facets a
``facing`` leaves out, another surface within a cell) the row keeps the patch's share of it: the
part of sum_q w_q phi(x_q) |t_a(x_q)| that the patch's points make (phi the row's hat, t the load's
traction, surface quadrature at h). On a flat face the hats add up to one, so the shares give the
patch's exact resultant up to the quadrature of the hats' kinks.

Rows that see only the patch get 1 without any scatter: the rest of the surface is cut into pieces
no longer than h and only the pieces within a block of BLOCK cells of a patch point are integrated,
so a closed patch away from the rest (a pressure inside a shell) costs one quadrature of the patch.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..boundary import SurfaceLoad, facet_measures, select_patch, surface_quadrature
from ..geometry.surface import Surface
from ..grid import Grid
from ..subdivision import subdivided
from . import sampling
from .layout import TileLayout

# Cells per side of the blocks of the nearness test. A rest piece (edges <= h) that meets the hat of a
# row a patch point reaches lies within 3 h of that point; blocks of 4 h and their neighbours cover it.
BLOCK = 4
CHUNK = 1 << 16  # pieces at a time while the patch's cells and blocks are found


def patch_shares(surface: Surface, load: SurfaceLoad, grid: Grid, layout: TileLayout,
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per component a: (positions [K] in ``layout``, shares [K] in (0, 1]) of the rows that see
    ``load``'s patch; rows not listed see none of it."""
    d, h = grid.dim, grid.spacing
    facets = surface.vertices[surface.faces]
    pieces, source = select_patch(load.region, facets, load.name)
    pieces = pieces.reshape(-1, d, d)
    covered = np.bincount(source, weights=facet_measures(pieces), minlength=len(facets))
    partly = covered < (1 - 1e-9) * facet_measures(facets)  # facets the patch takes in part or not at all
    cut = partly[source]  # the patch's pieces of facets it takes only in part
    # the patch in the pieces its quadrature at h integrates (edges <= h / 2), split as above
    whole, taken = subdivided(pieces[~cut], 0.5 * h), subdivided(pieces[cut], 0.5 * h)
    blocks = _Blocks(grid)
    cells, near_patch = [], []
    for group in (whole, taken):
        for start in range(0, len(group), CHUNK):
            corners = group[start:start + CHUNK].reshape(-1, d)
            cells.append(_cells(grid, corners))
            near_patch.append(blocks.around(corners))
    seeing = _rows_reached(grid, np.unique(np.concatenate(cells)))  # 1 unless the rest is near
    near_patch = np.unique(np.concatenate(near_patch))
    others = facets[partly]
    rest = [subdivided(others[start:start + CHUNK], h) for start in range(0, len(others), CHUNK)]
    rest = np.concatenate([r[_touching(blocks, r, near_patch)] for r in rest] or [np.zeros((0, d, d))])
    if not len(rest):
        return [(layout_rows, np.ones(len(layout_rows))) for layout_rows in _positions(layout, seeing)]

    def weighed(near: np.ndarray) -> list:
        x, w, n = surface_quadrature(near, h) if len(near) else (np.zeros((0, d)), np.zeros(0), np.zeros((0, d)))
        return sampling.surface_loads(grid, x, w, np.abs(load.tractions(x, n)))

    zone = blocks.around(rest.reshape(-1, d))
    taken = taken[_touching(blocks, taken, zone)]
    on_patch = weighed(np.concatenate([whole[_touching(blocks, whole, zone)], taken]))
    beside = weighed(rest)
    twice = weighed(taken)  # the rest holds the partly taken facets whole: their patch pieces are there too
    out = []
    for a, rows in enumerate(_positions(layout, seeing)):
        part, other, both = (_by_position(layout, *s[a]) for s in (on_patch, beside, twice))
        keys = np.union1d(rows, part[0])
        p, r, c = (_aligned(keys, *s) for s in (part, other, both))
        total = p + r - c
        share = np.where(r > 0, np.minimum(p / np.where(total > p, total, np.maximum(p, 1e-300)), 1.0), 1.0)
        keep = share > 0
        out.append((keys[keep], share[keep]))
    return out


def _touching(blocks: "_Blocks", pieces: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """bool [M]: which pieces [M, d, d] have a corner in the blocks ``keys`` (sorted)."""
    d = pieces.shape[-1]
    return np.isin(blocks.of(pieces.reshape(-1, d)), keys, assume_unique=False).reshape(len(pieces), d).any(axis=1)


def _cells(grid: Grid, corners: np.ndarray) -> np.ndarray:
    """Unique keys (see ``_rows_reached``) of the cells holding ``corners`` [N, d]."""
    dims = np.asarray(grid.shape) + 6  # cells from -3 on: points within h of the grid's edge included
    cells = np.floor((corners - np.asarray(grid.origin)) / grid.spacing).astype(np.int64) + 3
    return np.unique(np.ravel_multi_index(tuple(np.clip(cells, 2, dims - 3).T), dims))


def _rows_reached(grid: Grid, cells: np.ndarray) -> list[np.ndarray]:
    """Per component a: grid indices [K, d] (unique) of the rows whose hat support may hold a point of
    the pieces (edges <= h / 2) whose corners lie in ``cells`` (keys from ``_cells``). The sample of
    (a, I) lies at h (I + 1/2 - e_a / 2) and its support spans one cell on each side, so a point in
    cell J reaches I = J or J + e_a along a and J - 1 ... J + 1 across; a piece's points lie in
    cells within one of its corners' cells."""
    d = grid.dim
    dims = np.asarray(grid.shape) + 6
    out = []
    for a in range(d):
        rows = cells
        for k in range(d):  # one axis at a time: the sets stay near the band's own size
            stride = int(np.prod(dims[k + 1:]))
            steps = (-1, 0, 1, 2) if k == a else (-2, -1, 0, 1, 2)
            rows = np.unique((rows[:, None] + stride * np.asarray(steps)[None]).ravel())
        out.append(np.array(np.unravel_index(rows, dims)).T - 3)
    return out


def _positions(layout: TileLayout, rows: list[np.ndarray]) -> list[np.ndarray]:
    out = []
    for index in rows:
        pos = layout.positions(index)
        out.append(np.unique(pos[pos >= 0]))
    return out


def _by_position(layout: TileLayout, index: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sorted positions, values) of rows given by grid index, those outside the kept tiles dropped."""
    pos = layout.positions(index)
    kept = pos >= 0
    order = np.argsort(pos[kept])
    return pos[kept][order], value[kept][order]


def _aligned(keys: np.ndarray, pos: np.ndarray, value: np.ndarray) -> np.ndarray:
    """values at the sorted positions ``keys``, 0 where ``pos`` has none."""
    out = np.zeros(len(keys))
    if len(pos):
        at = np.minimum(np.searchsorted(pos, keys), len(pos) - 1)
        hit = pos[at] == keys
        out[hit] = value[at[hit]]
    return out


class _Blocks:
    """Keys of the BLOCK-cell blocks holding points, and of the blocks around them."""

    def __init__(self, grid: Grid) -> None:
        self.origin = np.asarray(grid.origin, dtype=float)
        self.size = BLOCK * grid.spacing
        self.dims = np.asarray(grid.shape) // BLOCK + 4  # a margin of a block and more on each side

    def _index(self, points: np.ndarray) -> np.ndarray:
        index = np.floor((points - self.origin) / self.size).astype(np.int64) + 2
        return np.clip(index, 0, self.dims - 1)

    def of(self, points: np.ndarray) -> np.ndarray:
        return np.ravel_multi_index(tuple(self._index(points).T), self.dims)

    def around(self, points: np.ndarray) -> np.ndarray:
        """Sorted keys of the blocks holding ``points`` and of their 3^d - 1 neighbours."""
        index = np.array(np.unravel_index(np.unique(self.of(points)), self.dims)).T
        d = index.shape[1]
        steps = np.array(list(itertools.product((-1, 0, 1), repeat=d)), dtype=np.int64)
        near = np.clip((index[:, None, :] + steps[None]).reshape(-1, d), 0, self.dims - 1)
        return np.unique(np.ravel_multi_index(tuple(near.T), self.dims))
