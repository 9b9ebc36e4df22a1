"""Stiffness warping of the DG operator (Kaufmann et al. 2009 section 6).

Internal forces of a warped block are R K (R^T x - X0) with x = X0 + u the deformed state in
coefficients and X0 the coefficients of the identity map (section 6.2: every basis holds the
affine polynomials, so X0 is exact). Element blocks use the element's rotation; the consistency
parts of interface and Nitsche blocks use the rotation of the side whose stress they carry
(section 6.1); penalty blocks are not warped. Rotations come from the polar decomposition of each
element's mean deformation gradient; a static solve iterates rotations -> assembly -> solve to a
fixed point.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import VoxelasticError
from ..method import State
from ..solvers.cg import SolveStats
from . import basis as B
from . import kernels
from .assembly import Group


def reference_state(method) -> np.ndarray:
    """X0 [E, 3, n]: coefficients of the identity map x = c_K + h xi in every element's basis."""
    el, basis = method.elements, method.basis
    L = basis.L
    c = el.centres
    return c[:, :, None] * L[:, None, 0, :] + basis.h * L[:, 1:4, :]


def mean_gradients(method) -> np.ndarray:
    """[E, 3, n]: (1 / vol) int_K d_a psi_I dV [1/m], so grad u = sum_I u[:, p, I] g[:, a, I]."""
    el, basis = method.elements, method.basis
    n = basis.size
    integral = basis.h**2 * np.einsum("eis,ast,et->eai", basis.T, B.derivative(basis.degree), el.moments[:, :n])
    return integral / el.volume[:, None, None]


def rotations(method, u: np.ndarray) -> np.ndarray:
    """Rotation [E, 3, 3] of each element: polar factor of I + mean grad u (u [E, 3, n])."""
    if getattr(method, "_mean_gradients", None) is None:
        method._mean_gradients = mean_gradients(method)
    F = np.eye(3) + np.einsum("epi,eai->epa", u, method._mean_gradients)
    U, _, Vt = np.linalg.svd(F)
    flip = np.linalg.det(U @ Vt) < 0
    U[flip, :, 2] *= -1  # a reflection is not a rotation: flip the least stretched direction
    return U @ Vt


def _rotated(data: np.ndarray, left: np.ndarray, right: np.ndarray, R: np.ndarray,
             out: np.ndarray | None = None) -> np.ndarray:
    out = np.empty_like(data) if out is None else out
    kernels.rotate_blocks(np.ascontiguousarray(data), left.astype(np.int32), right.astype(np.int32),
                          np.ascontiguousarray(R), out)
    return out


# Blocks warped per pass: the half-warped copies, their differences and the mirrors are made for
# this many blocks at a time, so a refactorisation holds the group and its warped copy and little
# else (for whole groups at once the temporaries were ~3 more copies: a 20-cell k = 2 torus peaked
# at 1.62x the linear job's memory; issue 18).
CHUNK = 4096


def rotate(groups: list[Group], R: np.ndarray, X0: np.ndarray) -> tuple[list[Group], np.ndarray]:
    """Warped groups (R K R^T for blocks with an owner) and the load they add, [E, 3, n]:
    R K X0 - R K R^T X0 per block (and its mirror for off-diagonal blocks)."""
    E = len(R)
    Rx = np.concatenate([R, np.eye(3)[None]])  # index E: no rotation (the half-warped R K)
    s = X0.shape[1] * X0.shape[2]
    X0f = X0.reshape(E, s)
    load = np.zeros((E, s))
    out = []
    for g in groups:
        if g.owner is None:
            out.append(g)
            continue
        full = np.empty_like(g.data)
        for a in range(0, len(g.data), CHUNK):
            part = slice(a, min(a + CHUNK, len(g.data)))
            data, owner, rows, cols = g.data[part], g.owner[part], g.rows[part], g.cols[part]
            warped = _rotated(data, owner, owner, Rx, out=full[part])
            half = _rotated(data, owner, np.full(len(owner), E), Rx)
            np.add.at(load, rows, np.einsum("kij,kj->ki", half - warped, X0f[cols]))
            off = rows != cols
            if np.any(off):
                # mirrored block (cols, rows): (R K)^T acts as K^T R^T; its warped force is
                # R K^T X0 - R K^T R^T X0
                mirror = _rotated(data[off].transpose(0, 2, 1).copy(), owner[off], np.full(int(off.sum()), E), Rx)
                np.add.at(load, cols[off], np.einsum("kij,kj->ki", mirror - warped[off].transpose(0, 2, 1),
                                                     X0f[rows[off]]))
        out.append(Group(g.rows, g.cols, full, None))
    return out, load.reshape(X0.shape)


