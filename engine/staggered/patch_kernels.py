"""Taichi kernels of the vertex-patch smoother (additive Schwarz) for near-incompressible materials.

A *vertex patch* is the set of faces that meet at a grid vertex V inside the 2^d cells around it:
for each component a, the a-faces (a, V - o) with o in {0, 1}^d, o_a = 0 (4 in 2D, 12 in 3D:
``m = d 2^(d-1)``). The discrete curls of the vertex's stream function (2D) or edge potentials
(3D) are divergence-free fields supported there, so smoothing with exact solves on these patches
sees the lambda (div u)^2 term's null space (Schoeberl 1999; Arnold, Falk & Winther 2000).

Slot ``a 2^(d-1) + k`` of a patch is component a at offset o, k the bits of o on the other axes
(first other axis most significant). Vertex V is the low corner of cell V: its patch is stored at
V's flat position. ``cmap`` [size] int32 gives each vertex's row in ``inv`` [n, m, m]: row 0 is
the patch shared by every vertex whose weights are all 1 (the constant-coefficient interior), the
others are the vertices near cut cells, surface terms or masked DOFs (``patches.py`` builds them).

Shapes: per-component arrays [d, size] as in ``kernels.py``; ``verts`` [n] int32 flat positions.
"""

import itertools

import taichi as ti

from ..grid import axis_pairs
from .kernels import BITS, B, stored

PAIRS = {d: axis_pairs(d) for d in (2, 3)}


def _slot(d: int, a: int, o: tuple[int, ...]) -> int:
    """Patch slot of component a at offset o (o[a] must be 0)."""
    k = 0
    for j in range(d):
        if j != a:
            k = 2 * k + o[j]
    return a * 2 ** (d - 1) + k


def _patch_dofs(d: int) -> list[tuple[int, tuple[int, ...], int]]:
    """(component a, offset o, slot) of every patch slot, in slot order."""
    out = []
    for a in range(d):
        for o in itertools.product((0, 1), repeat=d):
            if o[a] == 0:
                out.append((a, o, _slot(d, a, o)))
    return sorted(out, key=lambda t: t[2])


def _cube(d: int) -> list[tuple[int, ...]]:
    """{-1, 0, 1}^d in C order."""
    return list(itertools.product((-1, 0, 1), repeat=d))


def _corners(d: int) -> list[tuple[int, ...]]:
    """{0, 1}^d in C order."""
    return list(itertools.product((0, 1), repeat=d))


def _minus(o: tuple[int, ...], o2: tuple[int, ...]) -> tuple[int, ...]:
    return tuple(x - y for x, y in zip(o, o2))


def _code(d: int, offset: tuple[int, ...]) -> int:
    """Number of an offset in {-1, 0, 1}^d (C order, as ``TileLayout.neighbours``)."""
    c = 0
    for k in range(d):
        c = 3 * c + offset[k] + 1
    return c


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


def _edge_terms(d: int, q: int) -> list[tuple[tuple[int, ...], list[tuple[int, float]]]]:
    """The shear edges of pair q that read a patch face: (edge offset from V, [(slot, coefficient)]
    of the patch faces it reads), coefficients of 2 eps_ab = u_a(E) - u_a(E - e_b) + u_b(E) -
    u_b(E - e_a) (the energy's 2 mu Ve eps_ab^2 h^d gives mu Ve h^{d-2} per product)."""
    a, b = PAIRS[d][q]
    eye = [tuple(int(k == j) for k in range(d)) for j in range(d)]
    out = []
    others = [k for k in range(d) if k not in (a, b)]
    for da in (-1, 0, 1):
        for db in (-1, 0, 1):
            if da and db:
                continue
            for rest in itertools.product((-1, 0), repeat=len(others)):
                E = [0] * d
                E[a], E[b] = da, db
                for k, r in zip(others, rest):
                    E[k] = r
                taps = []
                for comp, shift, sign in ((a, None, 1.0), (a, b, -1.0), (b, None, 1.0), (b, a, -1.0)):
                    X = list(E)
                    if shift is not None:
                        X = [x - e for x, e in zip(X, eye[shift])]
                    o = tuple(-x for x in X)  # the face (comp, V - o)
                    if o[comp] == 0 and all(x in (0, 1) for x in o):
                        taps.append((_slot(d, comp, o), sign))
                if taps:
                    out.append((tuple(E), taps))
    return out


# What schwarz_step does with z = mask M^-1 r (a runtime argument: one compiled kernel; the 3D one
# takes ~5 s to compile, the unrolled 144 products of the gather).
START, STEP, APPLY = 0, 1, 2


@ti.kernel
def schwarz_step(d: ti.template(), mode: ti.i32, n: ti.i32, nbr: ti.types.ndarray(),
                 cmap: ti.types.ndarray(), inv: ti.types.ndarray(), mask: ti.types.ndarray(),
                 r: ti.types.ndarray(), x: ti.types.ndarray(), step: ti.types.ndarray(), c1: float, c2: float):
    """z = mask M^-1 r with M^-1 = sum_V R_V^T inv_V R_V (additive Schwarz over vertex patches),
    gathered at each of the n kept positions p from the 2^(d-1) patches V = p + o (o_a = 0) that
    hold its a-face, reading r in the 3^d block around p. ``mode``: START step = x = c2 z (the
    first Chebyshev step from x = 0); STEP step = c1 step + c2 z, x += step; APPLY x = c2 z."""
    for p in range(n):
        near = block(d, nbr, p)
        # r on the 3^d block around p, loaded once before any store
        rv = ti.Vector([0.0] * (d * 3**d))
        for b in ti.static(range(d)):
            for c in ti.static(range(3**d)):
                rv[b * 3**d + c] = r[b, near[c]]
        for a in ti.static(range(d)):
            z = 0.0
            if mask[a, p] != 0:
                for o in ti.static(_corners(d)):
                    if ti.static(o[a] == 0):
                        row = ti.static(_slot(d, a, o))
                        k = cmap[near[ti.static(_code(d, o))]]
                        for b, o2, s in ti.static(_patch_dofs(d)):
                            off = ti.static(_minus(o, o2))
                            z += inv[k, row, s] * rv[ti.static(b * 3**d + _code(d, off))]
                z *= mask[a, p]
            if mode == START:
                step[a, p] = stored(step, c2 * z)
                x[a, p] = stored(x, c2 * z)
            elif mode == STEP:
                s_ = c1 * step[a, p] + c2 * z
                step[a, p] = stored(step, s_)
                x[a, p] = stored(x, x[a, p] + s_)
            else:
                x[a, p] = stored(x, c2 * z)
