"""Hex slicing for the DG method: the solid cut by the grid planes into per-cell pieces.

``slice_cells(surface, grid)`` cuts the closed surface with manifold3d by recursive bisection
along grid planes (a region whose volume equals its box is emitted as full cells without further
cuts), splits every cell's part into connected pieces, and computes exact polynomial moments of
each piece, of each interface (connected part of a grid face shared by two pieces) and the
surface triangles bounding each piece (for Nitsche conditions and loads). The bisection and the
per-piece integrals run in worker processes (``bisection``); this module checks the input,
orders the pieces and pairs the interfaces.

Grid-plane faces of a piece are recognised geometrically (all vertices on the cell's plane
``x_a = origin_a + h i`` to 1e-9 h, normal pointing out of the cell). Whether such a face is an
interface or surface is decided by the neighbouring cell: where the neighbour's piece has the
same region with the opposite normal (equal area moments) it is an interface; where it does not
(a surface of the mesh lying in a grid plane, e.g. a box aligned with the grid) the regions are
intersected and differenced in 2D (shapely) and the remainder becomes surface.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace

import manifold3d
import numpy as np
import shapely

from ..errors import GeometryError
from ..grid import Grid
from .bisection import bisect_pieces, start_workers, stop_workers
from .moments import area_terms, cell_face_moments, cell_moments, monomial_exponents, shift_moments
from .surface import Surface

_MATCH_TOL = 1e-9  # [h^2 units] area moments of the two sides of an interface must agree this well
_SLIVER = 1e-12  # [h^2] 2D remainders smaller than this are round-off, not surface


@dataclass
class CutCells:
    """The DG elements: connected pieces of (grid cell ∩ solid), sparse over touched cells.

    Moments use xi = (x - c)/h with c the centre of the piece's cell and h the grid spacing:
    ``moments[p, i] = int_piece xi^alpha_i dV / h^3`` with alpha = ``exponents[i]``
    (``monomial_exponents(3, degree)``). Full cells carry ``cell_moments(degree)``.

    Interfaces (interior DG faces) f: ``face_minus[f]`` / ``face_plus[f]`` are the pieces on the
    low / high side along ``face_axis[f]``; the face normal is +e_axis (minus -> plus).
    ``face_moments[f, i] = int_f xi^alpha_i dA / h^2`` about the centre of the *minus* piece's
    cell (so xi_axis = +1/2 on the face); re-centre for the plus side with
    ``moments.shift_moments(face_moments, degree, e_axis)``.

    Boundary: ``boundary_triangles[t]`` [3, 3] (absolute coordinates [m], outward normal by the
    right-hand rule) is a piece of the mesh surface bounding piece ``boundary_piece[t]``
    (sorted by piece). Grid-plane faces of a piece are never boundary unless the surface itself
    lies in the grid plane there.
    """

    grid: Grid
    degree: int
    exponents: np.ndarray
    piece_cell: np.ndarray
    full: np.ndarray
    volume: np.ndarray
    moments: np.ndarray
    face_minus: np.ndarray
    face_plus: np.ndarray
    face_axis: np.ndarray
    face_area: np.ndarray
    face_moments: np.ndarray
    boundary_piece: np.ndarray
    boundary_triangles: np.ndarray
    warnings: list[str] = field(default_factory=list)

    @property
    def num_pieces(self) -> int:
        return int(self.piece_cell.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.face_axis.shape[0])

    def piece_centers(self) -> np.ndarray:
        """Centres [P, 3] [m] of the pieces' cells: the origin of each piece's xi coordinates."""
        return self.grid.sample_points(self.piece_cell)

    def closure_error(self) -> float:
        """max over pieces of |sum of outward area vectors| / h^2 (interfaces + boundary): 0 for
        closed pieces; a check that no face went missing or was counted twice."""
        if self.num_pieces == 0:
            return 0.0
        total = np.zeros((self.num_pieces, 3))
        vec = np.eye(3)[self.face_axis] * self.face_area[:, None]
        np.add.at(total, self.face_minus, vec)
        np.add.at(total, self.face_plus, -vec)
        t = self.boundary_triangles
        np.add.at(total, self.boundary_piece, 0.5 * np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
        return float(np.abs(total).max() / self.grid.spacing**2)


def slice_cells(surface: Surface, grid: Grid, degree: int = 4, *, min_fraction: float = 1e-12,
                workers: int | None = None, stats: dict | None = None) -> CutCells:
    """Slice the closed surface by the grid into DG pieces with exact moments up to ``degree``.

    min_fraction: pieces smaller than this fraction of h^3 are round-off slivers and dropped (counted
    in ``stats``, no warning). workers: worker processes for the bisection (each on its own CPU); None picks 1
    for small jobs and up to 4 (the CPUs available) where the estimated bisection time exceeds
    ~2 s; if workers cannot start (or one fails), the bisection runs here. The result is the same
    bit for bit with any number of workers. stats, if given, receives seconds per stage
    ("manifold": starting the workers and building the solid, "bisect": cutting and integrating
    the pieces, "moments_and_faces": ordering them and pairing interfaces), the process count
    ("workers"), the parts handed between workers ("parts_moved"), the number of grid faces
    that needed 2D booleans because a surface lies in them ("faces_resolved_2d") and the round-off
    pieces dropped ("dropped", "dropped_volume" [m^3]).
    Raises GeometryError for a 2D, open, non-manifold or inside-out surface.
    """
    if not isinstance(degree, (int, np.integer)) or degree < 0:
        raise GeometryError(f"slice_cells: degree must be an integer >= 0, got {degree!r}")
    if grid.dim != 3:
        raise GeometryError(f"slice_cells: hex slicing needs a 3D grid, got a {grid.dim}D grid")
    _check_surface(surface)
    # Cut in the grid's own frame (origin at 0): manifold3d's tolerances and the grid-plane tests
    # scale with the coordinates' magnitude, and a part placed 1e6 m from the origin (survey
    # coordinates) lost its interfaces (elements left unconnected, a silently wrong solution).
    # And in its units (cells of size 1): manifold3d's splits lose solids of about 1e-12 in size,
    # and a part 1e-11 m long (cells of 6e-13 m) came out with no piece at all.
    shift, h = np.asarray(grid.origin, dtype=float), float(grid.spacing)
    world = grid
    grid = replace(grid, origin=(0.0,) * 3, spacing=1.0)
    surface = replace(surface, vertices=(np.asarray(surface.vertices, dtype=float) - shift) / h)
    clock = time.perf_counter()
    # Workers boot while the solid is built and cut in two.
    procs = start_workers(_auto_workers(surface, grid) if workers is None else workers)
    try:
        solid, warnings = _make_manifold(surface, grid)
        stamp = time.perf_counter()
        digests, info = bisect_pieces(solid, grid, int(degree), min_fraction, procs)
    finally:
        stop_workers(procs)
    stats = {} if stats is None else stats
    # no warning: pieces below round-off (a cube's faces on grid planes leave a dozen of 1e-18 m^3)
    # change no result and ask nothing of the user; the merged slivers above it keep theirs
    stats["dropped"] = sum(d["dropped"] for d in digests)
    stats["dropped_volume"] = sum(d["dropped_volume"] for d in digests) * h**3
    stats["manifold"] = stamp - clock
    stats["bisect"] = time.perf_counter() - stamp
    stats.update(info)
    stamp = time.perf_counter()
    cut = _assemble(digests, grid, int(degree), warnings, stats)
    stats["moments_and_faces"] = time.perf_counter() - stamp
    # moments are about cell centres in units of h: the measures and the surface pieces go back to metres
    return replace(cut, grid=world, volume=cut.volume * h**3, face_area=cut.face_area * h**2,
                   boundary_triangles=cut.boundary_triangles * h + shift)


def _check_surface(surface: Surface) -> None:
    """GeometryError unless the surface is a closed 3D triangle mesh with valid indices."""
    vertices, faces = np.asarray(surface.vertices), np.asarray(surface.faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise GeometryError(
            f"slice_cells: needs a 3D triangle surface, got vertices {vertices.shape} and faces {faces.shape}")
    if faces.shape[0] == 0:
        raise GeometryError("slice_cells: the surface has no triangles")
    if not np.issubdtype(faces.dtype, np.integer) or faces.min() < 0 or faces.max() >= len(vertices):
        raise GeometryError(f"slice_cells: face vertex indices must be integers in [0, {len(vertices)})")
    if not np.all(np.isfinite(vertices)):
        raise GeometryError("slice_cells: the surface has non-finite vertex coordinates")
    if not surface.closed:
        raise GeometryError("slice_cells: the surface is not closed; hex slicing needs a watertight mesh")


def _make_manifold(surface: Surface, grid: Grid) -> tuple[manifold3d.Manifold, list[str]]:
    """The (checked) solid as a manifold3d object (f64), trimmed to the grid box; GeometryError
    if it is not an oriented 2-manifold enclosing a positive volume."""
    vertices = np.array(surface.vertices, dtype=np.float64, order="C")  # writable copy: nanobind rejects read-only
    faces = np.asarray(surface.faces)
    solid = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=vertices,
                                                  tri_verts=np.array(faces, dtype=np.uint64, order="C")))
    status = solid.status()
    if status != manifold3d.Error.NoError:
        raise GeometryError(f"slice_cells: the surface is not an oriented 2-manifold (manifold3d: {status.name})")
    volume = solid.volume()
    if not volume > 0:
        raise GeometryError(f"slice_cells: the surface encloses no volume ({volume:.3g}); is it inside out?")
    warnings: list[str] = []
    bounds = np.array(solid.bounding_box())
    lower, upper = np.asarray(grid.origin, dtype=float), grid.upper
    if np.any(bounds[:3] < lower) or np.any(bounds[3:] > upper):
        for a in range(3):
            normal = np.zeros(3)
            normal[a] = 1.0
            solid = solid.trim_by_plane(normal, float(lower[a]))
            solid = solid.trim_by_plane(-normal, -float(upper[a]))
        kept = solid.volume()
        warnings.append(f"the surface extends outside the grid; {100 * (1 - kept / volume):.3g}% of its volume "
                        "outside the grid box was dropped")
    return solid, warnings


def _auto_workers(surface: Surface, grid: Grid) -> int:
    """Processes worth starting: each costs ~0.5 s to spawn, the bisection ~0.5 ms per cut cell
    (estimated from the surface area) plus ~1 us per triangle and tree level."""
    p = np.asarray(surface.vertices, dtype=float)[np.asarray(surface.faces)]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    estimate = 5e-4 * 1.5 * area / grid.spacing**2 + 1e-6 * len(p) * np.log2(max(grid.num_cells, 2))
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return min(cpus, 4) if estimate > 2.0 else 1


def _assemble(digests: list[dict], grid: Grid, degree: int, warnings: list[str], stats: dict) -> CutCells:
    """Order the pieces by cell, place their moments, pair interfaces, collect boundary triangles."""
    cat = {key: np.concatenate([d[key] for d in digests]) for key in digests[0]
           if key not in ("dropped", "dropped_volume")}
    # Re-base the digests' local piece and component indices.
    piece_base = np.cumsum([0] + [len(d["cells"]) for d in digests])[:-1]
    comp_base = np.cumsum([0] + [len(d["comp_piece"]) for d in digests])[:-1]
    for key, base in (("surf_piece", piece_base), ("comp_piece", piece_base), ("plane_comp", comp_base)):
        cat[key] = cat[key] + np.repeat(base, [len(d[key]) for d in digests])
    full_cells = _box_cells(cat["full_lo"], cat["full_hi"])
    cells = np.concatenate([full_cells, cat["cells"]])
    is_full = np.concatenate([np.ones(len(full_cells), bool), np.zeros(len(cat["cells"]), bool)])
    order = np.lexsort((np.arange(len(cells)), grid.linear_index(cells) if len(cells) else np.zeros(0)))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    piece_cell, full = cells[order], is_full[order]
    cut_rank = rank[len(full_cells):]
    moments = np.tile(cell_moments(degree), (len(piece_cell), 1))
    moments[cut_rank] = cat["moments"]
    volume = moments[:, 0] * grid.spacing**3
    if np.any(volume <= 0):
        warnings.append(f"{int(np.sum(volume <= 0))} pieces have non-positive volume after integration")
    faces, boundary = _faces(grid, degree, piece_cell, full, cat, cut_rank, stats)
    return CutCells(grid=grid, degree=degree, exponents=monomial_exponents(3, degree), piece_cell=piece_cell,
                    full=full, volume=volume, moments=moments, **faces, **boundary, warnings=warnings)


def _box_cells(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The cells [N, 3] of the boxes [lo, hi) ([F, 3] each), box by box, each in C order."""
    extent = hi - lo
    count = np.prod(extent, axis=1)
    box = np.repeat(np.arange(len(lo)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)  # C-order index in its box
    ey, ez = extent[box, 1], extent[box, 2]
    return lo[box] + np.stack([k // (ey * ez), (k // ez) % ey, k % ez], axis=1)


@dataclass
class _Rows:
    """The sides of grid faces, one row each: an edge-connected component of a cut piece's
    triangles in a grid face, or one face of a full cell.

    piece, axis, side (0: the piece lies below the face, normal +e_axis), comp (the component, -1
    for a full cell's face) [R]; low [R, 3]: the cell below the face; key [R]: the face as axis *
    cells + the low cell's index, a distinct negative number on the grid's outer faces (never
    paired). comp_piece [C], comp_moments [C, n]: each component's piece and area moments about
    its low cell's centre; tri_comp [T], tri_xyz [T, 3, 3] [m]: the components' triangles;
    ref_face [3, n]: the moments of a whole face normal to each axis.
    """

    piece: np.ndarray
    axis: np.ndarray
    side: np.ndarray
    comp: np.ndarray
    low: np.ndarray
    key: np.ndarray
    comp_piece: np.ndarray
    comp_moments: np.ndarray
    tri_comp: np.ndarray
    tri_xyz: np.ndarray
    ref_face: np.ndarray

    def moments(self, r: np.ndarray) -> np.ndarray:
        """Area moments [len(r), n] of rows ``r`` about their low cell's centre."""
        m = np.empty((len(r), self.ref_face.shape[1]))
        m[self.comp[r] >= 0] = self.comp_moments[self.comp[r][self.comp[r] >= 0]]
        m[self.comp[r] < 0] = self.ref_face[self.axis[r][self.comp[r] < 0]]
        return m

    def region(self, grid: Grid, r: int, centre: np.ndarray) -> np.ndarray | None:
        """Row ``r``'s triangles in xi about ``centre`` [3] [m]; None for a whole face of a full cell."""
        return None if self.comp[r] < 0 else (self.tri_xyz[self.tri_comp == self.comp[r]] - centre) / grid.spacing


@dataclass
class _Groups:
    """Rows grouped by face: ``order`` sorts rows by (key, side); group g is
    order[starts[g]:starts[g] + counts[g]], of which n_low[g] lie below the face."""

    order: np.ndarray
    starts: np.ndarray
    counts: np.ndarray
    n_low: np.ndarray

    def rows(self, g: int) -> np.ndarray:
        return self.order[self.starts[g]:self.starts[g] + self.counts[g]]


def _faces(grid: Grid, degree: int, piece_cell: np.ndarray, full: np.ndarray, cat: dict, cut_rank: np.ndarray,
           stats: dict) -> tuple[dict, dict]:
    """Pair the two sides of every grid face into interfaces; collect the surface triangles.

    cat: the concatenated digests (``bisection.digest``), cut_rank [len(cat["cells"])] the final
    index of each digested piece. Each side of a grid face contributes "rows": one per
    edge-connected component of a cut piece's triangles in that face, one per face of a full
    cell. Rows are grouped by face; the low side (L, normal +e_axis) and high side (H) of a group
    are paired by their area moments.
    """
    rows = _face_rows(grid, degree, piece_cell, full, cat, cut_rank)
    groups = _group(rows)
    found: list[tuple] = []  # interfaces (minus [k], plus [k], axis [k], moments [k, n])
    surface: list[tuple] = []  # boundary (piece [k], triangles [k, 3, 3])
    settled = _pair_bulk(rows, groups, found)
    lonely = (groups.n_low == 0) | (groups.n_low == groups.counts)
    _one_sided(grid, rows, groups, lonely, cat, cut_rank, surface)
    settled |= lonely
    stats["faces_resolved_2d"] = 0
    for g in np.flatnonzero(~settled):
        stats["faces_resolved_2d"] += _settle(grid, degree, rows, groups.rows(g), found, surface)
    return _collect(grid, found, surface, rows.ref_face.shape[1])


def _face_rows(grid: Grid, degree: int, piece_cell: np.ndarray, full: np.ndarray, cat: dict,
               cut_rank: np.ndarray) -> _Rows:
    """The rows of every grid face's sides: the digests' plane components, then six faces per full cell."""
    ref_face = cell_face_moments(degree)
    # Components ordered by piece, then first triangle (a piece's triangles all lie in one digest,
    # in their order there, so the final stable sort by piece orders them as one list would).
    comp_piece = cut_rank[cat["comp_piece"]]
    corder = np.argsort(comp_piece, kind="stable")
    renumber = np.empty_like(corder)
    renumber[corder] = np.arange(len(corder))
    comp_piece, comp_kind = comp_piece[corder], cat["comp_kind"][corder]
    n_comp = len(comp_piece)
    comp_axis, comp_side = comp_kind // 2, 1 - comp_kind % 2  # side 0: the piece is below the face
    # Face moments about the low cell's centre: xi_low = xi_piece + e_axis for pieces above.
    to_low = -np.eye(3)[comp_axis] * comp_side[:, None]
    comp_moments = shift_moments(cat["comp_moments"][corder], degree, to_low)

    fp = np.flatnonzero(full)
    f_axis = np.tile(np.arange(3), 2 * len(fp))
    piece = np.concatenate([comp_piece, np.repeat(fp, 6)])
    axis = np.concatenate([comp_axis, f_axis])
    side = np.concatenate([comp_side, np.tile(np.repeat([0, 1], 3), len(fp))])
    comp = np.concatenate([np.arange(n_comp), np.full(6 * len(fp), -1)])
    low = piece_cell[piece].copy()
    low[np.arange(len(low)), axis] -= side
    high = low.copy()
    high[np.arange(len(high)), axis] += 1
    inside = np.all(low >= 0, axis=1) & np.all(high < np.asarray(grid.shape), axis=1)
    key = axis * grid.num_cells + np.ravel_multi_index(tuple(np.clip(low, 0, np.asarray(grid.shape) - 1).T), grid.shape)
    key = np.where(inside, key, -1 - np.arange(len(key)))  # the grid's outer faces are never paired
    return _Rows(piece, axis, side, comp, low, key, comp_piece, comp_moments, renumber[cat["plane_comp"]],
                 cat["plane_xyz"], ref_face)


def _group(rows: _Rows) -> _Groups:
    """Rows sorted by face, low side first, with each face's extent and count of low rows."""
    key, side = rows.key, rows.side
    order = np.lexsort((side, key))
    starts = np.flatnonzero(np.r_[True, key[order][1:] != key[order][:-1]]) if len(key) else np.zeros(0, int)
    counts = np.diff(np.r_[starts, len(key)])
    n_low = np.add.reduceat((side[order] == 0).astype(np.int64), starts) if len(starts) else np.zeros(0, int)
    return _Groups(order, starts, counts, n_low)


def _pair_bulk(rows: _Rows, groups: _Groups, found: list) -> np.ndarray:
    """The bulk: faces with one row per side and equal moments (full-full faces and generic cuts)
    become interfaces (appended to ``found``); returns which groups [G] that settled."""
    pair = np.flatnonzero((groups.counts == 2) & (groups.n_low == 1))
    r0, r1 = groups.order[groups.starts[pair]], groups.order[groups.starts[pair] + 1]
    comp = rows.comp
    cut = (comp[r0] >= 0) & (comp[r1] >= 0)  # a full side makes a whole face: only these need checking
    half = (comp[r0] >= 0) != (comp[r1] >= 0)
    ok = np.ones(len(pair), dtype=bool)
    m0, m1 = rows.comp_moments[comp[r0[cut]]], rows.comp_moments[comp[r1[cut]]]
    ok[cut] = np.max(np.abs(m0 - m1), axis=1) <= _MATCH_TOL
    ok[half] = np.max(np.abs(rows.moments(r0[half]) - rows.moments(r1[half])), axis=1) <= _MATCH_TOL
    f_mom = rows.ref_face[rows.axis[r0]]
    f_mom[cut] = 0.5 * (m0 + m1)
    found.append((rows.piece[r0[ok]], rows.piece[r1[ok]], rows.axis[r0[ok]], f_mom[ok]))
    settled = np.zeros(len(groups.starts), dtype=bool)
    settled[pair[ok]] = True
    return settled


def _one_sided(grid: Grid, rows: _Rows, groups: _Groups, lonely: np.ndarray, cat: dict, cut_rank: np.ndarray,
               surface: list) -> None:
    """Surface triangles: the pieces' own (not in a grid plane), then the one-sided groups ``lonely``
    [G] (a surface lying in a grid plane, the grid's outer faces), all appended to ``surface``."""
    alone = groups.order[np.repeat(lonely, groups.counts)]
    surface.append((cut_rank[cat["surf_piece"]], cat["surf_xyz"]))
    in_alone = np.isin(rows.tri_comp, rows.comp[alone][rows.comp[alone] >= 0])
    surface.append((rows.comp_piece[rows.tri_comp[in_alone]], rows.tri_xyz[in_alone]))
    whole = alone[rows.comp[alone] < 0]
    surface.append((np.repeat(rows.piece[whole], 2), _squares(grid, rows.low[whole], rows.axis[whole],
                                                              rows.side[whole])))


def _settle(grid: Grid, degree: int, rows: _Rows, group: np.ndarray, found: list, surface: list) -> int:
    """One face where several pieces meet or the two sides differ (surface in the plane): pair its
    rows by moments where they match one to one, else resolve it in 2D. Returns 1 when resolved in 2D."""
    rl, rh = group[rows.side[group] == 0], group[rows.side[group] == 1]
    piece, axis = rows.piece, rows.axis
    matched = _match(rows.moments(rl), rows.moments(rh))
    if matched is not None:
        found += [(piece[rl[[i]]], piece[rh[[j]]], axis[rl[[i]]],
                   0.5 * (rows.moments(rl[[i]]) + rows.moments(rh[[j]]))) for i, j in matched]
        return 0

    def region(r: int, centre: np.ndarray) -> np.ndarray | None:
        return rows.region(grid, r, centre)

    _resolve_face(grid, degree, int(axis[group[0]]), rows.low[group[0]], piece[rl], piece[rh], region, rl, rh,
                  found, surface)
    return 1


def _collect(grid: Grid, found: list, surface: list, n_mon: int) -> tuple[dict, dict]:
    """The interfaces ordered by (minus, plus) and the boundary triangles by piece, as CutCells fields."""
    minus, plus, f_axis, f_mom = (np.concatenate(parts) for parts in zip(*found))
    forder = np.lexsort((plus, minus))
    f_mom = f_mom.reshape(-1, n_mon)[forder]
    faces = {"face_minus": minus[forder].astype(np.int64), "face_plus": plus[forder].astype(np.int64),
             "face_axis": f_axis[forder].astype(np.int64), "face_area": f_mom[:, 0] * grid.spacing**2,
             "face_moments": f_mom}
    b_piece, b_tri = (np.concatenate(parts) for parts in zip(*surface))
    border = np.argsort(b_piece, kind="stable")
    return faces, {"boundary_piece": b_piece[border].astype(np.int64),
                   "boundary_triangles": b_tri.reshape(-1, 3, 3)[border]}


def _match(low: np.ndarray, high: np.ndarray) -> list[tuple[int, int]] | None:
    """Bijection between the rows of two moment tables that agree to _MATCH_TOL, or None."""
    if len(low) != len(high):
        return None
    close = np.max(np.abs(low[:, None, :] - high[None, :, :]), axis=2) <= _MATCH_TOL
    if not (np.all(close.sum(axis=1) == 1) and np.all(close.sum(axis=0) == 1)):
        return None
    return [(i, int(np.flatnonzero(close[i])[0])) for i in range(len(low))]


def _squares(grid: Grid, low_cell: np.ndarray, axis: np.ndarray, side: np.ndarray) -> np.ndarray:
    """Whole grid faces above ``low_cell`` [k, 3] as triangles [2k, 3, 3], normal +e_axis for side
    0 and -e_axis for side 1."""
    b, c = (axis + 1) % 3, (axis + 2) % 3
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    corner = np.zeros((len(axis), 4, 3))
    rows = np.arange(len(axis))[:, None]
    corner[rows, :, axis[:, None]] = 1.0
    corner[rows, :, b[:, None]] = uv[:, 0]
    corner[rows, :, c[:, None]] = uv[:, 1]
    pts = np.asarray(grid.origin) + grid.spacing * (low_cell[:, None, :] + corner)
    idx = np.where(side[:, None, None] == 0, np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0, 2, 1], [0, 3, 2]]))
    return pts[rows[:, :, None], idx].reshape(-1, 3, 3)


