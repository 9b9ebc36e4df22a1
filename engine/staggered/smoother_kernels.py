"""Taichi kernels of the hybrid smoother for near-incompressible materials (``curls.py``).

M^-1 = D^-1 + C Theta^-1 C^T: point Jacobi plus Jacobi on the discrete curls. C's column for the
edge of pair (a, b) = ``PAIRS[q]`` at index E (3D: the edge along the third axis through the
corner of cell E; 2D: the node) is the curl of that edge's potential,

    c = e_(a, E) - e_(a, E - e_b) - e_(b, E) + e_(b, E - e_a),

divergence-free in every cell; Theta = diag(C^T A C). Arrays: per-component [d, size] as in
``kernels.py``; per-edge [pairs, size] (pair q's edge E at E's flat position).
"""

import itertools

import gstaichi as ti

from .. import runtime  # noqa: F401 - first: its Taichi patches make the decorators below quick
from ..grid import axis_pairs
from .kernels import BITS, B, face_neighbours, local_coords, stored

PAIRS = {d: axis_pairs(d) for d in (2, 3)}
# What hybrid_step does with z = mask (D^-1 r + C t) (a runtime argument: one compiled kernel).
START, STEP, APPLY = 0, 1, 2


def curl_taps(d: int, q: int) -> list[tuple[int, tuple[int, ...], float]]:
    """(component, offset from E, coefficient) of the curl of pair q's edge at E."""
    a, b = PAIRS[d][q]
    eye = [tuple(int(k == j) for k in range(d)) for j in range(d)]
    zero = (0,) * d
    return [(a, zero, 1.0), (a, tuple(-x for x in eye[b]), -1.0), (b, zero, -1.0), (b, tuple(-x for x in eye[a]), 1.0)]


def _coefficients(d: int, q: int, plus: list[tuple[int, tuple[int, ...]]],
                  minus: list[tuple[int, tuple[int, ...]]]) -> list[float]:
    """Per tap of pair q's curl: its coefficient in (sum of the faces ``plus``) - (sum of ``minus``)
    (faces as (component, offset from E)), so a quantity of the masked curl is sum_i coef_i m_i."""
    out = []
    for k, o, c in curl_taps(d, q):
        out.append(c * (((k, o) in plus) - ((k, o) in minus)))
    return out


def _plus(o: tuple[int, ...], a: int, step: int) -> tuple[int, ...]:
    return tuple(x + step * (k == a) for k, x in enumerate(o))


def cell_terms(d: int, q: int) -> list[tuple[tuple[int, ...], list[list[float]]]]:
    """The cells whose normal strains the curl of pair q's edge moves: (cell offset from E, per
    component k the tap coefficients of h eps_kk = u_k(C + e_k) - u_k(C))."""
    out = []
    for o in itertools.product((-1, 0), repeat=d):
        strains = [_coefficients(d, q, [(k, _plus(o, k, 1))], [(k, o)]) for k in range(d)]
        if any(any(s) for s in strains):
            out.append((o, strains))
    return out


def edge_terms(d: int, q: int) -> list[tuple[int, tuple[int, ...], list[float]]]:
    """The shear edges the curl of pair q's edge strains: (pair q2, edge offset from E, the tap
    coefficients of 2 h eps_ab = u_a(E') - u_a(E' - e_b) + u_b(E') - u_b(E' - e_a))."""
    out = []
    for q2, (a, b) in enumerate(PAIRS[d]):
        for o in itertools.product((-1, 0, 1), repeat=d):
            g = _coefficients(d, q, [(a, o), (b, o)], [(a, _plus(o, b, -1)), (b, _plus(o, a, -1))])
            if any(g):
                out.append((q2, o, g))
    return out


def _tap_codes(d: int, q: int) -> list[tuple[int, int, int, float]]:
    """(tap number, component, offset code, coefficient) of pair q's curl."""
    return [(i, k, _code(d, o), c) for i, (k, o, c) in enumerate(curl_taps(d, q))]


def _code(d: int, offset: tuple[int, ...]) -> int:
    """Number of an offset in {-1, 0, 1}^d (C order, as ``TileLayout.neighbours``)."""
    c = 0
    for k in range(d):
        c = 3 * c + offset[k] + 1
    return c


def _cube(d: int) -> list[tuple[int, ...]]:
    return list(itertools.product((-1, 0, 1), repeat=d))


@ti.func
def block(d: ti.template(), nbr: ti.types.ndarray(), p: ti.i32):
    """Flat positions of p + o for every o in {-1, 0, 1}^d (numbered by :func:`_code`); a position
    in the zero tile where p + o lies in a tile that is not kept."""
    t = p >> (BITS * d)
    l = p & (B**d - 1)
    out = ti.Vector([0] * (3**d), dt=ti.i32)
    for o in ti.static(_cube(d)):
        step = ti.Vector([0] * d, dt=ti.i32)
        loc = 0
        for k in ti.static(range(d)):
            c = ((l >> (BITS * (d - 1 - k))) & (B - 1)) + o[k]
            if c < 0:
                step[k] = -1
                c += B
            elif c >= B:
                step[k] = 1
                c -= B
            loc = loc * B + c
        code = 0
        for k in ti.static(range(d)):
            code = code * 3 + step[k] + 1
        out[ti.static(_code(d, o))] = nbr[t, code] * (B**d) + loc
    return out


