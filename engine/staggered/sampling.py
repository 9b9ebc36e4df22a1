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
the load's torque is off by O(h F). Every body's loads therefore get one self-equilibrated couple
that restores their net torque (``_torque_couple``): the discrete load has the quadrature's net
force *and* net torque. A body held by nothing needs it to be solvable (a load that balances on
the surface balances on the samples); a held one needs it to be loaded along the right line: a
bar pulled at an end face whose sides cut cells (fill 0.8 / 0.2 and 0.9 / 0.1) took the
renormalised load 0.01 h off its axis and bent, its strain off by 4.3e-2 at 4 cells across and
1.1e-2 at 8 (1.1e-3 and 1.4e-4 with the couple; tests/test_staggered_verification.py). Only the
torque: a couple per load that restored the whole first-moment tensor also undid the energy's own
force where corner edges are pruned (a box on grid planes under a general constant stress: 0.38
of it off, 4e-15 with the torque alone).

Surface quadrature and the tractions of boundary conditions are the method-neutral
``engine.boundary``'s.

Units: positions [m], tractions, pressures and stresses [Pa], weights [m^2] (3D) or [m] (2D), forces
[N] (2D: per unit thickness, [N/m]); lattice offsets in units of h.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

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

# A direction in which the samples that may take a torque couple spread less than this (second
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
    gives it the quadrature's net torque (:func:`point_loads`).
    """
    return point_loads(grid, [(points, weights, tractions, normals, name)], active, bodies)


# One load given at surface points: (points [Q, d] m, weights [Q] m^2, tractions [Q, d] Pa, unit
# normals [Q, d] or None, name).
PointLoad = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, str]


def point_loads(grid: Grid, loads: list[PointLoad], active: Active | None = None,
                bodies: Bodies | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """The summed load vector of several point loads, per component (index [K, d], force [K] [N]),
    each spread as :func:`surface_loads` says. With ``active`` and ``bodies`` every body gets one
    self-equilibrated couple for all its loads together that restores the quadrature's net torque
    (:func:`_torque_balanced`)."""
    d = grid.dim
    balance = active is not None and bodies is not None
    out, spreads = [], []
    for a in range(d):
        parts = [_spread(grid, a, *load, active, balance) for load in loads]
        out.append(_merged(np.concatenate([np.zeros((0, d), np.int64)] + [s.samples for s in parts]),
                           np.concatenate([np.zeros(0)] + [s.force for s in parts])))
        spreads += [(a, s) for s in parts]
    return _torque_balanced(grid, spreads, out, active, bodies) if balance else out


@dataclass(frozen=True)
class _Spread:
    """One point load's component a on the samples, summed per lattice cell (cells [C, d]) of its
    points: per corner of a cell (the 2^d of :func:`_corners`) the force F_c = sum_q F_qa phi_qc [C,
    2^d] [N] and its points' first moment sum_q F_qa phi_qc frac_q [C, 2^d, d] [N h] (so the excess
    lever moment about the points is corner F_c - that); per cell sum_q |F_qa| [C] [N] and
    sum_q |F_qa| xi_q [C, d] [N h] (xi: lattice coordinates); the forces per sample (samples [K, d],
    force [K] [N]). Per cell, not per point: a mesh finer than the grid puts many points in a cell."""

    cells: np.ndarray
    corner_force: np.ndarray
    corner_moment: np.ndarray
    size: np.ndarray
    size_moment: np.ndarray
    samples: np.ndarray
    force: np.ndarray


def _spread(grid: Grid, a: int, points: np.ndarray, weights: np.ndarray, tractions: np.ndarray,
            normals: np.ndarray | None, name: str, active: Active | None, moments: bool = False) -> _Spread:
    """``moments``: also the cells' moments the torque couple needs (else those arrays are empty)."""
    points = np.asarray(points, dtype=float)
    weights = np.asarray(weights, dtype=float)
    tractions = np.asarray(tractions, dtype=float)
    d = grid.dim
    if weights.shape != (len(points),) or tractions.shape != (len(points), d):
        raise ValueError(
            f"{name}: expected weights [{len(points)}] and tractions [{len(points)}, {d}], "
            f"got {weights.shape} and {tractions.shape}"
        )
    corners = _corners(d)
    k = len(corners)
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
    entry = load[:, None] * phi  # [N, 2^d]
    summed = np.bincount(slot, weights=entry.ravel(), minlength=len(cells) * k)
    moment, size, size_moment = np.zeros((0, k, d)), np.zeros(0), np.zeros((0, d))
    if moments:
        moment = np.stack([np.bincount(slot, weights=(entry * frac[:, b, None]).ravel(), minlength=len(cells) * k)
                           if b != a else np.zeros(len(cells) * k) for b in range(d)], axis=1).reshape(len(cells), k, d)
        size = np.bincount(cell_of, weights=np.abs(load), minlength=len(cells))
        size_moment = np.stack([np.bincount(cell_of, weights=np.abs(load) * (base[:, b] + frac[:, b]),
                                            minlength=len(cells)) for b in range(d)], axis=1)
    used = np.bincount(slot[phi.ravel() > 0], minlength=len(cells) * k) > 0
    samples, force = _merged(near.reshape(-1, d)[used], summed[used])
    return _Spread(cells, summed.reshape(len(cells), k), moment, size, size_moment, samples, force)