def _resolve_face(grid: Grid, degree: int, axis: int, low_cell: np.ndarray, low_piece: np.ndarray,
                  high_piece: np.ndarray, region, low_rows, high_rows, found: list, surface: list) -> None:
    """2D booleans for one grid face whose sides differ: interfaces = L ∩ H per piece pair (each
    connected part its own interface), surface = L - H and H - L. ``region(row, centre)`` gives a
    row's triangles in xi about ``centre`` (None for a whole face of a full cell)."""
    h = grid.spacing
    b, c = (axis + 1) % 3, (axis + 2) % 3
    centre = grid.sample_points(low_cell[None, :])[0]

    def polygon(r: int):
        t = region(r, centre)
        if t is None:
            return shapely.box(-0.5, -0.5, 0.5, 0.5)
        tris = shapely.polygons(t[:, :, [b, c]])
        return shapely.union_all(tris[shapely.area(tris) > 0])

    lows, highs = [polygon(r) for r in low_rows], [polygon(r) for r in high_rows]
    for pl, p_low in zip(lows, low_piece):
        for ph, p_high in zip(highs, high_piece):
            for part in _polygons(pl.intersection(ph)):
                xi = (_lift(part, axis, centre, h, +1) - centre) / h
                found.append((np.array([p_low]), np.array([p_high]), np.array([axis]),
                              area_terms(xi, degree).sum(axis=0)[None, :]))
    for mine, pieces, other, sign in ((lows, low_piece, highs, +1), (highs, high_piece, lows, -1)):
        rest_of = shapely.union_all(other)
        for p, owner in zip(mine, pieces):
            for part in _polygons(p.difference(rest_of)):
                tris = _lift(part, axis, centre, h, sign)
                surface.append((np.full(len(tris), owner), tris))


