"""The background grid: a box of ``shape`` cubic cells of edge ``spacing`` starting at ``origin``.

Cell ``I`` (a d-tuple of integers) covers ``origin + spacing * [I, I + 1)``. Staggered samples are
named by an offset ``s`` in {0, 1}^d: the sample of cell ``I`` with offset ``s`` lies at
``origin + spacing * (I + 0.5 - 0.5 s)`` -- ``s = 0`` the cell centre, ``s = e_a`` the face of
normal ``a`` on the cell's low side, ``s = e_a + e_b`` the edge (3D) or node (2D) between.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from .errors import GridError
from .geometry._shared import MAX_COORDINATE


@dataclass(frozen=True)
class Grid:
    """Uniform grid of cubic cells.

    origin: (d,) corner of cell 0 [m]; spacing: cell edge h [m]; shape: (d,) cells per axis.
    """

    origin: tuple[float, ...]
    spacing: float
    shape: tuple[int, ...]

    def __post_init__(self) -> None:
        if len(self.origin) != len(self.shape) or len(self.shape) not in (2, 3):
            raise GridError(f"grid: origin {self.origin} and shape {self.shape} must both have 2 or 3 entries")
        if not (math.isfinite(self.spacing) and self.spacing > 0):
            raise GridError(f"grid.cell_size: must be a positive finite number, got {self.spacing}")
        if any(n < 1 for n in self.shape):
            raise GridError(f"grid: every axis needs at least one cell, got shape {self.shape}")
        if not all(math.isfinite(o) for o in self.origin):
            raise GridError(f"grid: origin must be finite, got {self.origin}")

    @property
    def dim(self) -> int:
        return len(self.shape)

    @property
    def num_cells(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def upper(self) -> np.ndarray:
        """(d,) far corner of the grid [m]."""
        return np.asarray(self.origin) + self.spacing * np.asarray(self.shape)

    def axis_coordinates(self, axis: int, offset: int = 0) -> np.ndarray:
        """Sample coordinates along ``axis`` [m]: cell centres (offset 0) or low faces (offset 1).

        Faces run over ``shape[axis] + 1`` positions so the far face of the last cell is included.
        """
        n = self.shape[axis] + offset
        return self.origin[axis] + self.spacing * (np.arange(n) + 0.5 - 0.5 * offset)

    def sample_points(self, index: np.ndarray, offset: tuple[int, ...] | np.ndarray | None = None) -> np.ndarray:
        """Positions [n, d] of the staggered samples ``index`` [n, d] with ``offset`` (default centres)."""
        s = np.zeros(self.dim) if offset is None else np.asarray(offset, dtype=float)
        return np.asarray(self.origin) + self.spacing * (np.asarray(index, dtype=float) + 0.5 - 0.5 * s)

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Integer cell index [n, d] containing each point [n, d] (may lie outside ``shape``)."""
        return np.floor((np.asarray(points) - np.asarray(self.origin)) / self.spacing).astype(np.int64)

    def linear_index(self, index: np.ndarray, shape: tuple[int, ...] | None = None) -> np.ndarray:
        """C-order linear index [n] of multi-indices [n, d] within ``shape`` (default the cell shape)."""
        return np.ravel_multi_index(tuple(np.asarray(index).T), shape or self.shape)

    def to_dict(self) -> dict:
        return {"origin": list(self.origin), "spacing": self.spacing, "shape": list(self.shape)}


MAX_CELL_OVER_EXTENT = 1000.0
"""Largest cell size as a multiple of the geometry's longest side (``make_grid``)."""


def make_grid(
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    cell_size: float | None = None,
    resolution: int | None = None,
    padding: int = 1,
    max_cells: int | None = None,
) -> Grid:
    """Grid around the box [lower, upper] (the object's bounds, [m]).

    Exactly one of ``cell_size`` [m] or ``resolution`` (cells along the longest side of the box)
    is given. ``padding`` empty cells are added on every side; the object is centred.
    ``max_cells`` rejects grids whose cell count exceeds it, before anything is allocated.
    """
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    if (cell_size is None) == (resolution is None):
        raise GridError("grid: give exactly one of cell_size or resolution")
    if padding < 0:
        raise GridError(f"grid.padding: must be >= 0 cells, got {padding}")
    extent = upper - lower
    if not np.all(np.isfinite(extent)) or np.any(extent < 0):
        raise GridError(f"grid: invalid bounds {lower.tolist()} .. {upper.tolist()}")
    if cell_size is None:
        if resolution < 1:
            raise GridError(f"grid.resolution: must be >= 1, got {resolution}")
        if extent.max() <= 0:
            raise GridError("grid.resolution: the geometry has zero extent")
        if resolution > 2**53:  # beyond any cell limit, and beyond what a float divides
            raise GridError(f"grid.resolution: {len(str(resolution))} digits, far more cells than any grid limit allows")
        cell_size = float(extent.max()) / resolution
    if not (math.isfinite(cell_size) and cell_size > 0):
        raise GridError(f"grid.cell_size: must be a positive finite number, got {cell_size}")
    # Cells far larger than the geometry hold all of it in one anyway, and lose it to round-off: the
    # part is a sliver of the cell (the volume fractions drop what is under 1e-12 of a sub-cell: a
    # 1 m bar in 1e4 m cells voxelized to no solid at all) and a speck beside the grid's origin (hex
    # slicing in the grid's frame). 1e308 m cells overflowed twice the spacing and the cell volume.
    largest = min(MAX_CELL_OVER_EXTENT * float(extent.max()), MAX_COORDINATE)
    if cell_size > largest:
        raise GridError(f"grid.cell_size: {cell_size:g} m is over {MAX_CELL_OVER_EXTENT:g} times the geometry's "
                        f"longest side ({float(extent.max()):.6g} m); a cell that large holds all of it and loses it "
                        "to round-off: give a cell size below the part's size")
    # cell counts as Python integers: a huge resolution or a tiny cell size must be reported as
    # too many cells, not wrap around int64 into a negative shape
    with np.errstate(over="ignore"):
        ratios = extent / cell_size
    if not np.all(np.isfinite(ratios)):
        raise GridError(f"grid.cell_size: {cell_size:g} is too small for a geometry of extent {extent.max():g}")
    counts = [max(math.ceil(float(r) - 1e-9), 1) + 2 * int(padding) for r in ratios]
    total = math.prod(counts)
    if (max_cells is not None and total > max_cells) or max(counts) > 2**40:
        shape = "x".join(str(n) if n < 10**12 else _rough(n) for n in counts)
        raise GridError(
            f"grid: {shape} = {total if total < 10**15 else _rough(total)} cells exceeds the limit of "
            f"{max_cells if max_cells is not None else 2**40}; increase grid.cell_size or lower grid.resolution"
        )
    cells = np.array(counts, dtype=np.int64)
    centre = 0.5 * (lower + upper)
    origin = centre - 0.5 * cell_size * cells
    return Grid(origin=tuple(float(o) for o in origin), spacing=float(cell_size), shape=tuple(int(n) for n in cells))


def _rough(n: int) -> str:
    """A huge count in three digits, also beyond what a float holds (1e-300 m cells)."""
    try:
        return f"{n:.3g}"
    except OverflowError:
        return f"{str(n)[0]}e+{len(str(n)) - 1}"


def axis_pairs(d: int) -> tuple[tuple[int, int], ...]:
    """The axis pairs (a, b), a < b, of a d-dimensional grid: (0, 1) in 2D; (0, 1), (0, 2), (1, 2)
    in 3D (the order of the staggered method's shear strains and edge fractions)."""
    return tuple(itertools.combinations(range(d), 2))
