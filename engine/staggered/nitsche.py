"""Displacement boundaries of the staggered method: Nitsche's method on the surface patch.

A displacement boundary holds the solid's surface where its patch is, at sub-cell accuracy: the
discrete energy gains, at the patch's quadrature points x_q (weights w_q, outward normals n_q,
prescribed components P_q, values g_q),

    - sum_q w_q (sigma_h(u) n_q) . P_q (u_h(x_q) - g_q) + 1/2 sum_q w_q gamma_q |P_q (u_h(x_q) - g_q)|^2

where u_h is the multilinear interpolation of the samples that every output reads (in 2D with the
ghost samples outside the material, ``operator.make_fine_level``; a corner that is not an unknown
is dropped and the rest renormalised) and sigma_h the staggered stress of a *source cell* near x_q: normal
strains from the cell's faces, shear strains the edge-fraction-weighted mean of its four edges
per pair (the strains the energy weighs). Its Hessian S adds to the operator, its gradient at
u = 0 to the loads: symmetric, consistent (an exact solution leaves the first term zero), and
positive definite with the penalty below.

Coercivity. A cell s with fill m_s (the smaller of its cell fraction and, per axis pair, a quarter
of its four edge fractions) owns at least m_s h^d eps_s : C : eps_s of the energy a(v, v) (cell
terms wholly, a quarter of each edge), and |sigma n|^2 <= Lambda eps : C eps
(:func:`traction_bound`). With A_s the patch area whose flux s carries, Young's inequality
gives a_N(v, v) >= a(v, v) / 2 + sum_q w_q gamma_q / 2 |P v|^2 for
gamma_s = COERCIVITY A_s Lambda / (h^d m_s). A cut cell holding a sliver would need a huge
gamma_s, so a point's source is its own cell only when that cell's fill is at least TAU, else the
nearest cell of its 3^d block that has (the best filled one when none has): the flux is then one
cell off, still first order in h like the cell's own constant stress.

The operator is stored factored, S = mass - F Sig - (F Sig)^T on the DOFs it touches (compact
numbering): ``stress`` Sig [m, n] maps samples to the source cells' Voigt stresses, ``flux`` F
[n, m] the stresses to forces (sum_q w_q phi_I(x_q) P_q n_q), ``mass`` [n, n] the penalty; the
assembled product would hold ~8x more entries. Every multigrid level gets its own S from the
same patches, with a quadrature fitted to its spacing (rediscretised, like the volume terms).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..boundary import Prescribed, select_patch, surface_quadrature
from ..errors import BoundaryError
from ..geometry.surface import Surface
from ..grid import axis_pairs
from . import kernels
from .operator import Level
from .sampling import _corner_weights, _corners, _unique_rows, renormalised

TAU = 0.5  # a point's source cell is its own when that cell's fill reaches this
COERCIVITY = 8.0  # gamma_s over the smallest penalty that keeps a_N(v, v) >= a(v, v) / 2 (twice it)
MIN_FILL = 1e-3  # the fill a source cell is taken to have when no edge of a pair holds material


@dataclass(frozen=True)
class HoldQuadrature:
    """Quadrature of every displacement patch: points [Q, d] [m], weights [Q] [m^2 | m], unit
    outward normals [Q, d], prescribed components mask [Q, d] (0 / 1), values [Q, d] [m] (0 where
    free) and the boundary of each point [Q] (its index among the patches')."""

    points: np.ndarray
    weights: np.ndarray
    normals: np.ndarray
    mask: np.ndarray
    values: np.ndarray
    owner: np.ndarray

    def subset(self, keep: np.ndarray) -> HoldQuadrature:
        """The points where ``keep`` [Q] (bool)."""
        return HoldQuadrature(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))


