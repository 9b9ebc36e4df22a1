"""Which DG element holds a point: probes and surface vertices are located in the pieces of cells.

A point strictly inside a full cell is in that cell's element; one in a cell without pieces is
outside; the rest (points in cut cells) are decided by the winding number and then by the
nearest piece surface (:func:`owners`).
"""

from __future__ import annotations

import numpy as np

from ..geometry.containment import ON_SURFACE, surface_tolerance
from ..geometry.slicing import CutCells
from ..geometry.surface import Surface, point_triangle_distance
from ..geometry.winding import inside
from .elements import Elements


def locate(elements: Elements, cut: CutCells, surface: Surface, points: np.ndarray) -> np.ndarray:
    """Element [N] containing each point, -1 outside the material (surface points count as inside)."""
    points = np.asarray(points, dtype=float)
    out = np.full(len(points), -1, dtype=np.int64)
    grid = elements.grid
    # the winding number costs O(points x triangles): only points in cut cells need it. A point
    # strictly inside a full cell is in that cell's element, one in a cell without pieces is outside
    # on the surface means what it means for every method (engine.geometry.containment)
    tol = surface_tolerance(surface, grid.spacing) / grid.spacing  # [cells]
    rel = (points - np.asarray(grid.origin)) / grid.spacing
    cell = np.floor(rel).astype(np.int64)
    interior = np.all((rel - cell > tol) & (rel - cell < 1 - tol), axis=1)
    interior &= np.all((cell >= 0) & (cell < np.asarray(grid.shape)), axis=1)
    lin = np.full(len(points), -1, dtype=np.int64)
    lin[interior] = grid.linear_index(cell[interior])
    full_lin = grid.linear_index(cut.piece_cell[cut.full])
    all_lin = np.unique(grid.linear_index(cut.piece_cell))
    in_full = interior & np.isin(lin, full_lin)
    empty = interior & ~np.isin(lin, all_lin)
    out[in_full] = elements.piece_element[np.nonzero(cut.full)[0][_positions(full_lin, lin[in_full])]]
    rest = ~in_full & ~empty
    if np.any(rest):
        ok = np.zeros(len(points), dtype=bool)
        ok[rest] = inside(surface.vertices, surface.faces, points[rest])
        if np.any(ok):
            out[ok] = owners(elements, cut, points[ok])
        # the winding number is 1/2 on the surface itself, and a probe placed on a face or a vertex
        # (from the mesh file) falls either way: it is in the piece whose surface it lies on
        on = np.nonzero(rest & ~ok)[0]
        if len(on):
            gap = np.full(len(on), np.inf)
            found = owners(elements, cut, points[on], distances=gap, tol=tol)
            touching = gap <= tol * grid.spacing
            out[on[touching]] = found[touching]
    return out

def owners(elements: Elements, cut: CutCells, points: np.ndarray, distances: np.ndarray | None = None,
           tol: float = ON_SURFACE) -> np.ndarray:
    """Element [N] of points known to lie in the solid or on its surface, -1 where no cell around
    holds a piece. A point on a cell face looks in the cells on both sides. Among several pieces the
    one owning the nearest surface triangle wins (exact: the segment from a point to another piece
    of its cell leaves the solid through the point's own piece's surface); a point within ``tol``
    cells of a cell face counts as on it. ``distances`` [N], if
    given, receives each point's distance [m] to the surface triangles of the chosen piece (inf for
    a piece without any)."""
    grid = elements.grid
    h = grid.spacing
    out = np.full(len(points), -1, dtype=np.int64)
    shape = np.asarray(grid.shape)
    lin_pieces = grid.linear_index(cut.piece_cell)
    order = np.argsort(lin_pieces, kind="stable")
    sorted_lin = lin_pieces[order]
    tri_order = np.argsort(cut.boundary_piece, kind="stable")
    tri_piece = cut.boundary_piece[tri_order]
    rel = (np.asarray(points) - np.asarray(grid.origin)) / h
    for q, r in enumerate(rel):
        lo, hi = np.floor(r - tol).astype(np.int64), np.floor(r + tol).astype(np.int64)
        cand = []
        for c in {tuple(np.where(np.array(bits, bool), hi, lo)) for bits in np.ndindex(2, 2, 2)}:
            if np.all(np.array(c) >= 0) and np.all(np.array(c) < shape):
                k = int(np.ravel_multi_index(c, tuple(shape)))
                i, j = np.searchsorted(sorted_lin, k), np.searchsorted(sorted_lin, k, side="right")
                cand.extend(order[i:j].tolist())
        if not cand:
            continue
        if len(cand) == 1 and distances is None:
            out[q] = elements.piece_element[cand[0]]
            continue
        best, best_d = cand[0], np.inf
        for piece in cand:
            i, j = np.searchsorted(tri_piece, piece), np.searchsorted(tri_piece, piece, side="right")
            if j > i:
                d = point_triangle_distance(points[q], cut.boundary_triangles[tri_order[i:j]]).min()
                if d < best_d:
                    best, best_d = piece, d
            elif best_d == np.inf:
                best = piece  # an interior (full) piece: the point is inside it unless a surface is nearer
                best_d = np.inf
        out[q] = elements.piece_element[best]
        if distances is not None:
            distances[q] = best_d
    return out


def _positions(keys: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Index [n] into keys [k] (distinct) of each value [n] (every value is a key)."""
    order = np.argsort(keys)
    return order[np.searchsorted(keys[order], values)]
