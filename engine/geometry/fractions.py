"""Exact volume fractions: the solid in every half-size sub-cell and in every control volume.

The grid of spacing h is refined to sub-cells of spacing h/2. The solid volume inside each sub-cell
is computed exactly (up to round-off) by the scan conversion of ``kernels.py``. Every control
volume the staggered method needs is an h-sized box centred at a staggered sample, i.e. the sum of
2^d sub-cells: the box of offset ``s`` (see ``engine.grid``) at index I covers the sub-cells
``2 I - s + {0, 1}^d``.

Work proceeds in slabs of one tile of cells along x, so only one slab of sub-cells is ever dense;
what is kept is block-sparse (``engine.blocks``): tiles holding material.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ..blocks import BlockSparse, concat, extract_tiles
from ..errors import GeometryError, GridError
from ..grid import Grid
from .surface import Surface

# Below this (in sub-cell volume units) a value is round-off from cancelling facets above it.
ROUND_OFF = 1e-12
# Beyond this outside [0, 1] the facets over-count: overlapping shells or an open surface.
OVERLAP_TOLERANCE = 1e-6
TILE = 8


@dataclass
class VolumeFractions:
    """Exact solid fractions on a grid, block-sparse.

    control: offset s (tuple in {0,1}^d with at most two ones) -> fraction in [0, 1] of the h^d
      control volume centred at each staggered sample (index extent grid.shape + s);
      s = (0,..,0) are the cells.
    subcells: (only when asked for) fraction of each h/2 sub-cell, index extent 2 * grid.shape.
    warnings: what was approximated, with numbers.
    """

    grid: Grid
    control: dict[tuple[int, ...], BlockSparse]
    subcells: BlockSparse | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def cells(self) -> BlockSparse:
        return self.control[(0,) * self.grid.dim]

    def solid_volume(self) -> float:
        """Total solid volume [m^d] (from the cell fractions)."""
        return self.cells.sum() * self.grid.spacing**self.grid.dim

    def dense(self, offset: tuple[int, ...] | None = None) -> np.ndarray:
        """Dense fractions [grid.shape + offset] of one sample kind (default cells); for output."""
        return self.control[tuple(offset or (0,) * self.grid.dim)].dense()


def control_offsets(dim: int) -> list[tuple[int, ...]]:
    """Offsets of the staggered samples: cell centres, faces, and edges (3D) / nodes (2D)."""
    return [s for s in itertools.product((0, 1), repeat=dim) if sum(s) <= 2]


def volume_fractions(surface: Surface, grid: Grid, *, keep_subcells: bool = False) -> VolumeFractions:
    """Exact solid fractions of every control volume (and optionally sub-cell) of ``grid``.

    surface: outward-oriented, same dimension as the grid, inside the grid box. Closed surfaces
    are scan-converted exactly; open ones (``surface.closed`` False) fall back to the
    generalized winding number, which is approximate and says so in the warnings.
    """
    d = grid.dim
    if surface.dim != d:
        raise GeometryError(f"geometry: a {surface.dim}D surface cannot be placed on a {d}D grid")
    tiles = slab_tiles(grid)
    warnings: list[str] = []
    if surface.closed:
        slabs = scan_slabs(surface, grid, tiles)
    else:
        from .winding_fill import winding_slabs

        slabs = winding_slabs(surface, grid, tiles, warnings)

    offsets = control_offsets(d)
    parts: dict[tuple[int, ...], list] = {s: [] for s in offsets}
    sub_parts: list = []
    carry = np.zeros((1,) + tuple(2 * TILE * t for t in tiles[1:]))  # last sub-column of the previous slab
    extremes = [0.0, 1.0]
    for tx, volume in enumerate(slabs):
        extremes = [min(extremes[0], float(volume.min())), max(extremes[1], float(volume.max()))]
        volume[np.abs(volume) < ROUND_OFF] = 0.0
        np.clip(volume, 0.0, 1.0, out=volume)
        for s, total in _control_sums(volume, carry, offsets).items():
            parts[s].append(extract_tiles(total / 2**d, TILE, tx))
        if keep_subcells:
            sub_parts.append(extract_tiles(volume, 2 * TILE, tx))
        carry = volume[-1:].copy()

    if extremes[0] < -OVERLAP_TOLERANCE or extremes[1] > 1 + OVERLAP_TOLERANCE:
        warnings.append(
            f"sub-cell volumes outside [0, 1] before clamping (min {extremes[0]:.3g}, max {extremes[1]:.3g}): "
            "overlapping or self-intersecting shells; fractions near the overlap are approximate"
        )
    control = {s: concat(tuple(n + o for n, o in zip(grid.shape, s)), TILE, p) for s, p in parts.items()}
    subcells = concat(tuple(2 * n for n in grid.shape), 2 * TILE, sub_parts) if keep_subcells else None
    fractions = VolumeFractions(grid, control, subcells, warnings)
    if not fractions.cells.sum() > 0:  # a solid thinner than ROUND_OFF of every sub-cell it is in
        raise GridError(f"grid.cell_size: no cell holds a share of the solid above round-off ({ROUND_OFF:g} of a "
                        f"sub-cell): cells of {grid.spacing:.6g} m are far too large for it; give a smaller cell size")
    return fractions


def slab_tiles(grid: Grid) -> list[int]:
    """Tiles per axis; they also cover the far faces (index n along a shifted axis), hence n + 1."""
    return [-(-(n + 1) // TILE) for n in grid.shape]


def scan_slabs(surface: Surface, grid: Grid, tiles: list[int]) -> Iterator[np.ndarray]:
    """Exact solid volume of every sub-cell (sub-cell units), one slab of tiles along x at a time.

    Yields arrays [2 TILE, 2 TILE tiles[1], ...]; everything beyond the grid is zero.
    """
    from ..runtime import ensure_initialized
    from . import kernels

    ensure_initialized()
    d = grid.dim
    facets = (surface.vertices[surface.faces] - np.asarray(grid.origin)) / (0.5 * grid.spacing)  # [N, d, d]
    _check_inside(facets, grid)
    if d == 3:
        # vertical triangles have no projected area: they contribute nothing
        e1, e2 = facets[:, 1, :2] - facets[:, 0, :2], facets[:, 2, :2] - facets[:, 0, :2]
        facets = facets[(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) != 0]
    lo, hi = facets[:, :, 0].min(axis=1), facets[:, :, 0].max(axis=1)
    scan = kernels.scan_triangles if d == 3 else kernels.scan_segments
    for tx in range(tiles[0]):
        x0 = 2 * TILE * tx
        volume = np.zeros((2 * TILE,) + tuple(2 * TILE * t for t in tiles[1:]))
        cover = np.zeros_like(volume)
        sel = (hi >= x0) & (lo <= x0 + 2 * TILE)
        if sel.any():
            scan(np.ascontiguousarray(facets[sel]), x0, volume, cover)
        # every sub-cell below a fragment gets the fragment's projected area
        volume += np.cumsum(cover[..., ::-1], axis=-1)[..., ::-1]
        volume -= cover
        yield volume


def _check_inside(facets: np.ndarray, grid: Grid) -> None:
    sub_shape = np.asarray(grid.shape) * 2
    slack = 1e-9 * sub_shape.max()
    if np.any(facets.min(axis=(0, 1)) < -slack) or np.any(facets.max(axis=(0, 1)) > sub_shape + slack):
        raise GridError(
            "grid: the geometry extends outside the grid box "
            f"({np.round(grid.origin, 6).tolist()} .. {np.round(grid.upper, 6).tolist()})"
        )


def _pair_sums(a: np.ndarray, axis: int, shifted: bool, carry: np.ndarray | None = None) -> np.ndarray:
    """Sums of consecutive sub-cell pairs along ``axis``: (2I, 2I+1), or (2I-1, 2I) when shifted.

    When shifted, sub-cell -1 is ``carry`` (the previous slab's last sub-column) or zero, and the
    slab's last sub-column is left for the next pair (the zero padding of the tile box guarantees
    nothing is lost at the far end).
    """
    if shifted:
        if carry is None:
            carry = np.zeros_like(a[_along(axis, slice(0, 1), a.ndim)])
        a = np.concatenate([carry, a[_along(axis, slice(0, -1), a.ndim)]], axis=axis)
    return a[_along(axis, slice(0, None, 2), a.ndim)] + a[_along(axis, slice(1, None, 2), a.ndim)]


def _along(axis: int, index: slice, ndim: int) -> tuple:
    return (slice(None),) * axis + (index,) + (slice(None),) * (ndim - axis - 1)


def _control_sums(
    volume: np.ndarray, carry: np.ndarray, offsets: list[tuple[int, ...]]
) -> dict[tuple[int, ...], np.ndarray]:
    """Control-volume sums (sub-cell units) of one slab for every offset.

    Pair sums along different axes commute, so the trailing axes are summed first and shared
    between the offsets that agree on them; x comes last because it needs the carry.
    """
    d = volume.ndim
    # cache[tail]: (slab, carry) pair-summed along the trailing axes d - len(tail) .. d - 1 with shifts tail
    cache: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray]] = {(): (volume, carry)}
    for s in offsets:
        for length in range(1, d):
            tail = s[d - length :]
            if tail not in cache:
                a, c = cache[tail[1:]]
                axis = d - length
                cache[tail] = (_pair_sums(a, axis, bool(tail[0])), _pair_sums(c, axis, bool(tail[0])))

    out = {}
    for s in offsets:
        a, c = cache[s[1:]]
        out[s] = _pair_sums(a, 0, bool(s[0]), c if s[0] else None)
    return out