def _polygons(geometry) -> list:
    """The polygons of a shapely result with area above the round-off threshold."""
    parts = shapely.get_parts(geometry)
    return [p for p in parts if isinstance(p, shapely.Polygon) and p.area > _SLIVER]


def _lift(polygon, axis: int, centre: np.ndarray, h: float, sign: int) -> np.ndarray:
    """Triangulate a polygon in the face plane (xi_axis = +1/2) into [k, 3, 3] absolute triangles
    with normal ``sign * e_axis``."""
    b, c = (axis + 1) % 3, (axis + 2) % 3  # e_b x e_c = e_axis
    tri2 = shapely.get_coordinates(shapely.constrained_delaunay_triangles(polygon)).reshape(-1, 4, 2)[:, :3]
    xi = np.zeros(tri2.shape[:2] + (3,))
    xi[:, :, axis] = 0.5
    xi[:, :, b], xi[:, :, c] = tri2[:, :, 0], tri2[:, :, 1]
    ccw = (tri2[:, 1, 0] - tri2[:, 0, 0]) * (tri2[:, 2, 1] - tri2[:, 0, 1]) \
        - (tri2[:, 1, 1] - tri2[:, 0, 1]) * (tri2[:, 2, 0] - tri2[:, 0, 0])
    flip = (ccw > 0) != (sign > 0)
    xi[flip] = xi[flip][:, ::-1]
    return centre + h * xi