def _energy_weights(frac: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Weights [N, 2^d] of the corners of :func:`_corners` at offsets frac [N, d] of points with unit
    normals [N, d]: sum_j n_j^2 times the hat along j and, along every other axis, the nearer sample.
    Each j's term sits on two corners, so it is added there alone (the outer products over all 2^d
    corners took 0.7 s for a sphere's 1.3 M points)."""
    n, d = frac.shape
    bit = 2 ** (d - 1 - np.arange(d))  # a corner's number is sum_b bit_b (0 or 1 along b)
    upper = (frac >= 0.5).astype(np.int64) * bit
    start = np.arange(n) * 2**d + upper.sum(axis=1)
    slots, values = [], []
    for j in range(d):
        lower = start - upper[:, j]  # the nearer samples across j, the lower one along j
        weight = normals[:, j] ** 2
        slots += [lower, lower + bit[j]]
        values += [weight * (1.0 - frac[:, j]), weight * frac[:, j]]
    return np.bincount(np.concatenate(slots), weights=np.concatenate(values), minlength=n * 2**d).reshape(n, 2**d)


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


def _torque_balanced(grid: Grid, spreads: list[tuple[int, _Spread]], summed: list[tuple[np.ndarray, np.ndarray]],
                     active: Active, bodies: Bodies) -> list[tuple[np.ndarray, np.ndarray]]:
    """``summed`` (per component: samples [K, d], force [K]) with each body's torque couple added.

    The excess first moment of a body's loads is E_ab = sum F_qa phi_qI (x_I - x_q)_b over the
    (point q, sample I) entries whose sample is the body's (positions in h: the spread's lever
    against the point's own); its torque is E - E^T. Only the torque is restored: for a constant
    stress the energy's own force has the moments sigma_ab times the volume of the weights that
    carry sigma_ab, which pruned corner edges lower for sigma_ab and sigma_ba alike
    (docs/design-notes.md, "A traction spread as the energy takes a stress"), so restoring E's
    symmetric part as well moved the loads away from the energy's force (a box on grid planes under
    a general constant stress 0.38 of it off). The couple acts on the active samples around the
    lattice cells of the body's points, each cell offering room sum |F_qa| for component a spread
    by a hat of width 2h (:func:`_room`)."""
    d = grid.dim
    corners = _corners(d)
    labels, first, size = [], np.zeros((1, d, d)), 0.0
    for a, s in spreads:
        near = s.cells[:, None, :] + corners[None]
        label = _read(grid, near, a, lambda c, i: (np.asarray(bodies(c, i), dtype=np.int64), np.ones(len(i), bool)))[0]
        label = label.astype(np.int64)  # [C, 2^d]: the body of each cell's corner sample, 0 for none
        labels.append(label)
        top = int(label.max(initial=0)) + 1
        if top > len(first):
            first = np.concatenate([first, np.zeros((top - len(first), d, d))])
        for b in (b for b in range(d) if b != a):
            lever = corners[None, :, b] * s.corner_force - s.corner_moment[:, :, b]
            first[:top, a, b] += np.bincount(label.ravel(), weights=lever.ravel(), minlength=top)
        size += s.size.sum()
    torque = first - first.transpose(0, 2, 1)
    held = [k for k in range(1, len(torque)) if np.abs(torque[k]).max() > ROUNDOFF_MOMENT * size]
    if not held:
        return summed
    rooms = [[np.zeros((0, d), np.int64)] for _ in range(d)], [[np.zeros(0)] for _ in range(d)]
    for (a, s), label in zip(spreads, labels):
        mine = np.nonzero(np.isin(label, held).any(axis=1) & (s.size > 0))[0]
        if len(mine):
            i, r = _room(grid, s.cells[mine], s.size[mine], s.size_moment[mine] / s.size[mine, None], a, active)
            rooms[0][a].append(i)
            rooms[1][a].append(r)
    rooms = [_merged(np.concatenate(i), np.concatenate(r)) for i, r in zip(*rooms)]  # neighbours' rooms overlap
    rooms = [(i, r, np.asarray(bodies(a, i), dtype=np.int64)) for a, (i, r) in enumerate(rooms)]
    couples = [np.zeros(len(r)) for _, r, _ in rooms]
    for k in held:
        mine = [label == k for _, _, label in rooms]
        forces = _torque_couple([(i[m].astype(float), r[m]) for (i, r, _), m in zip(rooms, mine)], torque[k])
        for a in range(d):
            couples[a][mine[a]] += forces[a]
    out = []
    for a, ((samples, force), (index, _, _)) in enumerate(zip(summed, rooms)):
        out_index, inverse = _unique_rows(np.concatenate([samples, index]))
        total = np.bincount(inverse[: len(samples)], weights=force, minlength=len(out_index))
        np.add.at(total, inverse[len(samples):], couples[a])
        keep = (np.bincount(inverse[: len(samples)], minlength=len(out_index)) > 0) | (total != 0)
        out.append((out_index[keep], total[keep]))
    return out


def _room(grid: Grid, cells: np.ndarray, force: np.ndarray, mean: np.ndarray, a: int,
          active: Active) -> tuple[np.ndarray, np.ndarray]:
    """Where a couple may act around lattice cells [C, d] of points whose summed |force| is ``force``
    [C] [N] about their |force|-weighted mean position ``mean`` [C, d] (lattice coordinates): the
    active samples among the 4^d around each cell (offsets -1..2 from it), the cell's force spread
    over them by a hat of width 2h about the mean (zero at the neighbourhood's edge, so samples enter
    it continuously). Returns the samples (index [K, d], repeats possible) and their room [K] [N]."""
    d = grid.dim
    around = np.array(list(itertools.product((-1, 0, 1, 2), repeat=d)), dtype=np.int64)  # [4^d, d]
    near = cells[:, None, :] + around[None]
    is_active = _read(grid, near, a, lambda c, i: (np.zeros(len(i)), active(c, i)))[1]
    hat = np.clip(1.0 - 0.5 * np.abs(near - mean[:, None, :]), 0.0, None).prod(axis=2) * is_active
    room = hat * (force / np.where(hat.sum(axis=1) > 0, hat.sum(axis=1), 1.0))[:, None]
    on = room > 0
    return near[on], room[on]


def _merged(index: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of index [n, d] and the sums of ``values`` [n] over each."""
    rows, inverse = _unique_rows(index)
    return rows, np.bincount(inverse, weights=values, minlength=len(rows))


def _torque_couple(rooms: list[tuple[np.ndarray, np.ndarray]], torque: np.ndarray) -> list[np.ndarray]:
    """Forces [K_a] [N] per component a on samples at lattice positions x_a [K_a, d] (repeats allowed;
    ``rooms[a]`` = (x_a, room_a), room_a >= 0 [N]: how much force each may take) that sum to zero per
    component and whose torque, sum g_a x_b - g_b x_a, is -torque[a, b] [N h] (torque antisymmetric):
    the smallest such forces in the room-weighted norm, g_a = room_a (Lambda_a . (x_a - xbar_a)) with
    Lambda antisymmetric. Torque about directions in which the samples with room do not spread
    (eigenvalues of the constraints' Gram matrix below SPREAD_CUTOFF times the room) is left."""
    d = torque.shape[0]
    pairs = list(itertools.combinations(range(d), 2))
    centred, second = [], []
    for x, room in rooms:
        xbar = room @ x / room.sum() if room.sum() > 0 else np.zeros(d)
        centred.append(x - xbar)
        second.append(((x - xbar) * room[:, None]).T @ (x - xbar))

    def multipliers(lam: np.ndarray) -> np.ndarray:  # Lambda [d, d] of one value per pair (a < b)
        big = np.zeros((d, d))
        for (a, b), v in zip(pairs, lam):
            big[a, b], big[b, a] = v, -v
        return big

    def constraints(lam: np.ndarray) -> np.ndarray:
        # the torques sum_k g_ak x_kb - g_bk x_ka of the forces the multipliers ``lam`` [pairs] give
        moments = np.stack([multipliers(lam)[a] @ second[a] for a in range(d)])  # [a, b] = sum_k g_ak x_kb
        return np.array([moments[a, b] - moments[b, a] for a, b in pairs])

    gram = np.stack([constraints(e) for e in np.eye(len(pairs))], axis=1)
    e, v = np.linalg.eigh(0.5 * (gram + gram.T))
    keep = e > SPREAD_CUTOFF * sum(r.sum() for _, r in rooms)
    want = -np.array([torque[a, b] for a, b in pairs])
    big = multipliers(v[:, keep] @ ((v[:, keep].T @ want) / e[keep]))
    return [room * (xc @ big[a]) for a, ((_, room), xc) in enumerate(zip(rooms, centred))]


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
