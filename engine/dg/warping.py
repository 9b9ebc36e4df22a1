"""Stiffness warping of the DG operator (Kaufmann et al. 2009 section 6).

Internal forces of a warped block are R K (R^T x - X0) with x = X0 + u the deformed state in
coefficients and X0 the coefficients of the identity map (section 6.2: every basis holds the
affine polynomials, so X0 is exact). Element blocks use the element's rotation; the consistency
parts of interface and Nitsche blocks use the rotation of the side whose stress they carry
(section 6.1); penalty blocks are not warped. Rotations come from the polar decomposition of each
element's mean deformation gradient; a static solve iterates rotations -> assembly -> solve to a
fixed point. The method hands :func:`solve_corotated` the one step it owns (warp its operator by
given rotations, factorise, solve) as a callable; this module reads none of its state.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..errors import VoxelasticError
from ..method import State
from ..solvers.linear import SolveStats
from . import basis as B
from . import kernels
from .assembly import Group
from .elements import Elements
from .integrals import Basis

COROTATED_TOL = 1e-8  # fixed point of the rotations: relative change of u per iteration
# ... or a change of u under this many eps ||X0||: the warped forces R K (R^T x - X0) round R^T x - X0 off
# by about eps |X0|, so a body strained 1e-8 (a stiff part under a light load) changed u by 1e-7 of
# itself in every iteration (steps of 0.4-1.3 eps ||X0||, rotations within 5e-15 of I) and was refused
ROUNDOFF_STEPS = 100.0
# ... or a stall (no new smallest change for DIVERGED_AFTER iterations) after a change under this one:
# the iterate of that change is the fixed point to about that change. Free thin plates at nu 0.4999
# under pressure stall there: round-off amplified by the solve (rotations 2e-12 from I, u changing by
# 1e-7 to 7e-7 of itself, 40x the ROUNDOFF_STEPS floor), or a fixed point the iteration leaves from
# 1e-6 on (changes growing 1.3-2.1x per iteration, under tension too, so no buckling; the cause is not
# pinned down, likely the interface terms' lambda acting on the rotations' noise), both refused before
# as a load step too large
STALL_ACCEPT = 1e-6
COROTATED_MAX = 100
OMEGA_RANGE = (0.05, 2.0)  # the relaxation factor's bounds: some progress, at most twice the step

# warp(rotations [E, 3, 3]) -> (u [E, 3, n], stats): the operator warped by those rotations, solved
WarpedSolve = Callable[[np.ndarray], tuple[np.ndarray, SolveStats]]


def reference_state(elements: Elements, basis: Basis) -> np.ndarray:
    """X0 [E, 3, n]: coefficients of the identity map x = c_K + h xi in every element's basis."""
    L = basis.L
    c = elements.centres
    return c[:, :, None] * L[:, None, 0, :] + basis.h * L[:, 1:4, :]


def mean_gradients(elements: Elements, basis: Basis) -> np.ndarray:
    """[E, 3, n]: (1 / vol) int_K d_a psi_I dV [1/m], so grad u = sum_I u[:, p, I] g[:, a, I]."""
    n = basis.size
    integral = basis.h**2 * np.einsum("eis,ast,et->eai", basis.T, B.derivative(basis.degree), elements.moments[:, :n])
    return integral / elements.volume[:, None, None]