@ti.kernel(fastcache=True)
def curl_diagonal(d: ti.template(), n: ti.i32, nbr: ti.types.ndarray(), vc: ti.types.ndarray(),
                  ve: ti.types.ndarray(), mask: ti.types.ndarray(), mass: ti.types.ndarray(), shift: float,
                  lam: float, mu: float, scale: float, theta: ti.types.ndarray()):
    """theta[q, p] = c^T (K + shift M) c for the curl c of pair q's edge at each of the n kept
    positions, restricted to the unknowns (``mask``); scale = h^{d-2}. Cells: Vc (2 mu sum_k
    (h eps_kk)^2 + lambda (h tr eps)^2), edges: mu Ve (2 h eps_ab)^2 (tables :func:`cell_terms`,
    :func:`edge_terms`)."""
    for p in range(n):
        near = block(d, nbr, p)
        for q in ti.static(range(len(PAIRS[d]))):
            m = ti.Vector([0.0] * 4)  # the taps that are unknowns
            total = 0.0
            for i, k, code, c in ti.static(_tap_codes(d, q)):
                m[i] = mask[k, near[code]]
                total += shift * mass[k, near[code]] * m[i] * c * c
            for o, strains in ti.static(cell_terms(d, q)):
                tr = 0.0
                sq = 0.0
                for coef in ti.static(strains):
                    e = 0.0
                    for i in ti.static(range(4)):
                        if ti.static(coef[i] != 0):
                            e += coef[i] * m[i]
                    tr += e
                    sq += e * e
                total += scale * vc[near[ti.static(_code(d, o))]] * (2.0 * mu * sq + lam * tr * tr)
            for q2, o, coef in ti.static(edge_terms(d, q)):
                g = 0.0
                for i in ti.static(range(4)):
                    if ti.static(coef[i] != 0):
                        g += coef[i] * m[i]
                total += scale * mu * ve[q2, near[ti.static(_code(d, o))]] * g * g
            theta[q, p] = stored(theta, total)


@ti.kernel(fastcache=True)
def curl_residual(d: ti.template(), n: ti.i32, nbr: ti.types.ndarray(), r: ti.types.ndarray(),
                  inv_theta: ti.types.ndarray(), t: ti.types.ndarray()):
    """t[q, p] = inv_theta[q, p] c^T r for pair q's edge at each of the n kept positions."""
    for p in range(n):
        tile = p >> (BITS * d)
        up, down = face_neighbours(d, nbr, tile, p, local_coords(d, p & (B**d - 1)))
        for q in ti.static(range(len(PAIRS[d]))):
            a, b = ti.static(PAIRS[d][q])
            t[q, p] = stored(t, inv_theta[q, p] * (r[a, p] - r[a, down[b]] - r[b, p] + r[b, down[a]]))


@ti.kernel(fastcache=True)
def hybrid_step(d: ti.template(), mode: ti.i32, n: ti.i32, nbr: ti.types.ndarray(), dinv: ti.types.ndarray(),
                mask: ti.types.ndarray(), r: ti.types.ndarray(), t: ti.types.ndarray(), x: ti.types.ndarray(),
                step: ti.types.ndarray(), c1: float, c2: float):
    """z = mask (D^-1 r + C t) at each of the n kept positions (t from :func:`curl_residual`).
    ``mode``: START step = x = c2 z; STEP step = c1 step + c2 z, x += step; APPLY x = c2 z."""
    for p in range(n):
        tile = p >> (BITS * d)
        up, down = face_neighbours(d, nbr, tile, p, local_coords(d, p & (B**d - 1)))
        for a in ti.static(range(d)):
            z = dinv[a, p] * r[a, p]
            for q in ti.static(range(len(PAIRS[d]))):
                qa, qb = ti.static(PAIRS[d][q])
                if ti.static(qa == a):  # (a, E) +1 at E = p, (a, E - e_b) -1 at E = p + e_b
                    z += t[q, p] - t[q, up[qb]]
                elif ti.static(qb == a):  # (b, E) -1 at E = p, (b, E - e_a) +1 at E = p + e_a
                    z += t[q, up[qa]] - t[q, p]
            z *= mask[a, p]
            if mode == START:
                step[a, p] = stored(step, c2 * z)
                x[a, p] = stored(x, c2 * z)
            elif mode == STEP:
                s = c1 * step[a, p] + c2 * z
                step[a, p] = stored(step, s)
                x[a, p] = stored(x, x[a, p] + s)
            else:
                x[a, p] = stored(x, c2 * z)


@ti.kernel(fastcache=True)
def band_add(mode: ti.i32, comp: ti.types.ndarray(), pos: ti.types.ndarray(), w: ti.types.ndarray(),
             mask: ti.types.ndarray(), c2: float, step: ti.types.ndarray(), x: ti.types.ndarray()):
    """What the vertex patches' w = Z r (``patches.py``; at the band's DOFs comp[k], pos[k]) add to
    :func:`hybrid_step`'s z, after it: x += c2 mask w, and step too unless ``mode`` is APPLY (each
    DOF once: no races)."""
    for k in range(comp.shape[0]):
        a, p = comp[k], pos[k]
        v = c2 * mask[a, p] * w[k]
        x[a, p] = stored(x, x[a, p] + v)
        if mode != APPLY:
            step[a, p] = stored(step, step[a, p] + v)
