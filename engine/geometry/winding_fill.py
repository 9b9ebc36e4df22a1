"""Volume fractions of an OPEN surface: the solid is where the generalized winding number w >= 1/2.

An open surface S (holes, flipped or missing facets) has no inside in the scan-conversion sense, but
its generalized winding number w_S (Jacobson et al. 2013) still is: w_S jumps by exactly one across
every facet and varies smoothly elsewhere, only its boundary (the holes' rims) spreading it away from
the integers. This module splits w_S into an exact part and a small, local, smooth part:

1. The boundary chain dS (edges not cancelled by an oppositely oriented twin; 2D: end points) is
   closed off by cone caps H, one per connected hole rim: the triangles (hub, b, a) over each rim
   edge a -> b, hub = mean of the rim's vertices (2D: segments between each end point and the hub
   of its connected piece). S + H is a closed surface, so its indicator chi is an integer and its
   exact sub-cell volumes come from the scan conversion of ``fractions.py``.
2. w_S = chi - w_H. Where a sub-cell B meets no cap facet and |w_H| < 1/2 all over B,
   w_S >= 1/2  <=>  chi >= 1, so the solid volume in B is the exact scan volume of S + H.
   |w_H| over B is bounded by its value at B's centre plus B's circumradius times a Biot-Savart
   bound of |grad w_H| from the rim edges (dH = -dS); a hierarchy of blocks (tiles of 16 sub-cells,
   then 8, 4, 2, 1) certifies whole regions with one evaluation each.
3. The rest (near the rims and the caps) is probed at sub-cell centres: w_S = chi - w_H exactly
   (chi by a robust signed ray count among the facets over the point's column, w_H by the cap's
   solid angles) with its gradient (Biot-Savart over dS) and bounds of its variation and of its
   linearisation error over the sub-cell. A sub-cell no facet of S meets is smooth: it is uniform
   when w_S stays on one side of 1/2 (exact), else its fraction is that of the half-space where
   the linearised w_S >= 1/2 when that plane is provably within half a sampling step of the true
   level set (second-order accurate).
4. What is left (a facet of S or a rim in the sub-cell, or a level set too curved to linearise)
   is sampled at q^d points, fraction = the share of points with w_S >= 1/2 (first-order
   accurate, not exact).

A closed surface flagged open has no rim: no cap, nothing probed, the result is the exact scan.
The work is O(blocks near rims x rim size + probes x (column facets + rim size) + samples x
(column facets + cap size)); each stage is estimated before it runs and refused when the total
would pass ``MAX_PAIRS`` point-facet evaluations.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import GeometryError
from ..grid import Grid
from .fractions import TILE, _check_inside, scan_slabs, slab_tiles
from .surface import Surface
from .topology import rim_edges

# Sample points per axis in a sampled sub-cell, by dimension (q^d points each).
SAMPLES_PER_AXIS = {2: 4, 3: 2}
# Point-facet evaluations allowed for one surface: 4e7 to 1.2e8 per second were measured on 2
# shared cores, so 25 to 75 s there (the dense alternative costs sub-cells x q^d x all facets).
MAX_PAIRS = 3e9
_BLOCK = 2 * TILE  # sub-cells per tile edge: the coarsest certified block and the column width


@dataclass
class Closure:
    """An open surface S closed by cone caps H over its holes; geometry in sub-cell units.

    closed: S + H as a closed Surface in metres (vertices [m + hubs, d], faces [k + C, d]).
    facets: [k + C, d, d] corners of the facets of S + H (S first); cap: [C, d, d] those of H.
    rims: [E, 2, d] boundary edges of S, oriented (2D: each boundary point as a zero-length edge);
      weight: [E] their multiplicity (3D: > 1 where facets repeat or are flipped; 2D: signed,
      segments ending at the point minus segments starting there).
    holes: connected rims (3D) / open pieces (2D).
    columns: the facets bucketed by grid columns, for ray counts.
    origin, unit: a point x [m] is (x - origin) / unit in sub-cell units (unit = h / 2).
    """

    closed: Surface
    facets: np.ndarray
    cap: np.ndarray
    rims: np.ndarray
    weight: np.ndarray
    holes: int
    columns: _Columns
    origin: np.ndarray
    unit: float

    @property
    def dim(self) -> int:
        return self.closed.dim

    @property
    def surface_facets(self) -> int:
        return len(self.facets) - len(self.cap)

    def winding_number(self, points: np.ndarray) -> np.ndarray:
        """Generalized winding number [n] of the open surface at ``points`` [n, d] [m], exact up
        to round-off (the closed indicator by a ray count minus the caps' winding number)."""
        from ..runtime import ensure_initialized

        ensure_initialized()
        return _sample(self, (np.asarray(points, dtype=np.float64) - self.origin) / self.unit)


def close_holes(surface: Surface, grid: Grid) -> Closure:
    """The boundary chain of ``surface`` and the cone caps that close it (module docstring, 1.).

    surface: inside the grid box (as for ``volume_fractions``); any orientation defects show up
    as rims of multiplicity 2 and are closed like holes.
    """
    d = surface.dim
    faces = np.asarray(surface.faces, dtype=np.int64)
    vertices = np.asarray(surface.vertices, dtype=np.float64)
    if d == 3:
        ends, mult = rim_edges(faces, len(vertices))
        labels = _components(ends, len(vertices))
        used = np.unique(ends)
    else:
        # boundary of a -> b is b - a: a rim point has multiplicity (segments in) - (segments out)
        mult_v = np.bincount(faces[:, 1], minlength=len(vertices)) - np.bincount(faces[:, 0], minlength=len(vertices))
        used = np.flatnonzero(mult_v)
        labels = _components(faces, len(vertices))
        mult = mult_v[used]
        ends = np.stack([used, used], axis=1)
    groups, group_of = np.unique(labels[used], return_inverse=True)
    hubs = np.zeros((len(groups), d))
    np.add.at(hubs, group_of, vertices[used])
    hubs /= np.maximum(np.bincount(group_of, minlength=len(groups)), 1)[:, None]
    hub_index = len(vertices) + np.searchsorted(groups, labels[ends[:, 0]])
    if d == 3:
        # (hub, b, a) over a -> b: the cap's boundary is -dS, so S + H has none
        cap_faces = np.stack([hub_index, ends[:, 1], ends[:, 0]], axis=1)
    else:
        v = ends[:, 0]
        cap_faces = np.where((mult > 0)[:, None], np.stack([v, hub_index], 1), np.stack([hub_index, v], 1))
    cap_faces = np.repeat(cap_faces, np.abs(mult), axis=0)
    all_vertices = np.concatenate([vertices, hubs])
    closed = Surface(all_vertices, np.concatenate([faces, cap_faces]), closed=True)
    origin, unit = np.asarray(grid.origin, dtype=np.float64), 0.5 * grid.spacing
    units = (all_vertices - origin) / unit
    facets = units[closed.faces]
    return Closure(
        closed=closed,
        facets=facets,
        cap=units[cap_faces],
        rims=units[ends],
        weight=mult.astype(np.float64),
        holes=len(groups),
        columns=_Columns(facets, slab_tiles(grid)[: d - 1]),
        origin=origin,
        unit=unit,
    )


def winding_slabs(
    surface: Surface,
    grid: Grid,
    tiles: list[int],
    warnings: list[str],
    *,
    samples_per_axis: int | None = None,
    max_pairs: float = MAX_PAIRS,
) -> Iterator[np.ndarray]:
    """Solid fraction of every sub-cell of an open surface, one slab of tiles along x at a time.

    Same contract as ``fractions.scan_slabs``: yields tiles[0] arrays of shape
    [2 TILE, 2 TILE tiles[1](, 2 TILE tiles[2])], zero beyond the grid. Exact up to round-off
    except in the linearised and sampled sub-cells near the holes; ``warnings`` gets one line with
    their numbers (none for a surface whose facets close up). Everything but the scan of the
    closed surface runs here, before the first slab: a surface whose estimated work exceeds
    ``max_pairs`` point-facet evaluations raises GeometryError before the work is done.
    samples_per_axis: q (default SAMPLES_PER_AXIS[d]).
    """
    from ..runtime import ensure_initialized

    ensure_initialized()
    d = grid.dim
    q = SAMPLES_PER_AXIS[d] if samples_per_axis is None else samples_per_axis
    if q < 1:
        raise ValueError(f"samples_per_axis: must be >= 1, got {q}")
    if len(surface.faces) == 0:
        raise GeometryError("geometry: the surface has no faces")
    closure = close_holes(surface, grid)
    _check_inside(closure.facets, grid)  # the scan would say so too, but only after the work below
    budget = _Budget(max_pairs, surface, closure, grid)
    budget.check("lower bound, from the sub-cells its boundary passes through", _least_work(closure, grid, q))
    uncertain = _uncertified_subcells(closure, 2 * np.asarray(grid.shape), budget)
    per_probe = 2 * closure.columns.sizes(uncertain) + len(closure.cap) + len(closure.rims)
    budget.charge("probing sub-cells", per_probe.sum())
    w, grad, spread, curvature = _probe(closure, uncertain)
    # smooth: w on one side of 1/2 over the whole sub-cell; linear: the level set w = 1/2 of the
    # linearised w is provably within half a sampling step (1 / 2q sub-cells) of the true one
    smooth = np.abs(w - 0.5) > spread
    linear = ~smooth & (curvature <= np.linalg.norm(grad, axis=1) / (2 * q))
    values = (w >= 0.5).astype(np.float64)
    values[linear] = halfspace_fraction(w[linear], grad[linear])
    known = _Overwrite(uncertain[smooth | linear], values[smooth | linear])
    sampled = uncertain[~(smooth | linear)]
    budget.charge("sampling", q**d * (closure.columns.sizes(sampled) + len(closure.cap)).sum())
    if len(closure.rims):
        warnings.append(
            f"surface is open ({len(closure.rims)} boundary {'edges' if d == 3 else 'points'}, "
            f"{closure.holes} hole(s)): the solid is where its generalized winding number is >= 1/2; sub-cell "
            "fractions are exact (scan of the surface closed by cone caps over the holes, or a certified winding "
            f"number) except near the holes: {int(linear.sum())} sub-cells from the linearised winding number "
            f"(second-order) and {len(sampled)} sampled with {q}^{d} = {q**d} points each (first-order accurate, "
            "not exact)"
        )
    return _slabs(closure, grid, tiles, known, _Overwrite(sampled), q)


def halfspace_fraction(w: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """Share [n] of the unit cube [0, 1]^d where w + grad . (x - 1/2) >= 1/2 (w [n], grad [n, d]).

    With every component of n = -grad made positive (reflect x_i -> 1 - x_i where it is not) and
    the largest scaled to 1, |{n . x <= t}| = sum_v (-1)^|v| max(t - n . v, 0)^k / (k! prod n)
    over the corners v of the k-cube of the components >= 1e-3; smaller ones are replaced by their
    mean over the cube (moving the plane by < 1e-3 sub-cells), which keeps the alternating sum's
    cancellation below ~1e-10.
    """
    n_vec = -np.asarray(grad, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    d = n_vec.shape[1]
    t = w - 0.5 + 0.5 * n_vec.sum(axis=1)  # n . x <= t  <=>  w + grad . (x - 1/2) >= 1/2
    t = t - np.where(n_vec < 0, n_vec, 0.0).sum(axis=1)
    n_vec = np.abs(n_vec)
    largest = n_vec.max(axis=1)
    flat = largest == 0.0
    scale = np.where(flat, 1.0, largest)
    n_vec, t = n_vec / scale[:, None], t / scale  # the region is scale-invariant
    small = n_vec < 1e-3
    t = t - 0.5 * np.where(small, n_vec, 0.0).sum(axis=1)
    n_vec = np.where(small, 0.0, n_vec)
    share = np.zeros(len(t))
    active = (~small).sum(axis=1)
    for k in range(1, d + 1):
        rows = np.flatnonzero((active == k) & ~flat)
        if len(rows) == 0:
            continue
        nk = -np.sort(-n_vec[rows], axis=1)[:, :k]  # the k non-zero components
        tk = np.clip(t[rows], 0.0, nk.sum(axis=1))
        total = np.zeros(len(rows))
        for v in itertools.product((0, 1), repeat=k):
            total += (-1) ** sum(v) * np.maximum(tk - nk @ np.array(v, dtype=np.float64), 0.0) ** k
        share[rows] = total / (math.factorial(k) * nk.prod(axis=1))
    share[flat] = (w[flat] >= 0.5).astype(np.float64)
    return np.clip(share, 0.0, 1.0)


def _slabs(
    closure: Closure, grid: Grid, tiles: list[int], known: _Overwrite, sampled: _Overwrite, q: int
) -> Iterator[np.ndarray]:
    d = grid.dim
    offsets = (np.arange(q) + 0.5) / q
    within = np.stack(np.meshgrid(*[offsets] * d, indexing="ij"), axis=-1).reshape(-1, d)  # [q^d, d]
    for tx, volume in enumerate(scan_slabs(closure.closed, grid, tiles)):
        _, values, index = known.slab(tx)
        volume[index] = values
        cells, _, index = sampled.slab(tx)
        if len(cells):
            points = (cells[:, None, :] + within[None]).reshape(-1, d)
            volume[index] = (_sample(closure, points).reshape(len(cells), -1) >= 0.5).mean(axis=1)
        yield volume


def _uncertified_subcells(closure: Closure, sub_shape: np.ndarray, budget: _Budget) -> np.ndarray:
    """Sub-cells [K, d] (int64) where |w_H| < 1/2 could not be certified: blocks of 16, 8, .. 1
    sub-cells; a block is certified by one bound evaluation, else its children are tried."""
    from . import kernels

    d = len(sub_shape)
    if len(closure.rims) == 0:
        return np.zeros((0, d), dtype=np.int64)
    size = _BLOCK
    blocks = np.stack(np.meshgrid(*[np.arange(-(-n // size)) for n in sub_shape], indexing="ij"), -1).reshape(-1, d)
    children = np.array(list(itertools.product((0, 1), repeat=d)))
    cap, rims = _facets_or_dummy(closure.cap), np.ascontiguousarray(closure.rims)
    while True:
        budget.charge(f"certifying blocks of {size} sub-cells", len(blocks) * (len(closure.cap) + len(rims)))
        w, spread = np.zeros(len(blocks)), np.zeros(len(blocks))
        centres = np.ascontiguousarray((blocks + 0.5) * size, dtype=np.float64)
        kernels.bound_cap_winding(cap, rims, closure.weight, centres, 0.5 * size, w, spread, d)
        blocks = blocks[np.abs(w) + spread >= 0.5]
        if size == 1 or len(blocks) == 0:
            return blocks.astype(np.int64)
        size //= 2
        blocks = (2 * blocks[:, None, :] + children[None]).reshape(-1, d)
        blocks = blocks[np.all(blocks * size < sub_shape, axis=1)]


def _probe(closure: Closure, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """At the centres of sub-cells [n, d]: the open surface's winding number [n], its gradient
    [n, d] (per sub-cell), a bound [n] of its variation over the sub-cell and one of the error of
    its linearisation (both huge where a facet of the surface meets the sub-cell)."""
    from . import kernels

    n, d = len(cells), closure.dim
    w, grad, spread, curvature = np.zeros(n), np.zeros((n, d)), np.zeros(n), np.zeros(n)
    if n:
        centres = np.ascontiguousarray(cells + 0.5, dtype=np.float64)
        kernels.probe_open_winding(
            _facets_or_dummy(closure.facets),
            closure.surface_facets,
            closure.columns.start,
            closure.columns.ids,
            _facets_or_dummy(closure.cap),
            np.ascontiguousarray(closure.rims),
            closure.weight,
            centres,
            closure.columns.of(centres),
            w,
            grad,
            spread,
            curvature,
            d,
        )
    return w, grad, spread, curvature


def _sample(closure: Closure, points: np.ndarray) -> np.ndarray:
    """Winding number [n] of the open surface at ``points`` [n, d] in sub-cell units."""
    from . import kernels

    out = np.zeros(len(points))
    if len(points):
        kernels.sample_open_winding(
            _facets_or_dummy(closure.facets),
            closure.columns.start,
            closure.columns.ids,
            _facets_or_dummy(closure.cap),
            np.ascontiguousarray(points, dtype=np.float64),
            closure.columns.of(points),
            out,
            closure.dim,
        )
    return out


def _least_work(closure: Closure, grid: Grid, q: int) -> float:
    """A lower bound of what the stages will charge. A block whose circumscribed ball holds a rim
    vertex cannot be certified (``rim_field``), nor can its ancestors (their balls hold its
    ball), so at every level at least 2^d children of each are evaluated; the sub-cells holding
    a rim vertex are probed and sampled (a facet of S meets them)."""
    d = grid.dim
    if len(closure.rims) == 0:
        return 0.0
    sub_shape = 2 * np.asarray(grid.shape)
    points = np.unique(closure.rims.reshape(-1, d), axis=0)
    near = np.array(list(itertools.product((-1, 0, 1), repeat=d)))
    per_point = len(closure.cap) + len(closure.rims)

    def blocked(size: int) -> int:
        blocks = np.floor(points / size).astype(np.int64)[:, None, :] + near[None]  # [n, 3^d, d]
        dist = np.linalg.norm((blocks + 0.5) * size - points[:, None, :], axis=2)
        held = blocks[(dist <= 0.5 * size * np.sqrt(d)) & np.all((blocks >= 0) & (blocks * size < sub_shape), axis=2)]
        return len(np.unique(held, axis=0))

    work = float(np.prod(-(-sub_shape // _BLOCK))) * per_point
    for size in (16, 8, 4, 2):
        work += 2**d * blocked(size) * per_point
    holding = len(np.unique(np.clip(np.floor(points), 0, sub_shape - 1).astype(np.int64), axis=0))
    return work + blocked(1) * per_point + holding * q**d * len(closure.cap)


class _Overwrite:
    """Values [n] (or none) for sub-cells [n, d], handed out slab by slab."""

    def __init__(self, cells: np.ndarray, values: np.ndarray | None = None):
        order = np.argsort(cells[:, 0], kind="stable")
        self.cells = cells[order]
        self.values = None if values is None else values[order]

    def slab(self, tx: int) -> tuple[np.ndarray, np.ndarray | None, tuple]:
        """(sub-cells [n, d], their values [n], index tuple into the slab) of slab ``tx``."""
        lo, hi = np.searchsorted(self.cells[:, 0], [_BLOCK * tx, _BLOCK * (tx + 1)])
        cells = self.cells[lo:hi]
        local = cells.copy()
        local[:, 0] -= _BLOCK * tx
        return cells, None if self.values is None else self.values[lo:hi], tuple(local.T)


class _Columns:
    """Facets [N, d, d] (sub-cell units) bucketed by the columns along the last axis of 16-sub-cell
    tiles (``ncols`` per axis) their bounding box meets, in CSR form (start, ids); points outside
    the columns get an extra, empty one (the facets lie inside the grid)."""

    def __init__(self, facets: np.ndarray, ncols: list[int]):
        d = facets.shape[-1]
        self.ncols = np.asarray(ncols, dtype=np.int64)
        cross = facets[:, :, : d - 1]  # coordinates across the columns
        lo = np.clip(np.floor(cross.min(axis=1) / _BLOCK).astype(np.int64), 0, self.ncols - 1)
        hi = np.clip(np.floor(cross.max(axis=1) / _BLOCK).astype(np.int64), 0, self.ncols - 1)
        span = hi - lo + 1
        count = span.prod(axis=1)
        facet = np.repeat(np.arange(len(facets)), count)
        rest = np.arange(len(facet)) - np.repeat(np.cumsum(count) - count, count)  # rank in its box
        index, stride = np.zeros(len(facet), dtype=np.int64), 1
        for a in reversed(range(d - 1)):  # unravel the rank, C order over the cross axes
            n_a = np.repeat(span[:, a], count)
            index += (np.repeat(lo[:, a], count) + rest % n_a) * stride
            rest, stride = rest // n_a, stride * int(self.ncols[a])
        total = int(self.ncols.prod())
        self.start = np.zeros(total + 2, dtype=np.int32)
        self.start[1 : total + 1] = np.cumsum(np.bincount(index, minlength=total))
        self.start[total + 1] = self.start[total]
        order = np.argsort(index, kind="stable")
        self.ids = np.ascontiguousarray(facet[order], dtype=np.int32) if len(facet) else np.zeros(1, np.int32)
        self.outside = total

    def of(self, points: np.ndarray) -> np.ndarray:
        """Column [n] (int32) of each point [n, d] (sub-cell units)."""
        d = points.shape[1]
        tile = np.floor(points[:, : d - 1] / _BLOCK).astype(np.int64)
        inside = np.all((tile >= 0) & (tile < self.ncols), axis=1)
        col = np.ravel_multi_index(tuple(np.clip(tile, 0, self.ncols - 1).T), tuple(self.ncols))
        return np.where(inside, col, self.outside).astype(np.int32)

    def sizes(self, cells: np.ndarray) -> np.ndarray:
        """Facets [n] over the column of each sub-cell [n, d]."""
        col = self.of(cells + 0.5)
        return (self.start[col + 1] - self.start[col]).astype(np.int64)


class _Budget:
    """Running count of point-facet evaluations; refuses a stage that would pass the limit."""

    def __init__(self, limit: float, surface: Surface, closure: Closure, grid: Grid):
        self.limit, self.spent = limit, 0.0
        self.what = (
            f"{len(surface.faces)} faces, {len(closure.rims)} boundary {'edges' if surface.dim == 3 else 'points'}, "
            f"{'x'.join(map(str, grid.shape))} cells"
        )

    def check(self, stage: str, pairs: float) -> None:
        """Refuse if ``pairs`` more evaluations would pass the limit."""
        if self.spent + pairs > self.limit:
            raise GeometryError(
                f"geometry: the open surface ({self.what}) needs about {self.spent + pairs:.3g} point-facet "
                f"evaluations of its winding number ({stage}), more than the limit of {self.limit:.3g}; "
                "close the mesh (fill its holes) or coarsen the grid"
            )

    def charge(self, stage: str, pairs: float) -> None:
        self.check(stage, pairs)
        self.spent += pairs


def _components(edges: np.ndarray, n: int) -> np.ndarray:
    """Connected-component label [n] of every vertex of the graph ``edges`` [E, 2]."""
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _facets_or_dummy(facets: np.ndarray) -> np.ndarray:
    """Kernels cannot take empty arrays: an empty set becomes one collapsed facet far away, which
    subtends no angle, meets no block and lies above no point."""
    if len(facets):
        return np.ascontiguousarray(facets, dtype=np.float64)
    d = facets.shape[-1]
    return np.full((1, d, d), -1e9)