def rotations(u: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """Rotation [E, 3, 3] of each element: polar factor of I + mean grad u (u [E, 3, n],
    ``gradients`` from :func:`mean_gradients`)."""
    F = np.eye(3) + np.einsum("epi,eai->epa", u, gradients)
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
        full = np.empty((len(g),) + g.data.shape[1:])
        for a in range(0, len(g), CHUNK):
            part = slice(a, min(a + CHUNK, len(g)))
            data, owner, rows, cols = g.blocks(part), g.owner[part], g.rows[part], g.cols[part]
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


def solve_corotated(warped_solve: WarpedSolve, start: np.ndarray, gradients: np.ndarray,
                    on_iteration: Callable[[int, float], None] | None, t0: float, reference: float = 0.0) -> State:
    """Fixed point of rotations and displacement from ``start`` [E, 3, n]: u -> rotations(u) ->
    ``warped_solve`` until u changes by less than COROTATED_TOL (relative) or by less than
    ROUNDOFF_STEPS eps ``reference`` (||X0||, :func:`reference_state`'s norm [m]), or the changes
    stall after one under STALL_ACCEPT (then the iterate of that one is returned); iterations = linear
    solves, ``on_iteration(i, residual)`` after each. t0: when the solve began (perf_counter [s]).
    Raises CorotatedDiverged when the changes grow, VoxelasticError after COROTATED_MAX."""
    floor = ROUNDOFF_STEPS * np.finfo(float).eps * reference
    u = start
    history: list[float] = []
    changes: list[float] = []
    step, omega = None, 1.0
    best: tuple[float, np.ndarray, float] | None = None  # (change, u, residual) of the smallest change
    for it in range(1, COROTATED_MAX + 1):
        new, stats = warped_solve(rotations(u, gradients))
        residual = stats.residual
        # Aitken's relaxation (Irons & Tuck): a large rotation's fixed point can repel the plain
        # iteration (a 7e4 Pa tip traction came within 1.6e-8 of it, then drifted off by 1.23x per
        # iteration); the relaxed one settles, and a contracting one is sped up
        previous, step = step, new - u
        if previous is not None:
            jump = step - previous
            norm = float(np.vdot(jump, jump))
            if norm > 0:
                omega = float(np.clip(-omega * np.vdot(previous, jump) / norm, OMEGA_RANGE[0], OMEGA_RANGE[1]))
        change = float(np.linalg.norm(step) / max(np.linalg.norm(new), 1e-300))
        history.append(residual)
        changes.append(change)
        if on_iteration is not None:
            on_iteration(it, residual)
        if best is None or change < best[0]:
            best = (change, new, residual)
        if change < COROTATED_TOL or np.linalg.norm(step) <= floor:
            u = new
            break
        if _stalled(changes) and best[0] < STALL_ACCEPT:  # the iterate nearest the fixed point
            _, u, residual = best
            break
        u = u + omega * step
        if _diverged(changes, COROTATED_TOL):
            recent = ", ".join(f"{c:.3g}" for c in changes[-DIVERGED_AFTER:])
            raise CorotatedDiverged(
                f"dg: the corotated fixed-point iteration diverges: relative changes {recent} in iterations "
                f"{it - DIVERGED_AFTER + 1}-{it}, never below the {min(changes[:-DIVERGED_AFTER]):.3g} reached before; "
                "the load step is too large, use a quasistatic analysis with more steps; if the steps fail as well, the "
                "load is past where the corotated model reaches an equilibrium (a buckling or snap-through load): reduce it")
    else:
        raise VoxelasticError(f"dg: the corotated rotations did not settle in {COROTATED_MAX} iterations "
                              f"(last relative change {change:.3g}); the load step is too large, use a quasistatic "
                              "analysis with more steps")
    seconds = time.perf_counter() - t0
    return State(u, SolveStats(it, residual, history, seconds=seconds), seconds, rotations=rotations(u, gradients))


def _stalled(changes: list[float]) -> bool:
    """No new smallest change for DIVERGED_AFTER iterations."""
    return len(changes) > DIVERGED_AFTER and min(changes[-DIVERGED_AFTER:]) >= min(changes[:-DIVERGED_AFTER])


def _diverged(changes: list[float], tol: float) -> bool:
    """A stall far above the tolerance (one near it is round-off, not divergence: STALL_ACCEPT)."""
    return _stalled(changes) and min(changes[-DIVERGED_AFTER:]) > 1e4 * tol

