"""Sampling the staggered displacement at points, and surface loads consistent with that sampling.

Displacement component ``a`` lives on the a-faces: sample ``(a, I)`` at ``origin + h (I + 0.5 -
0.5 e_a)``. Between samples it is read by multilinear interpolation on that shifted lattice
(``stencil``); inside the material only active samples count, their weights renormalised
(``interpolate``). A traction ``t`` on the surface becomes nodal forces
``f_a(I) = sum_q w_q t_a(x_q) psi_{a,I}(x_q)`` with the energy's own weights (given the points'
normals n): psi = sum_j n_j^2 (the hat along j times the nearest sample along the other axes). That
is how the operator's weights take a constant stress (row a's sigma_aj term reads fraction
differences along j of boxes h wide across j), so on faces normal to an axis the load is the
energy's own force of the stress the traction belongs to, cut cells and corners included; the
transpose of the interpolation (psi = phi, the hats along every axis) left a shear traction's state
0.23 off at a rectangle's corners and a pulled cylinder's 1.48 T off in a sliver. Either way a
constant traction keeps its total force. The points' pieces must be cut at the planes h/2
apart (``boundary.surface_quadrature``'s ``lattice``), where psi jumps.

Renormalising over the active samples moves a point's force to where they are, so at cut cells
the load's moment is off by O(h F). Every body's load therefore gets the self-equilibrated couple
that restores its first moments (``_moment_couple``): the discrete load has the quadrature's net
force *and* net moment. A body held by nothing needs it to be solvable (a load that balances on
the surface balances on the samples); a held one needs it to be loaded along the right line: a
bar pulled at an end face whose sides cut cells (fill 0.8 / 0.2 and 0.9 / 0.1) took the
renormalised load 0.01 h off its axis and bent, its strain off by 4.3e-2 at 4 cells across and
1.1e-2 at 8 (1.1e-3 and 1.4e-4 with the couple; tests/test_staggered_verification.py).

Surface quadrature and the tractions of boundary conditions are the method-neutral
``engine.boundary``'s.

Units: positions [m], tractions, pressures and stresses [Pa], weights [m^2] (3D) or [m] (2D), forces
[N] (2D: per unit thickness, [N/m]); lattice offsets in units of h.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from ..errors import VoxelasticError
from ..grid import Grid

# lookup(a, index [M, d] int64) -> (values [M], active [M] bool); index always inside the index box.
Lookup = Callable[[int, np.ndarray], tuple[np.ndarray, np.ndarray]]
# active(a, index [M, d] int64) -> bool [M]; index always inside the index box.
Active = Callable[[int, np.ndarray], np.ndarray]
# bodies(a, index [M, d] int64) -> int [M]: the label (> 0, one per body) of the body a sample
# belongs to, 0 where none; index always inside the index box.
Bodies = Callable[[int, np.ndarray], np.ndarray]

# A direction in which the samples that may take a moment couple spread less than this (second
# moment per unit room, lattice units) cannot carry one: they lie in a plane (a wall thinner than
# a cell, a load on one row of samples).
SPREAD_CUTOFF = 1e-9
# A first-moment excess [N h] below this times the load's size is round-off of the levers (a
# symmetric patch): no couple, so no dust of 1e-17 N on the samples around.
ROUNDOFF_MOMENT = 1e-13


def stencil(grid: Grid, points: np.ndarray, a: int) -> tuple[np.ndarray, np.ndarray]:
    """Multilinear interpolation stencil of displacement component ``a`` at ``points`` [N, d] [m].

    The lattice is that of the a-face samples, ``origin + h (I + 0.5 - 0.5 e_a)``. Returns
    (index [N, 2^d, d] int64, weights [N, 2^d] >= 0, each row summing to 1). Indices may fall
    outside the index box [0, n + 1)^d when a point is within h/2 of the grid's edge; callers treat
    those samples as inactive.
    """
    base, frac = _lattice(grid, points, a)
    corners = _corners(grid.dim)
    return base[:, None, :] + corners[None], _corner_weights(frac)


def _lattice(grid: Grid, points: np.ndarray, a: int) -> tuple[np.ndarray, np.ndarray]:
    """The a-sample lattice cell of each point [N, d] [m]: (base index [N, d] int64, offset in it
    [N, d] in [0, 1), units of h; base + offset is the point's lattice coordinate, exactly)."""
    d = grid.dim
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != d:
        raise ValueError(f"points: expected shape [N, {d}], got {points.shape}")
    if not 0 <= a < d:
        raise ValueError(f"component: expected 0 <= a < {d}, got {a}")
    shift = 0.5 - 0.5 * np.eye(d)[a]
    xi = (points - np.asarray(grid.origin)) / grid.spacing - shift  # lattice coordinates
    base = np.floor(xi)
    return base.astype(np.int64), xi - base


def _corners(d: int) -> np.ndarray:
    """The 2^d corners of a lattice cell as offsets [2^d, d] int64 (last axis fastest)."""
    return np.array(list(itertools.product((0, 1), repeat=d)), dtype=np.int64)


def _corner_weights(frac: np.ndarray) -> np.ndarray:
    """Multilinear weights [N, 2^d] at offsets frac [N, d] in a cell, of the corners in the order of
    :func:`_corners`: the outer product of the per-axis weights (1 - frac, frac)."""
    n, d = frac.shape
    phi = np.ones((n,) + (1,) * d)
    for b in range(d):
        hat = np.stack([1.0 - frac[:, b], frac[:, b]], axis=1)  # [N, 2]: lower, upper side along b
        phi = phi * hat.reshape((n,) + (1,) * b + (2,) + (1,) * (d - 1 - b))
    return phi.reshape(n, 2**d)


def stencil_samples(grid: Grid, points: np.ndarray, normals: np.ndarray) -> list[np.ndarray]:
    """Per component a, the distinct samples [k, d] beyond a surface that the multilinear
    stencils of its ``points`` [N, d] [m] read: of each stencil, the corners on the outward side
    along the dominant axis of the point's unit outward normal (``normals`` [N, d]). Where these
    are active the interpolation across the surface is the full multilinear one; the corners
    beside the point along the surface are left out (see ``ghosts``)."""
    d = grid.dim
    corners = _corners(d)
    axis = np.abs(normals).argmax(axis=1)
    side = (normals[np.arange(len(axis)), axis] > 0).astype(np.int64)
    out = []
    for a in range(d):
        base, _ = _lattice(grid, points, a)
        keys, _ = _unique_rows(np.column_stack([base, axis, side]))  # stencil cell, axis, outward side
        near = keys[:, None, :d] + corners[None]  # [C, 2^d, d]
        outward = corners[:, keys[:, d]].T == keys[:, d + 1][:, None]  # [C, 2^d]
        out.append(_unique_rows(near[outward])[0])
    return out


def interpolate(grid: Grid, points: np.ndarray, lookup: Lookup) -> np.ndarray:
    """Displacement [N, d] [m] at ``points`` [N, d] from the staggered values, restricted to material.

    ``lookup(a, index [M, d]) -> (values [M] [m], active [M] bool)`` reads component ``a``; it is
    only called with indices inside the index box (samples outside it are inactive). Weights of
    inactive samples are dropped and the rest renormalised, so constants are reproduced wherever
    any sample is active; a component with no active sample at a point is NaN.
    """
    points = np.asarray(points, dtype=float)
    out = np.empty((len(points), grid.dim))
    for a in range(grid.dim):
        index, weights = stencil(grid, points, a)
        values, active = _read(grid, index, a, lookup)
        weights = renormalised(weights, active)
        out[:, a] = np.where(active.any(axis=1), (weights * np.where(active, values, 0.0)).sum(axis=1), np.nan)
    return out


def surface_loads(
    grid: Grid,
    points: np.ndarray,
    weights: np.ndarray,
    tractions: np.ndarray,
    active: Active | None = None,
    *,
    bodies: Bodies | None = None,
    normals: np.ndarray | None = None,
    name: str = "surface load",
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Consistent load vector of tractions [Q, d] [Pa] at quadrature ``points`` [Q, d] with ``weights`` [Q].

    Per component ``a``: (index [K, d] int64, unique; force [K] [N]) with
    ``force(I) = sum_q w_q t_a(x_q) phi_{a,I}(x_q)`` -- the transpose of ``stencil``, so
    ``sum f . u = sum_q w_q t(x_q) . u_h(x_q)`` for the multilinear interpolant ``u_h``. Only samples
    of nonzero stencil weight appear; they can lie outside the index box for points within h/2 of
    the grid's edge.

    With the points' unit ``normals`` [Q, d] the weights are the energy's own instead of phi (module
    docstring), on the same 2^d samples.

    With ``active(a, index [M, d]) -> bool [M]`` the transpose of ``interpolate`` is used instead:
    inactive samples are dropped and the rest renormalised, so no force is lost on inactive DOFs
    (sum_I f_a(I) = sum_q w_q t_a exactly) and only active indices are returned. A point with a
    nonzero traction component but no active sample raises an error naming ``name``.

    With ``bodies`` as well (the samples' body labels), each body's load also gets the couple that
    gives it the quadrature's net moment (to round-off; unless the active samples around span too
    little), added on the active samples within 2h of its points.
    """
    points = np.asarray(points, dtype=float)
    weights = np.asarray(weights, dtype=float)
    tractions = np.asarray(tractions, dtype=float)
    d = grid.dim
    if weights.shape != (len(points),) or tractions.shape != (len(points), d):
        raise ValueError(
            f"{name}: expected weights [{len(points)}] and tractions [{len(points)}, {d}], "
            f"got {weights.shape} and {tractions.shape}"
        )
    loads = []
    corners = _corners(d)
    k = len(corners)
    for a in range(d):
        # Surface points far outnumber the cells they cross (~50 per cell on a fine mesh): samples are
        # looked up, and forces gathered, per (cell, corner) slot, never per (point, corner) entry.
        base, frac = _lattice(grid, points, a)
        phi = _corner_weights(frac) if normals is None else _energy_weights(frac, normals)  # [N, 2^d]
        cells, cell_of = _unique_rows(base)
        near = cells[:, None, :] + corners[None]  # [C, 2^d, d]: the samples of each cell
        load = weights * tractions[:, a]
        if active is not None:
            is_active = _read(grid, near, a, lambda c, i: (np.zeros(len(i)), active(c, i)))[1]
            phi = _restricted(phi, is_active[cell_of], a, load, name)
        slot = (cell_of[:, None] * k + np.arange(k)).ravel()
        keep = phi.ravel() > 0
        summed = np.bincount(slot[keep], weights=(load[:, None] * phi).ravel()[keep], minlength=len(cells) * k)
        used = np.bincount(slot[keep], minlength=len(cells) * k) > 0
        samples, inverse = _unique_rows(near.reshape(-1, d)[used])
        force = np.bincount(inverse, weights=summed[used], minlength=len(samples))
        if active is not None and bodies is not None:
            samples, force = _balanced(grid, load, a, (cells, cell_of, frac, phi), (samples, force), active, bodies)
        loads.append((samples, force))
    return loads


def _energy_weights(frac: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Weights [N, 2^d] of the corners of :func:`_corners` at offsets frac [N, d] of points with unit
    normals [N, d]: sum_j n_j^2 times the hat along j and, along every other axis, the nearer sample."""
    n, d = frac.shape
    hat = [np.stack([1.0 - frac[:, b], frac[:, b]], axis=1) for b in range(d)]
    nearest = [np.stack([frac[:, b] < 0.5, frac[:, b] >= 0.5], axis=1).astype(float) for b in range(d)]
    out = np.zeros((n, 2**d))
    for j in range(d):
        psi = np.ones((n,) + (1,) * d)
        for b in range(d):
            psi = psi * (hat[b] if b == j else nearest[b]).reshape((n,) + (1,) * b + (2,) + (1,) * (d - 1 - b))
        out += normals[:, j, None] ** 2 * psi.reshape(n, 2**d)
    return out


def renormalised(phi: np.ndarray, is_active: np.ndarray) -> np.ndarray:
    """Stencil weights phi [N, 2^d] over the active samples (``is_active`` [N, 2^d]) only, each row
    renormalised to 1 (rows without an active sample stay zero)."""
    phi = np.where(is_active, phi, 0.0)
    total = phi.sum(axis=1, keepdims=True)
    return phi / np.where(total > 0, total, 1.0)


def _restricted(phi: np.ndarray, is_active: np.ndarray, a: int, load: np.ndarray, name: str) -> np.ndarray:
    """Stencil weights phi [N, 2^d] over the active samples (``is_active`` [N, 2^d]) only,
    :func:`renormalised`; a point with force ``load`` [N] [N] != 0 along axis ``a`` and no active
    sample is an error naming ``name``."""
    lost = ~is_active.any(axis=1) & (load != 0)
    if lost.any():
        raise VoxelasticError(
            f"{name}: {int(lost.sum())} surface quadrature points carrying "
            f"{np.abs(load[lost]).sum():.6g} N of force along axis {a} have no active displacement "
            "sample nearby; the surface lies outside the material the grid resolves"
        )
    return renormalised(phi, is_active)


def _balanced(grid: Grid, load: np.ndarray, a: int, spread: tuple, summed: tuple, active: Active,
              bodies: Bodies) -> tuple[np.ndarray, np.ndarray]:
    """(samples [K, d], force [K]) of component a with each body's moment couple added.

    spread: the points' lattice cells (cells [C, d], cell_of [N]), offsets in them (frac [N, d]) and
    renormalised corner weights phi [N, 2^d]; summed: their forces summed per sample. The excess
    first moment of a body's load is sum F_q phi_qI (x_I - x_q) over its samples (positions in h);
    the couple acts on the active samples around the same points, each point offering room |F_q|
    spread by a hat of width 2h."""
    cells, cell_of, frac, phi = spread
    samples, force = summed
    d = grid.dim
    corners = _corners(d)
    near = cells[:, None, :] + corners[None]
    label = _read(grid, near, a, lambda c, i: (np.asarray(bodies(c, i), dtype=np.int64), np.ones(len(i), bool)))[0]
    label = np.where(phi > 0, label.astype(np.int64)[cell_of], 0)  # [N, 2^d] per (point, corner) entry
    if not (label > 0).any():
        return samples, force
    labels = np.unique(label[label > 0])
    moment = load[:, None] * phi  # force on each (point, corner) entry; its lever is corner - frac
    excess = np.zeros((len(labels), d))  # [bodies, d] [N h]; the lever along a does not turn f_a
    for b in (b for b in range(d) if b != a):
        per_label = np.bincount(label.ravel(), weights=(moment * (corners[None, :, b] - frac[:, b, None])).ravel())
        excess[:, b] = per_label[labels]
    size = np.abs(load).sum()
    held = [k for k, e in zip(labels, excess) if np.abs(e).max() > ROUNDOFF_MOMENT * size]
    if not held:
        return samples, force
    rows = np.nonzero(np.isin(label, held).any(axis=1))[0]
    xi = cells[cell_of] + frac  # lattice coordinates [N, d] (exact: frac = xi - floor(xi))
    room_index, room = _room(grid, xi, load, a, rows, active)
    room_label = np.asarray(bodies(a, room_index), dtype=np.int64)
    out_index, inverse = _unique_rows(np.concatenate([samples, room_index]))
    out = np.bincount(inverse[: len(samples)], weights=force, minlength=len(out_index))
    for k in held:
        mine = room_label == k
        couple = _moment_couple(room_index[mine].astype(float), room[mine], excess[labels == k][0], a)
        np.add.at(out, inverse[len(samples):][mine], couple)
    keep = (np.bincount(inverse[: len(samples)], minlength=len(out_index)) > 0) | (out != 0)
    return out_index[keep], out[keep]


def _room(grid: Grid, xi: np.ndarray, load: np.ndarray, a: int, rows: np.ndarray,
          active: Active) -> tuple[np.ndarray, np.ndarray]:
    """Where a couple may act for the points ``rows``: the active samples among the 4^d around
    each lattice cell they lie in (offsets -1..2 from it), the cell offering its points' summed
    |force| [N] spread by a hat of width 2h about their |force|-weighted mean position (zero at the
    neighbourhood's edge, so samples enter it continuously). Per cell, not per point: a fine mesh
    puts ~50 points in a cell, and per point this took 2.4 of the 4.1 s of a 3/4-sphere traction's
    load vector at h = 1/96. Returns the distinct samples (index [K, d]) and their room [K] [N]."""
    d = grid.dim
    around = np.array(list(itertools.product((-1, 0, 1, 2), repeat=d)), dtype=np.int64)  # [4^d, d]
    base = np.floor(xi[rows]).astype(np.int64)
    cells, cell_of = _unique_rows(base)
    force = np.bincount(cell_of, weights=np.abs(load[rows]), minlength=len(cells))
    mean = np.stack([np.bincount(cell_of, weights=np.abs(load[rows]) * xi[rows, k], minlength=len(cells))
                     for k in range(d)], axis=1) / np.where(force > 0, force, 1.0)[:, None]
    near = cells[:, None, :] + around[None]
    is_active = _read(grid, near, a, lambda c, i: (np.zeros(len(i)), active(c, i)))[1]
    hat = np.clip(1.0 - 0.5 * np.abs(near - mean[:, None, :]), 0.0, None).prod(axis=2) * is_active
    room = hat * (force / np.where(hat.sum(axis=1) > 0, hat.sum(axis=1), 1.0))[:, None]
    on = room > 0
    return near[on], room[on]


def _moment_couple(x: np.ndarray, room: np.ndarray, excess: np.ndarray, a: int) -> np.ndarray:
    """Forces [K] [N] on component-a samples at lattice positions x [K, d] (repeats allowed) that sum
    to zero and whose first moments along the axes b != a are -excess[b] [N h]:
    ``room * (beta . (x - xbar))``, the smallest such forces in the room-weighted norm (room [K] >= 0
    [N]: how much force each may take). A moment along a direction in which the samples with room do
    not spread (second moment below SPREAD_CUTOFF) is left."""
    if room.sum() <= 0:
        return np.zeros(len(x))
    xbar = room @ x / room.sum()
    transverse = np.arange(x.shape[1]) != a  # the moment of f_a needs only its lever across a
    xc = (x - xbar)[:, transverse]
    e, v = np.linalg.eigh(np.einsum("k,ki,kj->ij", room, xc, xc))
    keep = e > SPREAD_CUTOFF * room.sum()
    beta = v[:, keep] @ ((v[:, keep].T @ -excess[transverse]) / e[keep])
    return room * (xc @ beta)


def _unique_rows(index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of integer index [n, d] (sorted) and where each row went [n]: one 1D sort of
    linear keys (np.unique along axis 0 sorts rows as bytes, seconds for millions)."""
    if len(index) == 0:
        return index.reshape(0, index.shape[-1]).astype(np.int64), np.zeros(0, dtype=np.int64)
    lo = index.min(axis=0)
    dims = tuple(int(n) for n in index.max(axis=0) - lo + 1)
    keys, inverse = np.unique(np.ravel_multi_index(tuple((index - lo).T), dims), return_inverse=True)
    return (np.stack(np.unravel_index(keys, dims), axis=1) + lo).astype(np.int64), inverse.ravel()


def _read(grid: Grid, index: np.ndarray, a: int, lookup: Lookup) -> tuple[np.ndarray, np.ndarray]:
    """Values and activity [N, k] of stencil samples ``index`` [N, k, d]; outside the box: inactive."""
    flat = index.reshape(-1, grid.dim)
    inside = np.all((flat >= 0) & (flat <= np.asarray(grid.shape)), axis=1)  # index box [0, n + 1)
    values = np.zeros(len(flat))
    active = np.zeros(len(flat), dtype=bool)
    if inside.any():
        v, act = lookup(a, flat[inside])
        values[inside] = v
        active[inside] = act
    return values.reshape(index.shape[:2]), active.reshape(index.shape[:2])