@dataclass(frozen=True)
class HoldPatches:
    """The displacement boundaries' patches (pieces [M_k, d, d] per boundary), from which each
    multigrid level takes a quadrature fitted to its own spacing (:meth:`quadrature`): a coarse
    level's preconditioning operator needs no fine quadrature (4x fewer points per level); and the
    whole surface they lie on (every level's apertures, ``held``)."""

    prescribed: tuple[Prescribed, ...]
    pieces: tuple[np.ndarray, ...]
    surface: Surface | None = None

    def quadrature(self, spacing: float, merge: bool = False) -> HoldQuadrature:
        """The rule of :func:`engine.boundary.surface_quadrature` at ``spacing`` [m] on every patch;
        ``merge`` for a coarse level's (pieces much smaller than its cells merged into clusters)."""
        parts = []
        for k, (bc, pieces) in enumerate(zip(self.prescribed, self.pieces)):
            d = pieces.shape[-1]
            x, w, n = surface_quadrature(pieces, spacing, merge=merge)
            mask = np.broadcast_to(bc.mask(d).astype(float), (len(w), d))
            parts.append((x, w, n, mask, bc.values(x), np.full(len(w), k)))
        return HoldQuadrature(*(np.concatenate(p) for p in zip(*parts)))


def hold_patches(prescribed: list[Prescribed], surface: Surface) -> HoldPatches | None:
    """The patches of the displacement boundaries (None when there are none); a boundary whose
    region holds no surface is an error naming it."""
    if not prescribed:
        return None
    d = surface.dim
    facets = surface.vertices[surface.faces]
    pieces = tuple(select_patch(bc.region, facets, bc.name)[0].reshape(-1, d, d) for bc in prescribed)
    return HoldPatches(tuple(prescribed), pieces, surface)


