"""Tiled storage of staggered quantities: only tiles of 8^d indices that touch material are kept.

Every staggered kind (cells, faces of each normal, edges) is indexed by the same index box
[0, n_k + 1)^d (see ``engine.grid``); a ``TileLayout`` names the kept tiles of that box. Arrays
on a layout are flat per component: position ``p = tile * 8^d + local`` with the local index in C
order, plus one trailing *zero tile* (tile number ``count``) that stands for every tile not kept,
so stencils read zeros outside the material without branches. ``tile_map`` (dense over the tile
grid, tiny) turns a global index into its tile; the kernels use the same rule.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi

from ..blocks import BlockSparse

TILE = 8


@dataclass(frozen=True)
class TileLayout:
    """box: (d,) index extent (n + 1 per axis); coords: [nt, d] int32 kept tile coordinates
    (C-order sorted); tile_map: [ceil(box / 8)] int32 tile number of each tile, ``nt`` if not kept."""

    box: tuple[int, ...]
    coords: np.ndarray
    tile_map: np.ndarray

    @property
    def dim(self) -> int:
        return len(self.box)

    @property
    def count(self) -> int:
        """Number of kept tiles (the zero tile has this number)."""
        return len(self.coords)

    @property
    def tile_size(self) -> int:
        return TILE**self.dim

    @property
    def size(self) -> int:
        """Length of a per-component array, the zero tile included."""
        return (self.count + 1) * self.tile_size

    def neighbours(self) -> np.ndarray:
        """[count, 3^d] int32: tile number of the neighbour at offset o in {-1, 0, 1}^d (code
        sum_k (o_k + 1) 3^(d-1-k)); ``count`` (the zero tile) where it is not kept."""
        return self._around(self.coords.astype(np.int64), self)

    def parents(self, coarse: TileLayout) -> np.ndarray:
        """[count, 3^d] int32: the ``coarse`` layout's tiles around each tile's parent (coords // 2,
        offsets {-1, 0, 1}^d, code as in :meth:`neighbours`); ``coarse.count`` where not kept."""
        return self._around(self.coords.astype(np.int64) // 2, coarse)

    def children(self, fine: TileLayout) -> np.ndarray:
        """[count, 3^d] int32: the ``fine`` layout's tiles 2 T - 1 + {0, 1, 2}^d of each tile T of
        this (coarse) layout (code as in :meth:`neighbours`), which hold every fine DOF a coarse
        one of the tile interpolates to; ``fine.count`` where not kept."""
        return self._around(2 * self.coords.astype(np.int64), fine)

    def _around(self, centres: np.ndarray, other: TileLayout) -> np.ndarray:
        """Tile numbers in ``other`` of ``centres`` [count, d] + {-1, 0, 1}^d; ``other.count``
        outside its kept tiles."""
        d = self.dim
        shifts = np.array(list(itertools.product((-1, 0, 1), repeat=d)), dtype=np.int64)
        tiles = centres[:, None, :] + shifts[None]
        inside = np.all((tiles >= 0) & (tiles < np.asarray(other.tile_map.shape)), axis=2)
        out = np.full(inside.shape, other.count, dtype=np.int32)
        out[inside] = other.tile_map[tuple(tiles[inside].T)]
        return out

    def positions(self, index: np.ndarray) -> np.ndarray:
        """Flat positions [n] of global indices [n, d]; -1 where the tile is not kept or out of the box."""
        index = np.asarray(index, dtype=np.int64).reshape(-1, self.dim)
        tiles = index // TILE
        inside = np.all((index >= 0) & (index < np.asarray(self.box)), axis=1)
        t = np.full(len(index), self.count, dtype=np.int64)
        t[inside] = self.tile_map[tuple(tiles[inside].T)]
        local = np.ravel_multi_index(tuple((index - tiles * TILE).T), (TILE,) * self.dim)
        return np.where(t < self.count, t * self.tile_size + local, -1)

    def indices(self) -> np.ndarray:
        """Global index [size - tile_size, d] of every position of the kept tiles (in order)."""
        local = np.stack(np.unravel_index(np.arange(self.tile_size), (TILE,) * self.dim), axis=1)
        return (self.coords.astype(np.int64)[:, None, :] * TILE + local[None]).reshape(-1, self.dim)

    def index_of(self, pos: np.ndarray) -> np.ndarray:
        """Global index [k, d] int32 of the flat positions ``pos`` [k] in kept tiles: that of
        :meth:`indices` at those rows, without the [size, d] array."""
        pos = np.asarray(pos)
        tile, local = np.divmod(pos, self.tile_size)
        # one axis at a time, in the positions' integer type: unravel_index's int64 [k, d]
        # temporaries were most of the 1.6 s that the 256^3 shell's sample points took
        out = np.empty((len(pos), self.dim), dtype=np.int32)
        for a in range(self.dim):
            stride = TILE ** (self.dim - 1 - a)
            out[:, a] = self.coords[:, a][tile] * TILE + (local // stride) % TILE
        return out

    def load(self, values: BlockSparse, out: np.ndarray | None = None) -> np.ndarray:
        """A block-sparse array (8^d tiles on the same tile grid) as a flat array on this layout
        (written into ``out`` [size], zero, when given); tiles of ``values`` that are not kept here
        must be zero (they are dropped)."""
        out = np.zeros(self.size) if out is None else out
        if len(values.coords):
            if values.block != TILE:
                raise ValueError(f"block-sparse tiles of {values.block} cannot be loaded on a layout of {TILE}")
            t = self.tile_map[tuple(np.minimum(values.coords.T, np.asarray(self.tile_map.shape)[:, None] - 1))]
            kept = t < self.count
            rows = out.reshape(self.count + 1, self.tile_size)
            rows[t[kept]] = values.data[kept].reshape(int(kept.sum()), -1)
        return out

    def dense(self, flat: np.ndarray, shape: tuple[int, ...] | None = None) -> np.ndarray:
        """A flat array [size] (or [c, size]) as a dense array over the index box, cut to ``shape``."""
        flat = np.asarray(flat)
        if flat.ndim > 1:
            return np.stack([self.dense(f, shape) for f in flat])
        d, tiles_shape = self.dim, self.tile_map.shape
        full = np.zeros(tuple(t * TILE for t in tiles_shape))
        view = full.reshape(sum(((t, TILE) for t in tiles_shape), ()))
        rows = flat.reshape((self.count + 1,) + (TILE,) * d)[: self.count]
        view[tuple(i for k in range(d) for i in (self.coords[:, k], slice(None)))] = rows
        return full[tuple(slice(0, n) for n in (shape or self.box))]

    def flat(self, dense: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`dense`: a dense array over (part of) the index box as a flat array
        [size] on this layout (zero beyond ``dense`` and in the zero tile)."""
        d, tiles_shape = self.dim, self.tile_map.shape
        full = np.zeros(tuple(t * TILE for t in tiles_shape), dtype=dense.dtype)
        full[tuple(slice(0, n) for n in dense.shape)] = dense
        view = full.reshape(sum(((t, TILE) for t in tiles_shape), ()))
        rows = view[tuple(i for k in range(d) for i in (self.coords[:, k], slice(None)))]
        return np.concatenate([rows.reshape(-1), np.zeros(self.tile_size, dtype=dense.dtype)])

    def shifted(self, pos: np.ndarray, axis: int, step: int) -> np.ndarray:
        """Flat positions [n] of the indices one step (+1 or -1) along ``axis`` from the kept flat
        positions ``pos`` [n]: within a tile a fixed stride, across it through the neighbour table;
        a position in the zero tile where that tile is not kept (arrays read zero there)."""
        d, ts = self.dim, self.tile_size
        pos = np.asarray(pos, dtype=np.int64)
        tile, local = pos // ts, pos % ts
        stride = TILE ** (d - 1 - axis)
        c = (local // stride) % TILE
        out = pos + step * stride
        cross = c == (TILE - 1 if step > 0 else 0)
        beyond = self.coords[tile[cross]].astype(np.int64)
        beyond[:, axis] += step
        inside = np.all((beyond >= 0) & (beyond < np.asarray(self.tile_map.shape)), axis=1)
        table = np.full(len(beyond), self.count, dtype=np.int64)
        table[inside] = self.tile_map[tuple(beyond[inside].T)]
        out[cross] = table * ts + local[cross] - step * (TILE - 1) * stride
        return out

    def select(self, keep: np.ndarray) -> tuple[TileLayout, np.ndarray]:
        """The layout of the kept tiles ``keep`` [count] bool and, for re-indexing arrays, the old tile
        number of every new tile followed by the old zero tile: flat arrays map by ``rows[order]``."""
        order = np.concatenate([np.nonzero(keep)[0], [self.count]])
        return make_layout(self.box, self.coords[keep]), order


def cell_bodies(layout: TileLayout, vc: np.ndarray) -> np.ndarray:
    """The connected bodies of material cells (``vc`` [size] > 0): a label per cell of the index box
    (dense, int32; 1, 2, ... and 0 without material), cells joined across faces and edges (cells
    sharing only a vertex share no term of the staggered energy)."""
    labels, _ = ndi.label(layout.dense(vc) > 0, structure=ndi.generate_binary_structure(layout.dim, 2))
    return labels.astype(np.int32)


def make_layout(box: tuple[int, ...], coords: np.ndarray) -> TileLayout:
    """Layout of the tiles ``coords`` [nt, d] (duplicates removed, sorted) over the index ``box``."""
    d = len(box)
    tiles_shape = tuple(-(-n // TILE) for n in box)
    coords = np.asarray(coords, dtype=np.int64).reshape(-1, d)
    coords = coords[np.all((coords >= 0) & (coords < np.asarray(tiles_shape)), axis=1)]
    # marking a dense map of the (small) tile grid sorts and deduplicates in one pass; np.unique
    # over rows sorted millions of dilated coordinates (seconds at 256^3)
    kept = np.zeros(tiles_shape, dtype=bool)
    kept[tuple(coords.T)] = True
    coords = np.argwhere(kept).astype(np.int32)
    tile_map = np.full(tiles_shape, len(coords), dtype=np.int32)
    tile_map[tuple(coords.T)] = np.arange(len(coords), dtype=np.int32)
    return TileLayout(tuple(int(n) for n in box), coords, tile_map)


def dilate(coords: np.ndarray, dim: int) -> np.ndarray:
    """The tiles ``coords`` [nt, d] and all their 3^d - 1 neighbours (duplicates possible)."""
    shifts = np.array(list(itertools.product((-1, 0, 1), repeat=dim)), dtype=np.int32)
    return (np.asarray(coords, dtype=np.int32)[:, None, :] + shifts[None]).reshape(-1, dim)


def reorder(flat: np.ndarray, order: np.ndarray, tile_size: int) -> np.ndarray:
    """Re-index a flat array [..., size] by ``order`` from :meth:`TileLayout.select`."""
    lead = flat.shape[:-1]
    rows = flat.reshape(lead + (-1, tile_size))
    # np.take copies whole tiles: 2-2.5x faster than the fancy index rows[..., order, :] on the
    # 256^3 shell's [3, 11.9 M] fractions (0.05 -> 0.02 s each once their pages are touched)
    return np.take(rows, order, axis=-2).reshape(lead + (-1,))
