"""DG elements from the sliced cells: pieces, with tiny pieces merged into a face neighbour.

A piece below ``merge_fraction`` of a cell (volume / h^3) is merged into the neighbour it shares
the largest interface with (DG takes the non-convex union as one element, Kaufmann et al. 2009
section 9.4): the union's moments are the sum of its pieces' moments, re-centred on the frame of
its largest piece; interfaces inside a union disappear. A tiny piece with no interface (a whole
body smaller than the threshold) stays alone. Merges are counted for the solver report.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry.moments import shift_moments
from ..geometry.slicing import CutCells
from ..grid import Grid

# [-] pieces below this share of a cell are merged. Cantilever under 16 sub-cell offsets (P2, tests/test_dg.py):
# with 0.05 the condition number rose 64x over the uncut grid (slabs 0.06 h thick), with 0.3 at most 3.6x.
MERGE_FRACTION = 0.3


@dataclass
class Elements:
    """The elements and their couplings; everything sorted by element, SI units.

    cell [E, 3]: the grid cell whose centre is the element's frame origin; full [E]: an uncut
    cell (all full elements share one reference matrix); volume [E] [m^3]; moments [E, m]:
    int_K xi^a dV / h^3 in the element frame, degree 4 (``CutCells`` convention).
    Faces f (the interfaces, each a connected part of a grid face between two elements):
    minus / plus [F] elements (normal +e_axis from minus to plus), axis [F], area [F] [m^2],
    moments [F, m]: int_f eta^a dA / h^2 in the frame of cell ``face_cell`` [F, 3].
    Boundary: triangles [T, 3, 3] [m] of the surface (outward by the right-hand rule) and their
    element ``boundary_element`` [T]. ``piece_element`` [P] maps the sliced pieces to elements;
    ``merged`` counts the pieces merged away.
    """

    grid: Grid
    cell: np.ndarray
    full: np.ndarray
    volume: np.ndarray
    moments: np.ndarray
    minus: np.ndarray
    plus: np.ndarray
    axis: np.ndarray
    area: np.ndarray
    face_moments: np.ndarray
    face_cell: np.ndarray
    boundary_element: np.ndarray
    boundary_triangles: np.ndarray
    piece_element: np.ndarray
    merged: int = 0
    warnings: list[str] = field(default_factory=list)

    @property
    def count(self) -> int:
        return int(self.cell.shape[0])

    @property
    def centres(self) -> np.ndarray:
        """Frame origins c_K [E, 3] [m]."""
        return self.grid.sample_points(self.cell)

    @property
    def reference_faces(self) -> np.ndarray:
        """bool [F]: an interface between two full cells (shares the reference face matrices)."""
        h2 = self.grid.spacing**2
        return self.full[self.minus] & self.full[self.plus] & np.isclose(self.area, h2, rtol=1e-12, atol=0)

    def bodies(self) -> np.ndarray:
        """Connected component label [E] of every element (through interfaces)."""
        import scipy.sparse as sp
        from scipy.sparse.csgraph import connected_components

        n = self.count
        graph = sp.coo_matrix((np.ones(len(self.minus)), (self.minus, self.plus)), shape=(n, n))
        return connected_components(graph, directed=False)[1]


def make_elements(cut: CutCells, merge_fraction: float = MERGE_FRACTION) -> Elements:
    """Elements of the sliced geometry ``cut`` (moments of degree >= 4 needed for k = 2)."""
    grid, h = cut.grid, cut.grid.spacing
    P = cut.num_pieces
    fraction = cut.volume / h**3
    parent = np.arange(P)

    def root(p: int) -> int:
        while parent[p] != p:
            parent[p] = parent[parent[p]]
            p = parent[p]
        return p

    small = np.nonzero(fraction < merge_fraction)[0]
    merged = 0
    if len(small):
        # largest interface of every small piece: sort its faces by area and keep the last
        ends = np.concatenate([cut.face_minus, cut.face_plus])
        other = np.concatenate([cut.face_plus, cut.face_minus])
        area = np.concatenate([cut.face_area, cut.face_area])
        is_small = np.zeros(P, bool)
        is_small[small] = True
        pick = np.nonzero(is_small[ends])[0]
        # prefer neighbours that are not small themselves, then the larger interface
        order = np.lexsort((area[pick], ~is_small[other[pick]]))
        best = {}
        for i in pick[order]:
            best[int(ends[i])] = int(other[i])
        for p in sorted(best, key=lambda q: fraction[q]):
            a, b = root(p), root(best[p])
            if a != b:
                keep, drop = (a, b) if cut.volume[a] >= cut.volume[b] else (b, a)
                parent[drop] = keep
                merged += 1
    roots = np.array([root(p) for p in range(P)])
    # the host of a union is its largest piece; union-find keeps it as the root
    hosts, piece_element = np.unique(roots, return_inverse=True)
    E = len(hosts)
    cell = cut.piece_cell[hosts]
    full = cut.full[hosts] & (np.bincount(piece_element, minlength=E) == 1)
    offset = (cut.piece_cell - cell[piece_element]).astype(np.float64)  # [P, 3] cells from the host frame
    moved = np.any(offset != 0, axis=1)
    moments = np.array(cut.moments, dtype=np.float64)
    if np.any(moved):
        moments[moved] = shift_moments(moments[moved], cut.degree, -offset[moved])
    element_moments = np.zeros((E, moments.shape[1]))
    np.add.at(element_moments, piece_element, moments)
    volume = np.bincount(piece_element, weights=cut.volume, minlength=E)

    minus, plus = piece_element[cut.face_minus], piece_element[cut.face_plus]
    keep = minus != plus
    warnings = []
    if merged:
        warnings.append(f"{merged} cut piece(s) below {merge_fraction:g} of a cell merged into a face neighbour "
                        "(DG elements may be non-convex unions)")
    lonely = np.setdiff1d(small, np.concatenate([cut.face_minus, cut.face_plus]))
    if len(lonely):
        warnings.append(f"{len(lonely)} piece(s) below {merge_fraction:g} of a cell touch no other piece (a body "
                        "smaller than a cell); they are kept as elements of their own")
    boundary_element = piece_element[cut.boundary_piece]
    order = np.argsort(boundary_element, kind="stable")
    return Elements(
        grid=grid, cell=cell, full=full, volume=volume, moments=element_moments,
        minus=minus[keep], plus=plus[keep], axis=cut.face_axis[keep], area=cut.face_area[keep],
        face_moments=cut.face_moments[keep], face_cell=cut.piece_cell[cut.face_minus[keep]],
        boundary_element=boundary_element[order], boundary_triangles=cut.boundary_triangles[order],
        piece_element=piece_element, merged=merged, warnings=warnings,
    )