@dataclass(frozen=True)
class HeldDivergence:
    """The held cut cells' finite-volume divergence (``held``): what their volumetric energy reads in
    place of tr(eps), so what their pressure is. ``keys`` [k] (a * size + position of the samples it
    reads), ``matrix`` [groups, k] [m^(d-1)] (D_S), ``flux`` [groups] [m^d] (G_S, the prescribed
    values' at scale 1), ``volume`` [groups] [m^d]; ``members`` [M, d] the cells, ``group`` [M] each
    one's group. A group's mean tr(eps) is (D_S u + s G_S) / V_S, s the prescribed values' scale."""

    keys: np.ndarray
    matrix: sp.csr_matrix
    flux: np.ndarray
    volume: np.ndarray
    members: np.ndarray
    group: np.ndarray

    def trace(self, u: np.ndarray, value_scale: float = 1.0) -> np.ndarray:
        """Each member's tr(eps) [M] [-] from the samples u [d, size]."""
        size = u.shape[1]
        values = u[self.keys // size, self.keys % size]
        return ((self.matrix @ values + value_scale * self.flux) / self.volume)[self.group]


@dataclass
class SurfaceOperator:
    """The Nitsche terms on one level: S = mass - flux stress - (flux stress)^T over the DOFs
    (comp [n], pos [n]) (sorted by comp * size + pos); ``rhs`` [n] [N] their load for the
    prescribed values at scale 1; ``diagonal`` [n] of S."""

    comp: np.ndarray
    pos: np.ndarray
    mass: sp.csr_matrix
    flux: sp.csr_matrix
    stress: sp.csr_matrix
    rhs: np.ndarray
    # the points (of the quadrature it was made from) in cut cells off the grid's planes that keep the
    # full terms although lambda / mu calls for the finite-volume divergence (``held``); None: no such call
    kept: np.ndarray | None = None
    # the part of ``mass`` that is bulk energy, not a hold (``flat_layers``): it holds no rigid mode
    bulk: sp.csr_matrix | None = None
    # the held cut cells' divergence (``held``), whose cells' pressure it is; None: no such cells
    divergence: HeldDivergence | None = None

    @property
    def hold_mass(self) -> sp.csr_matrix:
        """The holds' share of ``mass`` (what decides which rigid modes a body keeps)."""
        return self.mass if self.bulk is None else (self.mass - self.bulk).tocsr()

    def matrix(self) -> sp.csr_matrix:
        """S assembled [n, n] (for the coarsest level's factorisation and for tests)."""
        b = (self.flux @ self.stress).tocsr()
        return (self.mass - b - b.T).tocsr()

    @property
    def diagonal(self) -> np.ndarray:
        b = np.asarray(self.flux.multiply(self.stress.T.tocsr()).sum(axis=1)).ravel()
        return self.mass.diagonal() - 2.0 * b


def combined(parts: list[SurfaceOperator], size: int, extra: tuple[np.ndarray, sp.spmatrix, np.ndarray] | None = None
             ) -> SurfaceOperator:
    """One operator of the sum of ``parts`` (each on its own DOFs; their stresses and fluxes side by
    side) and ``extra`` = (sample keys a * size + position [k], a symmetric matrix [k, k] added to the
    mass, its load [k])."""
    keys = [p.comp.astype(np.int64) * size + p.pos for p in parts]
    if extra is not None:
        keys.append(extra[0])
    every = np.unique(np.concatenate(keys))
    n = len(every)
    maps = [sp.csr_matrix((np.ones(len(k)), (np.searchsorted(every, k), np.arange(len(k)))), (n, len(k))) for k in keys]
    mass = sum((m @ p.mass @ m.T for m, p in zip(maps, parts)), sp.csr_matrix((n, n)))
    rhs = sum((m @ p.rhs for m, p in zip(maps, parts)), np.zeros(n))
    if extra is not None:
        mass = mass + maps[-1] @ extra[1] @ maps[-1].T
        rhs = rhs + maps[-1] @ extra[2]
    flux = sp.hstack([m @ p.flux for m, p in zip(maps, parts)]).tocsr() if parts else sp.csr_matrix((n, 0))
    stress = sp.vstack([p.stress @ m.T for m, p in zip(maps, parts)]).tocsr() if parts else sp.csr_matrix((0, n))
    return SurfaceOperator(every // size, every % size, sp.csr_matrix(mass), flux, stress, rhs)


def with_bulk(operator: SurfaceOperator | None, extra: tuple[np.ndarray, sp.spmatrix, np.ndarray], size: int
              ) -> SurfaceOperator:
    """``operator`` (None: no holds) with the bulk energy correction ``extra`` (keys, matrix, load) added
    to its mass and remembered as its ``bulk``."""
    merged = combined([] if operator is None else [operator], size, extra)
    merged.kept = None if operator is None else operator.kept
    merged.divergence = None if operator is None else operator.divergence
    every = merged.comp.astype(np.int64) * size + merged.pos
    keys, matrix = extra[0], extra[1]
    m = sp.csr_matrix((np.ones(len(keys)), (np.searchsorted(every, keys), np.arange(len(keys)))), (len(every), len(keys)))
    merged.bulk = (m @ matrix @ m.T).tocsr()
    return merged


def make_surface_operator(level: Level, quad: HoldQuadrature, lam: float | None = None,
                          exclude: np.ndarray | None = None) -> SurfaceOperator:
    """The Nitsche terms of ``quad`` on ``level`` (whose ``origin`` must be known); ``lam`` [Pa]: the
    first Lame parameter of their flux and penalty, the level's by default; ``exclude``: layout
    positions of cells that may not be a point's source cell (their energy does not bound its flux)."""
    d, h, lay = level.dim, level.spacing, level.layout
    origin = np.asarray(level.origin, dtype=float)
    nv = d + len(axis_pairs(d))
    lam = level.lam if lam is None else float(lam)
    mu = level.mu
    big = traction_bound(lam, mu, d)
    x, w = quad.points, quad.weights
    src, sources, fill = _sources(level, np.floor((x - origin) / h).astype(np.int64), exclude)
    area = np.bincount(src, weights=w, minlength=len(sources))
    gamma = (COERCIVITY * big / h**d) * area / fill  # [sources]
    gw = w * gamma[src]  # w_q gamma_q
    size = level.size

    # stress functional Sig: rows s * nv + v (Voigt: normals, then pairs), columns sample keys
    s_rows, s_keys, s_vals = _stress_rows(level, sources, nv, lam)
    # interpolation of each component at the points, on the active samples, renormalised
    slots = []  # per component: sample keys [cells, 2^d], the slot sums and the (source, cell) pairs
    corners = _corners(d)
    k = len(corners)
    voigt = {a: [(a, a)] + [(d + q, b if p == a else p) for q, (p, b) in enumerate(axis_pairs(d)) if a in (p, b)]
             for a in range(d)}
    for a in range(d):
        on = np.nonzero(quad.mask[:, a] > 0)[0]
        if not len(on):
            continue
        shift = 0.5 - 0.5 * np.eye(d)[a]
        xi = (x[on] - origin) / h - shift
        base = np.floor(xi).astype(np.int64)
        phi = _corner_weights(xi - base)  # [N, 2^d]
        cells, cell_of, by_cell, cell_begin = _groups(base)
        near = (cells[:, None, :] + corners[None]).reshape(-1, d)
        near_pos = lay.positions(near)
        act = (near_pos >= 0) & level.active[a, np.maximum(near_pos, 0)]
        act = act.reshape(len(cells), k)[cell_of]
        if np.any(~act.any(axis=1)):
            bad = x[on][~act.any(axis=1)]
            raise BoundaryError(
                f"boundaries: {len(bad)} surface points of a displacement patch (near {np.round(bad[0], 6).tolist()} m) "
                "have no displacement sample in the material the grid resolves; refine the grid"
            )
        phi = renormalised(phi, act)
        pair_rows, _, by_pair, pair_begin = _groups(np.stack([src[on], cell_of], axis=1))
        vs = voigt[a]
        # sums over the points of each cell (penalty mass w gamma phi_I phi_J per (cell, I, J) slot,
        # its load w gamma g_a phi_I per (cell, I)) and of each (source, cell) pair (flux w phi_I n_j
        # per (pair, I, voigt slot)): a kernel per sum over the points sorted by cell or pair (numpy's
        # [points, 2^d, 2^d] products and bincounts were 2.3 of the 4.6 s this took on the 256^3 shell)
        sorted_phi = phi[by_cell]
        slot_mass = _segment_sums(cell_begin, gw[on[by_cell]], sorted_phi, sorted_phi)
        slot_pen = _segment_sums(cell_begin, (gw * quad.values[:, a])[on[by_cell]], sorted_phi, np.ones((len(on), 1)))
        at_pair = on[by_pair]
        slot_flux = _segment_sums(pair_begin, w[at_pair], phi[by_pair], quad.normals[at_pair][:, [j for _, j in vs]])
        slots.append((a * size + near_pos.reshape(-1, k), slot_mass, slot_pen[:, :, 0], slot_flux, pair_rows,
                      np.array([v for v, _ in vs])))
    # the compact numbering of every DOF the terms touch: the samples of the non-zero slots, found
    # per cell (2^d keys each) rather than per slot
    used = [s_keys]
    for key, slot_mass, _, slot_flux, pair_rows, _ in slots:
        used += [key[(slot_mass != 0).any(axis=2)], key[pair_rows[:, 1]][(slot_flux != 0).any(axis=2)]]
    every = np.unique(np.concatenate(used))
    n, m = len(every), len(sources) * nv
    at = lambda key: np.searchsorted(every, key)  # noqa: E731
    mass_r, mass_c, mass_v, flux_r, flux_c, flux_v = [], [], [], [], [], []
    rhs = np.zeros(n)  # load of the values: Phi^T (w gamma P g) - Sig^T h (below)
    for key, slot_mass, slot_pen, slot_flux, pair_rows, voigt_rows in slots:
        number = at(key)  # compact number of each cell's samples (only those of non-zero slots are read)
        nz = np.nonzero(slot_mass)
        mass_r.append(number[nz[0], nz[1]])
        mass_c.append(number[nz[0], nz[2]])
        mass_v.append(slot_mass[nz])
        nz = np.nonzero(slot_pen)
        np.add.at(rhs, number[nz], slot_pen[nz])
        nz = np.nonzero(slot_flux)
        flux_r.append(number[pair_rows[nz[0], 1], nz[1]])
        flux_c.append(pair_rows[nz[0], 0] * nv + voigt_rows[nz[2]])
        flux_v.append(slot_flux[nz])
    mass = sp.csr_matrix((np.concatenate(mass_v), (np.concatenate(mass_r), np.concatenate(mass_c))), (n, n))
    flux = sp.csr_matrix((np.concatenate(flux_v), (np.concatenate(flux_r), np.concatenate(flux_c))), (n, m))
    stress = sp.csr_matrix((s_vals, (s_rows, at(s_keys))), (m, n))
    # h_{s, v} = sum_q w_q (P g (x) n)_v, symmetrised
    hg = np.zeros(m)
    pg = quad.mask * quad.values
    for a in range(d):
        for v, j in voigt[a]:
            hg += np.bincount(src * nv + v, weights=w * pg[:, a] * quad.normals[:, j], minlength=m)
    rhs -= stress.T @ hg
    comp, pos = every // size, every % size
    return SurfaceOperator(comp, pos, mass, flux, stress, rhs)


def _groups(index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The distinct rows of integer index [N, d] (N > 0) in the order of ``sampling._unique_rows``,
    the row of each point [N], the points sorted by row (stable: each row's in their own order)
    [N] and where each row's points start among them [rows + 1] int32: one sort for all four."""
    lo = index.min(axis=0)
    dims = tuple(int(n) for n in index.max(axis=0) - lo + 1)
    key = np.ravel_multi_index(tuple((index - lo).T), dims)
    order = np.argsort(key, kind="stable")
    key = key[order]
    first = np.ones(len(key), dtype=bool)
    first[1:] = key[1:] != key[:-1]
    row = np.empty(len(key), dtype=np.int64)
    row[order] = np.cumsum(first) - 1
    begin = np.append(np.flatnonzero(first), len(key)).astype(np.int32)
    return np.stack(np.unravel_index(key[first], dims), axis=1) + lo, row, order, begin


def _segment_sums(begin: np.ndarray, w: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[segments, i, j] sums of w a_i b_j over the sorted points of each segment (``_groups``)."""
    out = np.empty((len(begin) - 1, a.shape[1], b.shape[1]))
    kernels.segment_products(begin, np.ascontiguousarray(w, dtype=np.float64), np.ascontiguousarray(a, dtype=np.float64),
                             np.ascontiguousarray(b, dtype=np.float64), out)
    return out


def traction_bound(lam: float, mu: float, d: int) -> float:
    """Lambda [Pa] with |sigma n|^2 <= Lambda eps : C eps for unit n: the largest eigenvalue of C
    (2 mu + d lambda, or 2 mu when lambda < 0), or, from |sigma n| <= 2 mu |eps| + |lambda tr eps|,
    max(4 mu, 2 lambda) when that is smaller (nu > 1/(2 + d) in 3D: 1.5x smaller as nu -> 1/2)."""
    if lam < 0:
        return 2.0 * mu
    return min(2.0 * mu + d * lam, max(4.0 * mu, 2.0 * lam))


def _sources(level: Level, cell: np.ndarray, exclude: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source cell of each point given its cell index [Q, d] (never one of the positions ``exclude``):
    (source number [Q], source cell indices [S, d], their fills [S] > 0)."""
    d = level.dim
    cells, cell_of = _unique_rows(cell)
    offsets = np.array(list(itertools.product((-1, 0, 1), repeat=d)), dtype=np.int64)
    cand = cells[:, None, :] + offsets[None]
    # the 3^d blocks of neighbouring cells overlap: each distinct cell's fill once (27 per cell
    # took 0.75 s on the 256^3 shell's fine level)
    distinct, which = _unique_rows(cand.reshape(-1, d))
    allowed = np.ones(len(distinct), dtype=bool) if exclude is None else ~np.isin(level.layout.positions(distinct), exclude)
    allowed = allowed[which].reshape(len(cells), -1)
    fill = cell_fill(level, distinct)[which].reshape(len(cells), -1) * allowed
    if np.any(fill.max(axis=1) <= 0):
        # material thinner than a cell with no edge holding it (a thin wall): take the cells' own
        # fractions; such walls stop the setup with the thin-feature error that names them
        fill = np.where(fill.max(axis=1, keepdims=True) > 0, fill,
                        _cell_fraction(level, cand.reshape(-1, d)).reshape(fill.shape) * allowed)
    if np.any(fill.max(axis=1) <= 0):
        raise BoundaryError("boundaries: a displacement patch lies where the grid resolves no material around it; "
                            "refine the grid")
    # any cell filled to TAU beats every other; among those the nearest, then the fuller
    distance = np.abs(offsets).sum(axis=1)
    score = np.where(fill >= TAU, 10.0 - distance[None, :] + 0.1 * fill, fill)
    chosen = cand[np.arange(len(cells)), score.argmax(axis=1)]
    sources, source_of = _unique_rows(chosen)
    own = cell_fill(level, sources)
    return source_of[cell_of], sources, np.where(own > 0, own, np.maximum(_cell_fraction(level, sources), MIN_FILL))


def _cell_fraction(level: Level, cell: np.ndarray) -> np.ndarray:
    """Cell fractions [N] of cells [N, d] (0 outside the kept tiles)."""
    pos = level.layout.positions(cell)
    return np.where(pos >= 0, level.vc_host[np.maximum(pos, 0)], 0.0)


def cell_fill(level: Level, cell: np.ndarray) -> np.ndarray:
    """Fill [N] of cells [N, d] (indices; outside the kept tiles: 0): the cell's fraction and, per
    axis pair, a quarter of the sum of its four edge fractions, whichever is least."""
    lay, d = level.layout, level.dim
    pos = lay.positions(cell)
    out = np.where(pos >= 0, level.vc_host[np.maximum(pos, 0)], 0.0)
    eye = np.eye(d, dtype=np.int64)
    corner = {}  # positions of the cells' corners, each found once (pairs share them)
    for q, (a, b) in enumerate(axis_pairs(d)):
        total = np.zeros(len(cell))
        for i, j in itertools.product((0, 1), repeat=2):
            o = tuple(i * eye[a] + j * eye[b])
            if o not in corner:
                corner[o] = lay.positions(cell + np.asarray(o))
            p = corner[o]
            total += np.where(p >= 0, level.ve_host[q, np.maximum(p, 0)], 0.0)
        out = np.minimum(out, 0.25 * total)
    return out


def _stress_rows(level: Level, cells: np.ndarray, nv: int, lam: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Voigt stresses of cells [S, d] as linear functionals of the samples: (rows s * nv + v,
    sample keys a * size + position, coefficients [Pa / m]). Normal strains from the cell's faces,
    shear strains the edge-fraction-weighted mean over its four edges (every cell here has fill > 0,
    so each pair has an edge that holds material and whose samples are active)."""
    lay, d, h, size = level.layout, level.dim, level.spacing, level.size
    mu = level.mu
    eye = np.eye(d, dtype=np.int64)
    s = np.arange(len(cells))
    rows, keys, vals = [], [], []

    def add(row, a, index, coef):
        pos = lay.positions(index)
        keep = (coef != 0) & (pos >= 0)
        rows.append(row[keep])
        keys.append(a * size + pos[keep])
        vals.append(coef[keep])

    one = np.ones(len(cells))
    for a in range(d):  # sigma_kk = lam tr eps + 2 mu eps_kk
        for k in range(d):
            c = (lam + 2.0 * mu * (a == k)) / h
            add(s * nv + k, a, cells + eye[a], c * one)
            add(s * nv + k, a, cells, -c * one)
    for q, (a, b) in enumerate(axis_pairs(d)):  # sigma_ab = 2 mu eps_ab
        edges = [cells + i * eye[a] + j * eye[b] for i, j in itertools.product((0, 1), repeat=2)]
        weight = np.stack([np.where((p := lay.positions(e)) >= 0, level.ve_host[q, np.maximum(p, 0)], 0.0)
                           for e in edges], axis=1)
        total = weight.sum(axis=1, keepdims=True)
        weight /= np.where(total > 0, total, 1.0)  # no edge of this pair (a thin wall): no shear stress
        for e, wt in zip(edges, weight.T):
            c = 2.0 * mu * 0.5 / h * wt  # eps_e = (u_a(E) - u_a(E - e_b) + u_b(E) - u_b(E - e_a)) / (2 h)
            row = s * nv + d + q
            add(row, a, e, c)
            add(row, a, e - eye[b], -c)
            add(row, b, e, c)
            add(row, b, e - eye[a], -c)
    return np.concatenate(rows), np.concatenate(keys), np.concatenate(vals)