class CorotatedDiverged(VoxelasticError):
    """The fixed point of the rotations moves away instead of settling (the load step is too large)."""


# The iteration has diverged when this many iterations in a row brought no relative change below
# the smallest one seen before them. A contraction makes a new smallest change every iteration
# (slow ones too: the 20 kN torus settles at 0.97 per iteration after a bump at iteration 6);
# a diverging step keeps changing u by about its own size (the 200 kN torus: 1.07-1.43 from
# iteration 4 on, for 100 iterations on the old code).
DIVERGED_AFTER = 5


def solve_corotated(method, load_scale: float, value_scale: float, inertia, on_iteration, t0: float):
    """Fixed point of rotations and displacement; iterations = linear solves."""
    from .elasticity import COROTATED_MAX, COROTATED_TOL

    u = getattr(method, "_last_u", None)
    u = np.zeros((method.elements.count, 3, method.n)) if u is None else u
    history: list[float] = []
    changes: list[float] = []
    for it in range(1, COROTATED_MAX + 1):
        _free_factor(method)
        method.set_rotations(rotations(method, u))
        new, residual = method._linear_solve(load_scale, value_scale, inertia)
        change = float(np.linalg.norm(new - u) / max(np.linalg.norm(new), 1e-300))
        u = new
        history.append(residual)
        changes.append(change)
        if on_iteration is not None:
            on_iteration(it, residual)
        if change < COROTATED_TOL:
            break
        if _diverged(changes, COROTATED_TOL):
            _free_factor(method)
            recent = ", ".join(f"{c:.3g}" for c in changes[-DIVERGED_AFTER:])
            raise CorotatedDiverged(
                f"dg: the corotated fixed-point iteration diverges: relative changes {recent} in iterations "
                f"{it - DIVERGED_AFTER + 1}-{it}, never below the {min(changes[:-DIVERGED_AFTER]):.3g} reached before; "
                "the load step is too large, use a quasistatic analysis with more steps")
    else:
        raise VoxelasticError(f"dg: the corotated rotations did not settle in {COROTATED_MAX} iterations "
                              f"(last relative change {change:.3g}); the load step is too large, use a quasistatic "
                              "analysis with more steps")
    method._last_u = u
    return State(u, SolveStats(it, residual, history), time.perf_counter() - t0, rotations=rotations(method, u))


def _diverged(changes: list[float], tol: float) -> bool:
    """No new smallest change for DIVERGED_AFTER iterations, far above the tolerance (a stall
    near the tolerance is round-off, not divergence: it is left to the iteration limit)."""
    if len(changes) <= DIVERGED_AFTER:
        return False
    before, recent = min(changes[:-DIVERGED_AFTER]), changes[-DIVERGED_AFTER:]
    return min(recent) >= before and min(recent) > 1e4 * tol


def _free_factor(method) -> None:
    """Release the current factorisation before the next one is made: PARDISO's memory is not
    Python's, so a replaced factor would otherwise stay resident (issue 18)."""
    factor = getattr(method, "_factor", None)
    if factor is not None:
        factor.free()
        method._factor = None
