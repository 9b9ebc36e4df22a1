"""Held cut cells near incompressibility: their volumetric term in finite-volume form.

Near nu = 1/2 the stress is mostly a pressure p = -lambda tr(eps), O(1) where u is O(1 / lambda).
Read through Nitsche's multilinear trace, a hold's reaction to it is not the energy's own boundary
force, row by row, and the difference, which no discrete pressure balances, is left to mu: the holds
lock (docs/design-notes.md, "Held surfaces near incompressibility"). Here a cut cell holding surface
held with its normal component prescribed weighs its divergence as a finite volume does,

    int_(cell n solid) div u = sum_faces +- alpha_f h^(d-1) u_f + int_(held) g . n + N_free . mean(u),

with exact apertures alpha_f (``geometry.apertures``): the wall's flux is the prescribed one, so the
wall takes a uniform pressure's reaction by construction and no penalty has to. The cell's free
surface, at a patch's rim (area vector N_free, the cell's whole one less the held part's), passes the
flux of its cell's mean face velocities (mean(u)_a = (u_a(I) + u_a(I + e_a)) / 2). Its energy
lambda / 2 (D_S(u) + G_S)^2 / V_S replaces lambda / 2 sum V_c tr(eps_c)^2 over a group S (a cell
of fill >= TAU, with the held slivers beside it, whose own constraint would pin their few faces),
and Nitsche holds its points with the mu part alone. Other held points keep the full terms, with
sources outside the groups (whose energy no longer bounds their flux).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..boundary import area_vectors
from ..geometry.apertures import cell_area_vectors, face_apertures
from ..geometry.surface import Surface
from .nitsche import (TAU, HeldDivergence, HoldPatches, HoldQuadrature, SurfaceOperator, _cell_fraction, cell_fill, combined,
                      make_surface_operator)
from .operator import Level
from .sampling import _unique_rows

# lambda / mu (nu 0.476) above which holds left with the full terms are a warning (the clamped sphere's
# error at h = 1/40 was 1.9x nu 0.3's at nu 0.47, 2.6x at 0.48 with every hold so)
LOCKING_RATIO = 20.0
# lambda / mu above which held cut cells take the finite-volume divergence (nu 0.444): on the clamped
# thick sphere at h = 0.05 the two forms agree at nu 0.45 (4.69e-3), the Nitsche terms alone are 6% better
# at 0.4 and 2.3x worse at 0.49
APERTURE_RATIO = 8.0
AREA_TOLERANCE = 1e-7  # of a cell face: a cell's held area vector this small holds nothing
NORMAL_TOLERANCE = 1e-6  # |n - P n|: the hold prescribes the normal component
# a rim cell whose held area vector is below this share of its whole one keeps its volumetric term: the
# held shell at 64^3, nu 0.4999, took 121 CG iterations with every rim cell in a group, 76 so; the rim
# sphere at h = 1/20 7.29e-3 and 8.13e-3 from its h = 1/60 reference (0.25: 79, 8.12e-3; 0.1: 108, 7.86e-3);
# with the Galerkin coarse holds and band patches (multigrid.py) 44 / 31 / 31 iterations at 0 / 0.5 / 0.9
RIM_SHARE = 0.5
PLANE_NUDGE = 1e-7  # [cells]: a point moved this far inwards along its normal finds its cell


def surface_operator(level: Level, quad: HoldQuadrature, patches: HoldPatches, lam: float | None = None
                     ) -> SurfaceOperator:
    """The displacement boundaries' terms of ``quad`` on ``level``: Nitsche's (``nitsche``; ``lam`` [Pa]
    their first Lame parameter, the level's by default), and above lambda / mu = APERTURE_RATIO the
    held cut cells' finite-volume divergence."""
    surface = patches.surface
    if level.lam <= APERTURE_RATIO * level.mu or level.origin is None or surface is None:
        return make_surface_operator(level, quad, lam)
    h, lay = level.spacing, level.layout
    origin = np.asarray(level.origin, dtype=float)
    cells, cell_of = _unique_rows(_point_cells(quad, origin, h))
    on_plane = (np.abs(quad.normals).max(axis=1) > 1 - 1e-12) & _on_planes(quad.points, quad.normals, origin, h)
    off_plane = (_cell_fraction(level, cells)[cell_of] > 0) & ~on_plane
    groups = _groups(level, _near(cells), patches, surface)
    if groups is None:
        operator = make_surface_operator(level, quad, lam)
        operator.kept = off_plane
        return operator
    in_group = np.isin(lay.positions(cells), lay.positions(groups.qualified))[cell_of]
    member_pos = lay.positions(groups.members)
    kept = off_plane & ~in_group
    in_group |= ~_has_source(level, cells, member_pos)[cell_of]  # a full hold's points need a source
    parts = [make_surface_operator(level, quad.subset(in_group), 0.0)] if in_group.any() else []
    if not in_group.all():
        parts.append(make_surface_operator(level, quad.subset(~in_group), lam, exclude=member_pos))
    extra = divergence = None
    if len(groups.members):
        extra, divergence = _finite_volume(level, groups, _prescribed_flux(level, quad, in_group, groups))
    operator = combined(parts, level.size, extra)
    operator.kept = kept
    operator.divergence = divergence
    return operator


def locking_warning(patches: HoldPatches | None, quad: HoldQuadrature | None, operator: SurfaceOperator | None,
                    lam: float, mu: float) -> list[str]:
    """A warning naming the displacement boundaries part of whose surface off the grid's planes kept
    Nitsche's full terms (``SurfaceOperator.kept``: cut cells where the hold leaves the normal free, or a
    sliver with no fuller neighbour) when lambda / mu [-] exceeds LOCKING_RATIO: there the hold locks
    (docs/design-notes.md, "Held surfaces near incompressibility")."""
    if patches is None or operator is None or operator.kept is None or lam <= LOCKING_RATIO * mu:
        return []
    kept = np.bincount(quad.owner, weights=quad.weights * operator.kept, minlength=len(patches.prescribed))
    total = np.bincount(quad.owner, weights=quad.weights, minlength=len(patches.prescribed))
    named = [f"{bc.name} ({100 * k / t:.2g}% of its surface)" for bc, k, t in zip(patches.prescribed, kept, total) if k > 0]
    if not named:
        return []
    nu = lam / (2.0 * (lam + mu))
    return [f"{', '.join(named)}: held where the hold leaves the surface's normal component free (or in a "
            f"sliver cell with no fuller neighbour), at poisson_ratio {nu:.4g}: there the staggered method's hold "
            "keeps Nitsche's terms, which lock as nu -> 1/2 (a thick sphere clamped on its curved surface with "
            "them: 76x nu 0.3's error at 0.4999, h = 1/40; 1.2x where the normal is held): hold the normal "
            "component too, or use method.kind 'dg' with method.degree 2 (locking-free: 1.3x nu 0.3's error at "
            "0.4999, h = 1/8)"]


def _point_cells(quad: HoldQuadrature, origin: np.ndarray, h: float) -> np.ndarray:
    """The cell [Q, d] of each point, on its solid side where it lies on a plane of cell faces (as the
    apertures' scan puts such a surface)."""
    return np.floor((quad.points - origin) / h - PLANE_NUDGE * quad.normals).astype(np.int64)


def _on_planes(points: np.ndarray, normals: np.ndarray, origin: np.ndarray, h: float) -> np.ndarray:
    """[Q] whether each point lies on a plane of cell faces across its (axis-aligned) normal."""
    axis = np.abs(normals).argmax(axis=1)
    x = (points[np.arange(len(points)), axis] - origin[axis]) / h
    return np.abs(x - np.round(x)) <= 1e-6


def _block(cells: np.ndarray) -> np.ndarray:
    """[C, 3^d, d] the 3^d block of cells around each of ``cells`` [C, d] (offsets in -1, 0, 1)."""
    d = cells.shape[1]
    return cells[:, None, :] + np.array(list(itertools.product((-1, 0, 1), repeat=d)), dtype=np.int64)[None]


def _near(cells: np.ndarray) -> np.ndarray:
    """The distinct cells [k, d] of the 3^d blocks of ``cells``: every cell a patch whose points lie in
    ``cells`` can cut (points are less than a cell apart)."""
    return _unique_rows(_block(cells).reshape(-1, cells.shape[1]))[0]


def _apertures(surface: Surface, origin: np.ndarray, h: float, cells: np.ndarray) -> np.ndarray:
    """[C, d, 2] the solid shares of each cell's lower and upper face along every axis (one scan per
    axis for both)."""
    n, d = cells.shape
    out = np.empty((n, d, 2))
    for a in range(d):
        out[:, a] = face_apertures(surface, origin, h, a, np.concatenate([cells, cells + np.eye(d, dtype=np.int64)[a]])
                                   ).reshape(2, n).T
    return out


@dataclass(frozen=True)
class Groups:
    """members [M, d]: the cells whose volumetric term is replaced; group [M]: each one's group;
    qualified [k, d]: the cells holding surface held with its normal prescribed whose points Nitsche
    holds with its mu part alone (the members and the weak rim cells); free, held [M, d] [m^(d-1)]: the
    area vectors of each member's free and held (normal prescribed) surface; alpha: its apertures."""

    members: np.ndarray
    group: np.ndarray
    qualified: np.ndarray
    free: np.ndarray
    held: np.ndarray
    alpha: np.ndarray  # [M, d, 2] each member's lower and upper face's solid share per axis


def _groups(level: Level, cells: np.ndarray, patches: HoldPatches, surface: Surface) -> Groups | None:
    """The groups of the cells among ``cells`` (None when no cell qualifies)."""
    d, h = level.dim, level.spacing
    origin = np.asarray(level.origin, dtype=float)
    vc = _cell_fraction(level, cells)
    ok = vc > 0  # full cells too: a held face on a plane of cell faces is their wall
    if not ok.any():
        return None
    # the cell's surface (its area vector from the apertures) and the part of it held, normal prescribed
    idx = np.nonzero(ok)[0]
    alpha = _apertures(surface, origin, h, cells[idx])
    whole = -(alpha[:, :, 1] - alpha[:, :, 0]) * h ** (d - 1)
    held = cell_area_vectors(_normal_held_pieces(patches), origin, h, cells[idx])
    cell_held = np.zeros((len(cells), d))
    cell_held[idx] = held
    # a cell holding free surface too (a patch's rim) takes that part's flux from its mean face velocities;
    # one mostly free keeps its volumetric term, and its points Nitsche's mu part alone ("weak")
    free = np.zeros((len(cells), d))
    free[idx] = whole - held
    ok[idx] = np.abs(held).max(axis=1) > AREA_TOLERANCE * h ** (d - 1)
    weak = np.zeros(len(cells), dtype=bool)
    weak[idx] = ok[idx] & (np.linalg.norm(held, axis=1) < RIM_SHARE * np.linalg.norm(whole, axis=1))
    ok &= ~weak
    # groups: a qualifying cell filled to TAU is its own; a sliver joins the nearest qualifying cell filled
    # to TAU or full cell without surface of its 3^d block (fuller first), or keeps the full Nitsche terms
    source = cells.copy()
    slivers = np.nonzero(ok & (vc < TAU))[0]
    if len(slivers):
        cand = _block(cells[slivers])
        distance = np.abs(cand - cells[slivers][:, None, :]).sum(axis=2)
        fill = _cell_fraction(level, cand.reshape(-1, d)).reshape(len(slivers), -1)
        pos = level.layout.positions(cand.reshape(-1, d))
        # a source brings its own surface into the group: a qualifying cell, or a full one with none
        plain = np.zeros(len(cells), dtype=bool)
        plain[idx] = (vc[idx] >= 1.0) & (np.abs(whole).max(axis=1) <= AREA_TOLERANCE * h ** (d - 1))
        big = level.layout.positions(cells[(ok & (vc >= TAU)) | plain])
        usable = (fill >= TAU) & np.isin(pos, big).reshape(fill.shape)
        score = np.where(usable, 10.0 - distance + 0.1 * fill, -np.inf)
        best = score.argmax(axis=1)
        found = np.isfinite(score[np.arange(len(slivers)), best])
        source[slivers] = cand[np.arange(len(slivers)), best]
        ok[slivers[~found]] = False
    if not ok.any():
        return None if not weak.any() else Groups(np.zeros((0, d), np.int64), np.zeros(0, np.int64), cells[weak],
                                                  np.zeros((0, d)), np.zeros((0, d)), np.zeros((0, d, 2)))
    members, where = _unique_rows(np.concatenate([cells[ok], source[ok]]))
    _, group = _unique_rows(source[ok])
    member_group = np.empty(len(members), dtype=np.int64)
    member_group[where] = np.concatenate([group, group])
    # a source that does not qualify holds no surface
    member_free, member_held = np.zeros((len(members), d)), np.zeros((len(members), d))
    member_free[where[: int(ok.sum())]] = free[ok]
    member_held[where[: int(ok.sum())]] = cell_held[ok]
    # every member is one of ``cells`` (sources come from them): its apertures are at hand
    cell_alpha = np.zeros((len(cells), d, 2))
    cell_alpha[idx] = alpha
    order = np.argsort(level.layout.positions(cells))
    at = order[np.searchsorted(level.layout.positions(cells)[order], level.layout.positions(members))]
    return Groups(members, member_group, cells[ok | weak], member_free, member_held, cell_alpha[at])


def _normal_held_pieces(patches: HoldPatches) -> np.ndarray:
    """The held pieces [M, d, d] whose boundary prescribes their normal component."""
    out = []
    for bc, pieces in zip(patches.prescribed, patches.pieces):
        an = area_vectors(pieces)
        n = an / np.maximum(np.linalg.norm(an, axis=1, keepdims=True), 1e-300)
        out.append(pieces[np.linalg.norm(n * (1.0 - bc.mask(pieces.shape[-1])), axis=1) <= NORMAL_TOLERANCE])
    return np.concatenate(out)


def _has_source(level: Level, cells: np.ndarray, exclude: np.ndarray) -> np.ndarray:
    """[C] whether a cell of each one's 3^d block holds material and is not excluded (Nitsche's
    full terms need such a source cell)."""
    cand = _block(cells).reshape(-1, level.dim)
    usable = (cell_fill(level, cand) > 0) & ~np.isin(level.layout.positions(cand), exclude)
    return usable.reshape(len(cells), -1).any(axis=1)


def _prescribed_flux(level: Level, quad: HoldQuadrature, in_group: np.ndarray, groups: Groups) -> np.ndarray:
    """G_S [groups] [m^d]: int g . n over each group's held surface. The points' rule is corrected by
    the cells' exact held area vectors so that a constant g gives the exact flux (its points are not
    clipped to the cells, and a constant field must leave every group without divergence)."""
    d, h, lay = level.dim, level.spacing, level.layout
    origin = np.asarray(level.origin, dtype=float)
    members, group = groups.members, groups.group
    n_groups = int(group.max()) + 1
    order = np.argsort(lay.positions(members))
    sorted_pos = lay.positions(members)[order]
    pos = lay.positions(_point_cells(quad, origin, h))
    at = np.minimum(np.searchsorted(sorted_pos, pos), len(order) - 1)
    on = in_group & (sorted_pos[at] == pos)
    point_group = group[order[at]][on]
    g = (quad.mask * quad.values)[on]
    w = quad.weights[on]
    wn = w[:, None] * quad.normals[on]
    sums = lambda v: np.bincount(point_group, weights=v, minlength=n_groups)  # noqa: E731
    flux = sums(np.einsum("qi,qi->q", wn, g))
    area = np.stack([sums(wn[:, a]) for a in range(d)], axis=1)
    weight = sums(w)
    mean_g = np.stack([sums(w * g[:, a]) for a in range(d)], axis=1) / np.maximum(weight, 1e-300)[:, None]
    empty = np.nonzero(weight <= 0)[0]
    if len(empty):  # a group whose held surface got no point: g at the point nearest its first cell
        first = np.zeros(n_groups, dtype=np.int64)
        first[group[::-1]] = np.arange(len(group))[::-1]
        centre = origin + h * (members[first[empty]] + 0.5)
        nearest = cKDTree(quad.points).query(centre)[1]
        mean_g[empty] = (quad.mask * quad.values)[nearest]
    exact = np.zeros((n_groups, d))
    np.add.at(exact, group, groups.held)
    return flux + np.einsum("gi,gi->g", mean_g, exact - area)


def _finite_volume(level: Level, groups: Groups, flux_g: np.ndarray
                   ) -> tuple[tuple[np.ndarray, sp.csr_matrix, np.ndarray], HeldDivergence]:
    """((sample keys [k], lambda (D^T V^-1 D - T^T diag(V_c) T) [k, k], -lambda D^T V^-1 G [k]), the
    divergence itself): the groups' finite-volume divergence D_S in place of their members' lambda / 2
    V_c tr(eps_c)^2 (T: the members' tr(eps) [1 / m]), with the prescribed flux G_S (its load)."""
    d, h, lay, size = level.dim, level.spacing, level.layout, level.size
    members, group = groups.members, groups.group
    eye = np.eye(d, dtype=np.int64)
    volume = _cell_fraction(level, members) * h**d
    alpha = groups.alpha
    n_groups = len(flux_g)
    rows, keys, div, trace = [], [], [], []
    for a in range(d):
        for side, sign in ((0, -1.0), (1, 1.0)):
            pos = lay.positions(members + side * eye[a])
            live = (pos >= 0) & level.active[a, np.maximum(pos, 0)]
            rows.append(np.nonzero(live)[0])
            keys.append(a * size + pos[live])
            div.append(sign * alpha[live, a, side] * h ** (d - 1) + 0.5 * groups.free[live, a])
            trace.append(np.full(live.sum(), sign / h))
    rows, keys, div, trace = (np.concatenate(v) for v in (rows, keys, div, trace))
    every, col = np.unique(keys, return_inverse=True)
    D = sp.csr_matrix((div, (group[rows], col)), (n_groups, len(every)))
    T = sp.csr_matrix((trace, (rows, col)), (len(members), len(every)))
    vs = np.bincount(group, weights=volume, minlength=n_groups)
    lam = level.lam
    matrix = lam * (D.T @ sp.diags(1.0 / vs) @ D - T.T @ sp.diags(volume) @ T)
    return ((every, sp.csr_matrix(matrix), -lam * (D.T @ (flux_g / vs))),
            HeldDivergence(every, D, np.asarray(flux_g, dtype=float), vs, members, group))
