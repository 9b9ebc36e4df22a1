"""Block-sparse arrays: values on a d-dimensional index box, stored only in blocks that are non-zero.

Empty space is never stored: the index box is tiled by ``block``^d tiles and a tile is kept only if
one of its values is non-zero. Inside a kept tile values are dense, which keeps stencils and
reductions vectorised (and maps onto Taichi's pointer/bitmasked SNodes later).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class BlockSparse:
    """shape: (d,) index extent; block: tile edge B; coords: [nb, d] int32 tile coordinates
    (C-order sorted); data: [nb, B, ..., B] float64 values of the kept tiles."""

    shape: tuple[int, ...]
    block: int
    coords: np.ndarray
    data: np.ndarray

    @property
    def dim(self) -> int:
        return len(self.shape)

    @property
    def nbytes(self) -> int:
        return int(self.coords.nbytes + self.data.nbytes)

    def sum(self) -> float:
        return float(self.data.sum())

    def nonzero(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices [n, d] (int64) and values [n] of the non-zero entries."""
        where = np.nonzero(self.data)
        local = np.stack(where[1:], axis=1)
        index = self.coords[where[0]].astype(np.int64) * self.block + local
        return index, self.data[where]

    def dense(self) -> np.ndarray:
        """All values as a dense array of ``shape`` (for output and tests; allocates the full box)."""
        B, d = self.block, self.dim
        padded = tuple(-(-n // B) * B for n in self.shape)
        out = np.zeros(padded)
        view = out.reshape(sum(((n // B, B) for n in padded), ()))
        view[_tile_index(self.coords.T, d)] = self.data
        return out[tuple(slice(0, n) for n in self.shape)]

    def lookup(self, index: np.ndarray) -> np.ndarray:
        """Values [n] at integer indices [n, d]; zero outside the kept tiles and outside ``shape``."""
        index = np.asarray(index, dtype=np.int64)
        out = np.zeros(len(index))
        inside = np.all((index >= 0) & (index < np.asarray(self.shape)), axis=1)
        tiles = index // self.block
        tile_key = _keys(tiles, self.shape, self.block)
        kept_key = _keys(self.coords.astype(np.int64), self.shape, self.block)
        pos = np.searchsorted(kept_key, tile_key)
        pos = np.minimum(pos, len(kept_key) - 1)
        hit = inside & (len(kept_key) > 0) & (kept_key[pos] == tile_key if len(kept_key) else False)
        local = index[hit] - tiles[hit] * self.block
        out[hit] = self.data[(pos[hit],) + tuple(local.T)]
        return out


def _keys(tiles: np.ndarray, shape: tuple[int, ...], block: int) -> np.ndarray:
    counts = [-(-n // block) for n in shape]
    return np.ravel_multi_index(tuple(np.clip(tiles, 0, np.asarray(counts) - 1).T), counts)


def _tile_index(coords_t: np.ndarray, d: int) -> tuple:
    """Index of tiles ``coords_t`` [d, nb] into an array reshaped to (n0/B, B, n1/B, B, ...)."""
    return tuple(i for axis in range(d) for i in (coords_t[axis], slice(None)))


def extract_tiles(dense: np.ndarray, block: int, first_tile_x: int) -> tuple[np.ndarray, np.ndarray]:
    """Tiles of ``dense`` (every axis a multiple of ``block``) holding a non-zero value.

    Returns coords [nb, d] int32 (x shifted by ``first_tile_x``) and data [nb, B, ..., B].
    """
    d = dense.ndim
    view = dense.reshape(sum(((n // block, block) for n in dense.shape), ()))
    inner = tuple(range(1, 2 * d, 2))
    kept = np.nonzero(np.abs(view).max(axis=inner) > 0)
    data = view[_tile_index(np.asarray(kept), d)]
    coords = np.stack(kept, axis=1).astype(np.int32)
    coords[:, 0] += first_tile_x
    return coords, data


def concat(shape: tuple[int, ...], block: int, parts: list[tuple[np.ndarray, np.ndarray]]) -> BlockSparse:
    """Join tiles extracted slab by slab (already in C order because slabs advance along x)."""
    d = len(shape)
    if not parts:
        return BlockSparse(shape, block, np.zeros((0, d), np.int32), np.zeros((0,) + (block,) * d))
    return BlockSparse(shape, block, np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
