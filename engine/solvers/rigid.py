"""Rigid-body modes: which ones the Dirichlet conditions leave free, and whether the loads balance.

A body (a connected component of material) whose prescribed displacements do not pin all its
rigid modes (d translations and d(d-1)/2 infinitesimal rotations) can only be solved when the
loads do no work on the free modes (net force and torque zero); the solve then runs in the
complement of those modes. Unbalanced loads on a free body are an error naming the net force.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import VoxelasticError

# Loads balance when their work on a unit-normalised free mode is below this times their size.
BALANCE_TOLERANCE = 1e-6
# A mode is pinned when the Dirichlet DOFs see it with at least this share of its norm.
PIN_TOLERANCE = 1e-10
# Singular values below this (relative) mean the free modes are dependent on the body's DOFs.
RANK_TOLERANCE = 1e-8
# Singular values above this (relative) are resolved well by the modes' Gram matrix (its round-off
# is ~1e-16 of the largest eigenvalue, so ~1e-8 of the largest singular value).
GRAM_TOLERANCE = 1e-5
ROWS = 1 << 16  # rows of an [n, k] array multiplied at once in place


class UnbalancedLoadError(VoxelasticError):
    """Loads on a body with free rigid modes do not balance."""


def rigid_modes(points: np.ndarray, axis: np.ndarray, center: np.ndarray | None = None) -> np.ndarray:
    """Rigid modes [n, m] at scalar DOFs: the DOF at ``points`` [n, d] [m] carries component
    ``axis`` [n] of each mode. Columns: d translations, then rotations in the planes (k, l), k < l,
    about ``center`` (default the centroid) with unit angle: u_k = -(x_l - c_l), u_l = x_k - c_k."""
    points = np.asarray(points, dtype=float)
    n, d = points.shape
    c = points.mean(axis=0) if center is None else np.asarray(center, dtype=float)
    planes = list(itertools.combinations(range(d), 2))
    # filled column by column: a body of 20 M DOFs would hold a dozen [n] temporaries otherwise
    out = np.zeros((n, d + len(planes)))
    on = [np.nonzero(axis == k)[0] for k in range(d)]
    for k in range(d):
        out[on[k], k] = 1.0
    for m, (k, l) in enumerate(planes, start=d):
        out[on[k], m] = c[l] - points[on[k], l]
        out[on[l], m] = points[on[l], k] - c[k]
    return out


def rigid_motions(points: np.ndarray, center: np.ndarray | None = None) -> np.ndarray:
    """Rigid modes as vector fields [n, m, d] at ``points`` [n, d] [m]: the columns of
    :func:`rigid_modes` (same order: d translations, then rotations in the planes (k, l), k < l)
    with every component at once. ``center``: [d], or [n, d] for one per point (points of several
    bodies about their own centres); default the centroid."""
    points = np.asarray(points, dtype=float)
    n, d = points.shape
    c = points.mean(axis=0) if center is None else np.asarray(center, dtype=float)
    x = points - c
    planes = list(itertools.combinations(range(d), 2))
    r = np.zeros((n, d + len(planes), d))
    r[:, np.arange(d), np.arange(d)] = 1.0
    for m, (k, l) in enumerate(planes, start=d):
        r[:, m, k], r[:, m, l] = -x[:, l], x[:, k]
    return r


def free_modes(points: np.ndarray, axis: np.ndarray, fixed: np.ndarray, body: np.ndarray,
               held: sp.spmatrix | None = None) -> list[np.ndarray]:
    """For each body, an orthonormal basis [n_body, k] (over that body's unfixed DOFs, in order) of
    the rigid modes the fixed DOFs leave free; bodies with none free are omitted.

    points [n, d], axis [n]: every DOF; fixed [n] bool: prescribed; body [n] int: component label;
    held [n, n]: a positive semi-definite penalty on the DOFs (weak Dirichlet conditions), which
    holds the modes it does not vanish on.
    Returns a list of (dof indices [n_body_free], basis [n_body_free, k]) flattened as arrays of
    shape [n_body_free, 1 + k] would be awkward, hence pairs.
    """
    out = []
    d = points.shape[1]
    labels = np.nonzero(np.bincount(body))[0] if len(body) and body.min() >= 0 else np.unique(body)
    for label in labels:
        # one body (the usual case) is every DOF: no masked copies of [n, d] arrays (the 256^3
        # shell has 20 M DOFs, and this ran for seconds)
        on = slice(None) if len(labels) == 1 else np.nonzero(body == label)[0]
        center = points[on].mean(axis=0)
        # unit columns over the whole body, but only the pinned rows built: a clamped body (the
        # usual case) stops here, without an [n, modes] array over all its DOFs
        norms = _mode_norms(points[on], center, axis[on], d)
        pins = np.nonzero(fixed[on])[0]
        pinned = rigid_modes(points[on][pins], axis[on][pins], center) / norms
        gram = pinned.T @ pinned
        if held is not None:
            gram = gram + _held_gram(held, points, axis, on, center, norms)
        w, v = np.linalg.eigh(gram)
        loose = v[:, w < PIN_TOLERANCE * max(1.0, float(w.max(initial=0.0)))]
        if loose.shape[1] == 0:
            continue
        free_dofs = np.arange(len(body))[on][~fixed[on]]
        everything = len(free_dofs) == len(body)  # a free body alone: no copies of its points
        free_part = rigid_modes(points if everything else points[free_dofs],
                                axis if everything else axis[free_dofs], center)
        free_part /= norms
        q = _orthonormal(_times(free_part, loose))
        if q.shape[1]:
            out.append((free_dofs, q))
    return out


def _orthonormal(a: np.ndarray) -> np.ndarray:
    """An orthonormal basis [n, r] of the columns of a [n, k] (k small; ``a`` is overwritten),
    dropping the directions whose singular value is below RANK_TOLERANCE of the largest: the modes
    can be dependent on few DOFs (a rotation vanishes at a lone cell's faces). An SVD of the [n, k]
    array holds ~3 such arrays at once (a free body of 20 M DOFs: ~3 GiB), so the usual case --
    modes far from dependent -- goes by the k x k Gram matrix, twice (the first pass squares the
    condition, the second restores orthonormality to round-off), in place. The Gram matrix
    resolves singular values only down to ~1e-8 of the largest, so when one lies below
    GRAM_TOLERANCE the SVD decides."""
    w, v = np.linalg.eigh(a.T @ a)
    s = np.sqrt(np.clip(w, 0.0, None))
    top = max(1.0, float(s.max(initial=0.0)))
    if np.any((s > 0) & (s < GRAM_TOLERANCE * top)):
        u, sv, _ = np.linalg.svd(a, full_matrices=False)
        return u[:, sv > RANK_TOLERANCE * max(1.0, float(sv.max(initial=0.0)))]
    keep = s > RANK_TOLERANCE * top
    q = _times(a, v[:, keep] / s[keep])
    if q.shape[1]:
        q = _times(q, np.linalg.inv(np.linalg.cholesky(q.T @ q)).T)
    return q


def _times(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    """a @ m for a [n, k] and m [k, r], r <= k, written into a's first r columns (returned as a view)
    a block of rows at a time: no second [n, k] array."""
    r = m.shape[1]
    for start in range(0, len(a), ROWS):
        block = a[start:start + ROWS]
        block[:, :r] = block @ m
    return a[:, :r]


def _held_gram(held: sp.spmatrix, points: np.ndarray, axis: np.ndarray, on, center: np.ndarray,
               norms: np.ndarray) -> np.ndarray:
    """R^T H R / max diag(H) for the unit rigid modes R of the body ``on`` on the DOFs the
    penalty H [n, n] touches: a DOF held as firmly as the firmest counts like a pinned one."""
    h = held.tocsr()
    if isinstance(on, slice):
        # the body is every DOF: no fancy-indexed copies of H and of the points (1.2 s, and 0.5 GiB
        # for the points, on the 256^3 shell's 20 M DOFs, of which H touches a few hundred thousand)
        sub = h.tocoo()
    else:
        sub = h[on][:, on].tocoo()
    rows = np.unique(np.concatenate([sub.row, sub.col]))
    if not len(rows):
        return 0.0
    dofs = rows if isinstance(on, slice) else on[rows]
    r = rigid_modes(points[dofs], axis[dofs], center) / norms
    local = sp.csr_matrix((sub.data, (np.searchsorted(rows, sub.row), np.searchsorted(rows, sub.col))),
                          shape=(len(rows), len(rows)))
    return (r.T @ (local @ r)) / max(float(np.abs(h.diagonal()).max(initial=0.0)), np.finfo(float).tiny)


def _mode_norms(points: np.ndarray, center: np.ndarray, axis: np.ndarray, d: int) -> np.ndarray:
    """Euclidean norms [m] of the columns of ``rigid_modes`` about ``center`` (the centroid of
    ``points``), without building them; 1 for a column that vanishes."""
    squares = np.bincount(axis, minlength=d)[:d].astype(float).tolist()
    # sums over the DOFs of each component of each squared coordinate: [component, coordinate]
    moments = np.stack([np.bincount(axis, weights=(points[:, l] - center[l]) ** 2, minlength=d)[:d]
                        for l in range(d)], axis=1)
    for k, l in itertools.combinations(range(d), 2):
        squares.append(float(moments[k, l] + moments[l, k]))
    norms = np.sqrt(np.asarray(squares))
    return np.where(norms > 0, norms, 1.0)


def torque_vector(planes: Sequence[float], digits: int) -> list[float] | float:
    """The torque [N m] (2D: per unit thickness [N]) of the work of loads on the unit rotations in the
    planes (k, l), k < l, of :func:`rigid_modes` (sum r_k f_l - r_l f_k each), as it is written: the
    vector [T_x, T_y, T_z] in 3D (the planes (0, 1), (0, 2), (1, 2) turn about z, -y and x), the
    scalar T_z in 2D; rounded to ``digits``."""
    planes = [float(v) for v in planes]
    if len(planes) == 1:
        return round(planes[0], digits) + 0.0
    return [round(v, digits) + 0.0 for v in (planes[2], -planes[1], planes[0])]


def check_balance(points: np.ndarray, axis: np.ndarray, loads: np.ndarray, modes: list) -> None:
    """Raise ``UnbalancedLoadError`` when ``loads`` [n] [N] do work on a free mode of ``modes``
    (from :func:`free_modes`) beyond the tolerance, naming the net force and torque of that body."""
    d = points.shape[1]
    for dofs, q in modes:
        f = loads[dofs]
        size = np.abs(f).sum()
        if size == 0:
            continue
        scale = np.sqrt(len(dofs))  # q's columns are unit vectors spread over the body's DOFs
        work = np.abs(q.T @ f).max() * scale
        if work > BALANCE_TOLERANCE * size:
            x = points[dofs]
            c = x.mean(axis=0)
            force = np.array([f[axis[dofs] == k].sum() for k in range(d)])
            r = x - c
            planes = [
                float((np.where(axis[dofs] == l, r[:, k], 0.0) * f - np.where(axis[dofs] == k, r[:, l], 0.0) * f).sum())
                for k, l in itertools.combinations(range(d), 2)
            ]
            raise UnbalancedLoadError(
                f"boundaries: the displacement boundaries leave {q.shape[1]} rigid-body mode(s) of a body free, and its "
                f"loads do not balance: net force {(np.round(force, 12) + 0.0).tolist()} N, net torque about its centroid "
                f"{torque_vector(planes, 12)} N m (total load {size:.6g} N); hold every component on a patch "
                "that spans more than a grid cell each way along the surface (a strip narrower than a cell, or a body "
                "thinner than one, can leave a rotation free: refine the grid), or balance the loads"
            )
