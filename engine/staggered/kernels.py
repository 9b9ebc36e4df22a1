"""Taichi kernels of the staggered elasticity operator, its multigrid transfers and vector algebra.

All kernels loop over the kept tiles of a ``TileLayout`` (``coords`` [nt, d], ``tmap``) and are
generic in the dimension ``d`` (a compile-time argument; loops over axes are unrolled, nothing
else is). Per-component arrays are [d, size] (size = (nt + 1) 8^d, the last tile the zero
tile, which no kernel writes). ``full`` [nt] flags tiles whose cell and edge fractions are all 1:
they take the constant-coefficient path and read no fractions.

The operator is applied in two passes: the weighted stresses at cells and edges, then their
discrete divergence at the faces (each a gather, so there are no atomics and no races). Both
passes run either over every kept position or over a sorted list of flat positions (a *part*:
the multigrid's boundary band is a few DOFs thick, far thinner than its tiles).

Arithmetic is f64 whatever the arrays hold; stores go through :func:`stored`, so one kernel
serves f64 and f32 arrays (``solver.precision`` f32) without a precision warning per store.
"""

import itertools

import gstaichi as ti

from .. import runtime  # noqa: F401 - first: its Taichi patches make the decorators below quick
from ..grid import axis_pairs

B = 8
BITS = 3
PAIRS = {d: axis_pairs(d) for d in (2, 3)}  # compile-time tuples for ti.static


@ti.func
def unit(d: ti.template(), a: ti.template()):
    return ti.Vector([1 if k == a else 0 for k in range(d)], dt=ti.i32)


@ti.func
def stored(y: ti.template(), v):
    """v in the element type of array y: an f32 array takes f64 results without Taichi's
    precision warning at every store."""
    return ti.cast(v, y.get_type().element_type)


@ti.func
def position(listed: ti.template(), pos: ti.types.ndarray(), i: ti.i32) -> ti.i32:
    """The i-th flat position of a part: ``pos[i]`` for a listed part, else i itself (every kept
    position in order)."""
    p = i
    if ti.static(listed):
        p = pos[i]
    return p


@ti.func
def index_of(d: ti.template(), coords: ti.types.ndarray(), t: ti.i32, l: ti.i32):
    """Global index of local position l in kept tile t."""
    I = ti.Vector([0] * d, dt=ti.i32)
    for k in ti.static(range(d)):
        I[k] = coords[t, k] * B + ((l >> (BITS * (d - 1 - k))) & (B - 1))
    return I


@ti.func
def address(d: ti.template(), tmap: ti.types.ndarray(), I, zero: ti.i32) -> ti.i32:
    """Flat position of global index I; a position in the zero tile when its tile is not kept."""
    t = zero
    inside = True
    T = ti.Vector([0] * d, dt=ti.i32)
    for k in ti.static(range(d)):
        T[k] = I[k] >> BITS
        if I[k] < 0 or T[k] >= tmap.shape[k]:
            inside = False
    if inside:
        t = tmap[T]
    l = 0
    for k in ti.static(range(d)):
        l = l * B + (I[k] & (B - 1))
    return t * (B**d) + l


@ti.func
def local_coords(d: ti.template(), l: ti.i32):
    c = ti.Vector([0] * d, dt=ti.i32)
    for k in ti.static(range(d)):
        c[k] = (l >> (BITS * (d - 1 - k))) & (B - 1)
    return c


@ti.func
def face_neighbours(d: ti.template(), nbr: ti.types.ndarray(), t: ti.i32, p: ti.i32, c):
    """Flat positions of p + e_k and p - e_k for every axis k (two d-vectors), p being local
    coordinates c of tile t: within the tile a fixed stride, across its side through ``nbr``.
    Computed once per position before any store: per-access lookups (``near``) were repeated
    for every read, and the compiler could not merge them across the stores (20-25% slower)."""
    up = ti.Vector([0] * d, dt=ti.i32)
    down = ti.Vector([0] * d, dt=ti.i32)
    for k in ti.static(range(d)):
        stride = ti.static(B ** (d - 1 - k))
        up[k] = p + stride
        if c[k] == B - 1:
            up[k] = nbr[t, ti.static((3**d - 1) // 2 + 3 ** (d - 1 - k))] * (B**d) + (p & (B**d - 1)) - (B - 1) * stride
        down[k] = p - stride
        if c[k] == 0:
            down[k] = nbr[t, ti.static((3**d - 1) // 2 - 3 ** (d - 1 - k))] * (B**d) + (p & (B**d - 1)) + (B - 1) * stride
    return up, down


@ti.kernel(fastcache=True)
def weighted_stresses(d: ti.template(), listed: ti.template(), pos: ti.types.ndarray(), n: ti.i32,
                      nbr: ti.types.ndarray(), full: ti.types.ndarray(), u: ti.types.ndarray(),
                      vc: ti.types.ndarray(), ve: ti.types.ndarray(), lam: float, mu: float, inv_h: float,
                      sc: ti.types.ndarray(), se: ti.types.ndarray()):
    """sc[a] = Vc (2 mu eps_aa + lam tr eps) at cells; se[q] = Ve 2 mu eps_ab at edges of pair q,
    at the n positions of a part (see :func:`position`)."""
    for i in range(n):
        p = position(listed, pos, i)
        t = p >> (BITS * d)
        up, down = face_neighbours(d, nbr, t, p, local_coords(d, p & (B**d - 1)))
        here = ti.Vector([0.0] * d)
        for a in ti.static(range(d)):
            here[a] = u[a, p]
        eps = ti.Vector([0.0] * d)
        for a in ti.static(range(d)):
            eps[a] = (u[a, up[a]] - here[a]) * inv_h
        g = ti.Vector([0.0] * ti.static(len(PAIRS[d])))
        for q in ti.static(range(len(PAIRS[d]))):
            a, b = ti.static(PAIRS[d][q])
            g[q] = (here[a] - u[a, down[b]] + here[b] - u[b, down[a]]) * inv_h
        w = 1.0
        if full[t] == 0:
            w = vc[p]
        tr = eps.sum()
        for a in ti.static(range(d)):
            sc[a, p] = stored(sc, w * (2.0 * mu * eps[a] + lam * tr))
        for q in ti.static(range(len(PAIRS[d]))):
            wq = 1.0
            if full[t] == 0:
                wq = ve[q, p]
            se[q, p] = stored(se, wq * mu * g[q])


# What stress_divergence does with A x at a face (compile-time modes).
APPLY, RESIDUAL, CHEBYSHEV = 0, 1, 2


@ti.kernel(fastcache=True)
def stress_divergence(d: ti.template(), mode: ti.template(), listed: ti.template(), pos: ti.types.ndarray(),
                      n: ti.i32, nbr: ti.types.ndarray(), mask: ti.types.ndarray(), sc: ti.types.ndarray(),
                      se: ti.types.ndarray(), scale: float, x: ti.types.ndarray(), m: ti.types.ndarray(),
                      shift: float, b: ti.types.ndarray(), dinv: ti.types.ndarray(), step: ti.types.ndarray(),
                      c1: float, c2: float, y: ti.types.ndarray()):
    """A x = mask (h^{d-1} div(weighted stresses) + shift m x), the operator K (+ shift M), at the
    faces of the n positions of a part (whose stresses and their neighbours' must be current).
    ``mode``: APPLY y = A x; RESIDUAL y = b - A x; CHEBYSHEV step = c1 step + c2 dinv (b - A x),
    x += step (one step of the Chebyshev recurrence; c1 = 0 never reads step). Fusing these into
    the divergence saves writing and re-reading A x, and x is only read at the face itself (the
    stresses were computed before), so updating it in place is safe. Arrays a mode does not use may
    be any array of the right rank. The surface terms' S x, on their few DOFs, comes after: :func:`surface_add`."""
    for i in range(n):
        p = position(listed, pos, i)
        t = p >> (BITS * d)
        up, down = face_neighbours(d, nbr, t, p, local_coords(d, p & (B**d - 1)))
        div = ti.Vector([0.0] * d)
        for a in ti.static(range(d)):
            div[a] = sc[a, down[a]] - sc[a, p]
        for q in ti.static(range(len(PAIRS[d]))):
            qa, qb = ti.static(PAIRS[d][q])
            here = se[q, p]
            div[qa] += here - se[q, up[qb]]
            div[qb] += here - se[q, up[qa]]
        for a in ti.static(range(d)):
            f = div[a]
            if shift != 0.0:  # uniform branch: statics never read the mass and x here
                f += shift * m[a, p] * x[a, p] / scale
            if ti.static(mode == APPLY):
                y[a, p] = stored(y, mask[a, p] * scale * f)
            elif ti.static(mode == RESIDUAL):
                y[a, p] = stored(y, b[a, p] - mask[a, p] * scale * f)
            else:
                # dinv vanishes off the unknowns, so the mask is not needed: step stays 0 there
                s = c2 * dinv[a, p] * (b[a, p] - scale * f)
                if c1 != 0.0:
                    s += c1 * step[a, p]
                step[a, p] = stored(step, s)
                x[a, p] = stored(x, x[a, p] + s)


@ti.kernel(fastcache=True)
def inverse_diagonal(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(),
                     mask: ti.types.ndarray(), vc: ti.types.ndarray(), ve: ti.types.ndarray(),
                     lam: float, mu: float, scale: float, m: ti.types.ndarray(), shift: float,
                     dinv: ti.types.ndarray()):
    """dinv = mask / diag(K + shift M) (zero where masked); scale = h^{d-2}."""
    nt = coords.shape[0]
    for t, l in ti.ndrange(nt, B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            g = (2.0 * mu + lam) * (vc[p] + vc[address(d, tmap, I - unit(d, a), nt)])
            for q in ti.static(range(len(PAIRS[d]))):
                qa, qb = ti.static(PAIRS[d][q])
                if ti.static(qa == a or qb == a):
                    b = ti.static(qb if qa == a else qa)
                    g += mu * (ve[q, p] + ve[q, address(d, tmap, I + unit(d, b), nt)])
            diag = scale * g + shift * m[a, p]
            inv = 0.0
            if mask[a, p] != 0 and diag > 0:
                inv = 1.0 / diag
            dinv[a, p] = stored(dinv, inv)


@ti.kernel(fastcache=True)
def active_faces(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(),
                 vc: ti.types.ndarray(), active: ti.types.ndarray()):
    """active[a, p] = 1 where a cell on either side of the face holds material."""
    nt = coords.shape[0]
    for t, l in ti.ndrange(nt, B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            active[a, p] = ti.select(vc[p] + vc[address(d, tmap, I - unit(d, a), nt)] > 0, 1, 0)


@ti.kernel(fastcache=True)
def prune_edges(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(),
                active: ti.types.ndarray(), ve: ti.types.ndarray()):
    """Zero the edge weights whose shear stencil reaches an inactive face: such a face would be
    an unknown held by nothing else, free to cancel the shear (a zero-energy mechanism), so the
    term adds no stiffness and only makes the operator singular. A wall thinner than a cell inside
    one cell layer loses every shear term of its transverse samples this way and is then held by
    nothing across: ``operator.unheld_groups`` finds those motions and the setup names them."""
    nt = coords.shape[0]
    for t, l in ti.ndrange(nt, B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for q in ti.static(range(len(PAIRS[d]))):
            a, b = ti.static(PAIRS[d][q])
            n = (active[a, p] + active[a, address(d, tmap, I - unit(d, b), nt)]
                 + active[b, p] + active[b, address(d, tmap, I - unit(d, a), nt)])
            if n < 4:
                ve[q, p] = 0.0


@ti.kernel(fastcache=True)
def coarse_fractions(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(),
                     fine_tmap: ti.types.ndarray(), fine_zero: ti.i32, fine_vc: ti.types.ndarray(),
                     vc: ti.types.ndarray(), ve: ti.types.ndarray(), vf: ti.types.ndarray()):
    """Fractions of the 2h control volumes: every one is the union of 2^d fine cells. Coarse cell
    J covers fine cells 2J - 2 + {0, 1}^d: one more cell of padding per level keeps material off
    the low boundary, where the strain stencils would leave the grid."""
    nt = coords.shape[0]
    for t, l in ti.ndrange(nt, B**d):
        J = index_of(d, coords, t, l)
        p = t * (B**d) + l
        c = 0.0
        for s in range(2**d):
            o = ti.Vector([(s >> k) & 1 for k in ti.static(range(d))], dt=ti.i32)
            c += fine_vc[address(d, fine_tmap, 2 * J - 2 + o, fine_zero)]
        vc[p] = stored(vc, c / 2**d)
        for a in ti.static(range(d)):
            f = 0.0
            for s in range(2**d):
                o = ti.Vector([(s >> k) & 1 for k in ti.static(range(d))], dt=ti.i32)
                f += fine_vc[address(d, fine_tmap, 2 * J - 2 - unit(d, a) + o, fine_zero)]
            vf[a, p] = stored(vf, f / 2**d)
        for q in ti.static(range(len(PAIRS[d]))):
            a, b = ti.static(PAIRS[d][q])
            e = 0.0
            for s in range(2**d):
                o = ti.Vector([(s >> k) & 1 for k in ti.static(range(d))], dt=ti.i32)
                e += fine_vc[address(d, fine_tmap, 2 * J - 2 - unit(d, a) - unit(d, b) + o, fine_zero)]
            ve[q, p] = stored(ve, e / 2**d)


# Transfers between levels (compile-time kinds). LINEAR: multilinear interpolation of each component
# on its own faces. FACE: linear along the component's axis, constant across it (the lowest-order
# Raviart-Thomas interpolation): a fine face inside a coarse face takes its value, one inside a
# coarse cell the mean of the cell's two faces, so the divergence of the prolonged field in every
# fine cell is the divergence of its coarse cell (what the near-incompressible smoothing needs).
LINEAR, FACE = 0, 1


def _corner_used(kind: int, a: int, corner: int, d: int) -> bool:
    """Whether ``corner`` (bit k: second coarse sample along axis k) of the a-component's
    interpolation can carry weight: FACE reads one coarse sample across the component's axis."""
    return kind == LINEAR or all((corner >> k) & 1 == 0 for k in range(d) if k != a)


@ti.func
def prolongation_weights(d: ti.template(), a: ti.template(), I, corner: ti.template(), kind: ti.template()):
    """Coarse index and weight of corner ``corner`` (bit k: second coarse sample along axis k) of
    the interpolation ``kind`` of the a-component at fine index I."""
    J = ti.Vector([0] * d, dt=ti.i32)
    w = 1.0
    for k in ti.static(range(d)):
        second = (corner >> k) & 1
        if ti.static(k == a):
            # faces coincide at even fine indices, odd ones sit halfway
            J[k] = (I[k] >> 1) + second
            if I[k] & 1 == 0:
                w *= 1.0 - second
            else:
                w *= 0.5
        elif ti.static(kind == FACE):
            J[k] = I[k] >> 1  # the coarse face (cell) the fine sample lies in
        else:
            # samples sit at cell centres: fine 2j -> 3/4 coarse j, 1/4 coarse j-1; 2j+1 -> j, j+1
            odd = I[k] & 1
            J[k] = (I[k] >> 1) + second * (2 * odd - 1)
            w *= 0.75 - 0.5 * second
    return J, w


@ti.func
def parent_address(d: ti.template(), parents: ti.types.ndarray(), coords: ti.types.ndarray(), t: ti.i32, J) -> ti.i32:
    """Flat position of coarse index J, seen from fine tile t: its coarse tile is one of the 3^d
    around the tile's parent (``parents`` [nt, 3^d], the coarse zero tile where not kept)."""
    code = 0
    l = 0
    for k in ti.static(range(d)):
        code = code * 3 + (J[k] >> BITS) - (coords[t, k] >> 1) + 1
        l = l * B + (J[k] & (B - 1))
    return parents[t, code] * (B**d) + l


@ti.kernel(fastcache=True)
def prolong_add(d: ti.template(), kind: ti.template(), coords: ti.types.ndarray(), parents: ti.types.ndarray(),
                mask: ti.types.ndarray(), coarse: ti.types.ndarray(), x: ti.types.ndarray()):
    """x += mask P coarse (P: the interpolation ``kind``, LINEAR or FACE, of each component on its
    own faces)."""
    for t, l in ti.ndrange(coords.shape[0], B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            v = 0.0
            for corner in ti.static(range(2**d)):  # unrolled: 25% faster than a runtime loop
                if ti.static(_corner_used(kind, a, corner, d)):
                    J, w = prolongation_weights(d, a, I + 2, corner, kind)
                    v += w * coarse[a, parent_address(d, parents, coords, t, J)]
            x[a, p] = stored(x, x[a, p] + mask[a, p] * v)  # a plain store: no atomic, each p has one writer


@ti.kernel(fastcache=True)
def restrict_add(d: ti.template(), kind: ti.template(), dtype: ti.template(), coords: ti.types.ndarray(),
                 parents: ti.types.ndarray(), zero: ti.i32, fine: ti.types.ndarray(), out: ti.types.ndarray()):
    """out += P^T fine, scattered from the fine DOFs with the prolongation's own weights (so the
    restriction is its exact transpose); nothing lands in the coarse zero tile (``zero``, the
    coarse tile count). ``dtype``: the arrays' float type. Callers zero ``out`` first, mask after."""
    for t, l in ti.ndrange(coords.shape[0], B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            r = fine[a, p]
            if r != 0.0:
                for corner in ti.static(range(2**d)):
                    if ti.static(_corner_used(kind, a, corner, d)):
                        J, w = prolongation_weights(d, a, I + 2, corner, kind)
                        q = parent_address(d, parents, coords, t, J)
                        if w != 0.0 and q < zero * (B**d):
                            ti.atomic_add(out[a, q], ti.cast(w * r, dtype))


def _across(kind: int) -> range:
    """Offsets g across the component's axis that a coarse DOF collects (see :func:`_offsets`)."""
    return range(4) if kind == LINEAR else range(1, 3)


def _offsets(d: int, a: int, kind: int) -> list[tuple[int, ...]]:
    """Offsets g (per axis, of fine I = 2 J - 3 + g) of the fine DOFs that coarse DOF J of
    component a collects, axes 1..d-1: g in {0, 1, 2} along the component's axis; across it
    {0..3} (LINEAR) or {1, 2} (FACE)."""
    return list(itertools.product(*[range(3) if k == a else _across(kind) for k in range(1, d)]))


def _restriction_weight(a: int, g: tuple[int, ...], kind: int) -> float:
    """Interpolation weight of the fine DOF at offsets g (one per axis, see :func:`restrict`) for
    component a: the product of 1/2, 1, 1/2 along the component's axis and, across it, 1/4, 3/4,
    3/4, 1/4 (LINEAR) or 1 (FACE)."""
    w = 1.0
    for k, gk in enumerate(g):
        if k == a:
            w *= 1.0 if gk == 1 else 0.5
        elif kind == LINEAR:
            w *= 0.75 if gk in (1, 2) else 0.25
    return w


@ti.kernel(fastcache=True)
def restrict(d: ti.template(), kind: ti.template(), coords: ti.types.ndarray(), children: ti.types.ndarray(),
             mask: ti.types.ndarray(), fine: ti.types.ndarray(), out: ti.types.ndarray()):
    """out = mask P^T fine at every kept coarse position (``coords`` the coarse tiles; ``children``
    [nt, 3^d] the fine tiles around 2 T, see ``TileLayout.children``), P the interpolation ``kind``.
    A gather with the weights of :func:`prolongation_weights` read backwards: coarse J collects
    fine I + 2 = 2 J + o with o in {-1, 0, 1} (weights 1/2, 1, 1/2) along the component's axis and,
    across it, o in {-1, 0, 1, 2} (1/4, 3/4, 3/4, 1/4; LINEAR) or {0, 1} (1; FACE). The scatter
    (:func:`restrict_add`) needs an atomic per fine DOF and corner and was as slow as an operator
    apply; this is 4-5x faster. The per-axis address parts
    are computed once per position; the taps are unrolled over the static offsets (a runtime loop
    over them was 4x slower: the address parts were recomputed in it)."""
    for t, l in ti.ndrange(coords.shape[0], B**d):
        J = index_of(d, coords, t, l)
        p = t * (B**d) + l
        # per axis k and offset g: the tile-code and local parts of the fine address
        codes = ti.Matrix([[0] * 4 for _ in ti.static(range(d))], dt=ti.i32)
        locs = ti.Matrix([[0] * 4 for _ in ti.static(range(d))], dt=ti.i32)
        for k in ti.static(range(d)):
            for g in ti.static(range(4)):
                I = 2 * J[k] - 3 + g
                codes[k, g] = ((I >> BITS) - 2 * coords[t, k] + 1) * (3 ** (d - 1 - k))
                locs[k, g] = (I & (B - 1)) * (B ** (d - 1 - k))
        for a in ti.static(range(d)):
            v = 0.0
            for g0 in ti.static(range(3) if a == 0 else _across(kind)):
                for rest in ti.static(_offsets(d, a, kind)):
                    code = codes[0, g0]
                    loc = locs[0, g0]
                    for k in ti.static(range(1, d)):
                        code += codes[k, rest[k - 1]]
                        loc += locs[k, rest[k - 1]]
                    w = ti.static(_restriction_weight(a, (g0,) + rest, kind))
                    v += w * fine[a, children[t, code] * (B**d) + loc]
            out[a, p] = stored(out, mask[a, p] * v)


@ti.kernel(fastcache=True)
def chebyshev_start(d: ti.template(), x: ti.types.ndarray(), step: ti.types.ndarray(), dinv: ti.types.ndarray(),
                    b: ti.types.ndarray(), c: float):
    """step = x = c D^-1 b: the first Chebyshev step from x = 0 (needs no A x)."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            s = c * dinv[a, p] * b[a, p]
            step[a, p] = stored(step, s)
            x[a, p] = stored(x, s)


@ti.kernel(fastcache=True)
def random_fill(d: ti.template(), x: ti.types.ndarray(), m: ti.types.ndarray(), seed: ti.u32):
    """x = m * (a hash of (component, position, seed) in [0, 1)): a reproducible random vector made
    where it lives (the smoothing bound's Lanczos start), independent of threads and of the backend."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            k = ti.cast(p, ti.u32) * ti.u32(d) + ti.u32(a) + seed * ti.u32(0x9E3779B9)
            k ^= k >> 16
            k *= ti.u32(0x7FEB352D)
            k ^= k >> 15
            k *= ti.u32(0x846CA68B)
            k ^= k >> 16
            x[a, p] = stored(x, m[a, p] * (ti.cast(k, ti.f64) / 4294967296.0))


@ti.kernel(fastcache=True)
def scaled(d: ti.template(), x: ti.types.ndarray(), s: ti.types.ndarray(), omega: float, out: ti.types.ndarray()):
    """out = omega s x (elementwise)."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            out[a, p] = stored(out, omega * s[a, p] * x[a, p])


@ti.kernel(fastcache=True)
def dot(d: ti.template(), x: ti.types.ndarray(), y: ti.types.ndarray()) -> ti.f64:
    s = ti.cast(0.0, ti.f64)
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            s += ti.cast(x[a, p], ti.f64) * ti.cast(y[a, p], ti.f64)
    return s


@ti.kernel(fastcache=True)
def axpy(d: ti.template(), alpha: ti.f64, x: ti.types.ndarray(), y: ti.types.ndarray()):
    """y += alpha x."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            y[a, p] = stored(y, y[a, p] + alpha * x[a, p])


@ti.kernel(fastcache=True)
def xpby(d: ti.template(), x: ti.types.ndarray(), beta: ti.f64, y: ti.types.ndarray()):
    """y = x + beta y."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            y[a, p] = stored(y, x[a, p] + beta * y[a, p])


@ti.kernel(fastcache=True)
def copy(d: ti.template(), src: ti.types.ndarray(), dst: ti.types.ndarray()):
    for p in range(src.shape[1]):
        for a in ti.static(range(d)):
            dst[a, p] = stored(dst, src[a, p])


@ti.kernel(fastcache=True)
def fill(d: ti.template(), x: ti.types.ndarray(), value: float):
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            x[a, p] = stored(x, value)


@ti.kernel(fastcache=True)
def count_nonfinite(d: ti.template(), x: ti.types.ndarray()) -> ti.i32:
    bad = 0
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            if ti.math.isnan(x[a, p]) or ti.math.isinf(x[a, p]):
                bad += 1
    return bad


@ti.kernel(fastcache=True)
def gather(x: ti.types.ndarray(), comp: ti.types.ndarray(), pos: ti.types.ndarray(), z: ti.types.ndarray()):
    """z[k] = x[comp[k], pos[k]]: the DOFs a surface operator touches, in its compact order."""
    for k in range(comp.shape[0]):
        z[k] = x[comp[k], pos[k]]


@ti.kernel(fastcache=True)
def csr_apply(indptr: ti.types.ndarray(), cols: ti.types.ndarray(), vals: ti.types.ndarray(),
              src: ti.types.ndarray(), dst: ti.types.ndarray(), offset: ti.i32):
    """dst[offset + i] = sum_k vals[k] src[cols[k]] over row i of a CSR matrix (a gather: no atomics;
    src and dst may be one array when the rows written are not among the columns read)."""
    for i in range(indptr.shape[0] - 1):
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            acc += vals[k] * src[cols[k]]
        dst[offset + i] = acc


@ti.kernel(fastcache=True)
def segment_products(start: ti.types.ndarray(), w: ti.types.ndarray(), a: ti.types.ndarray(), b: ti.types.ndarray(),
                     out: ti.types.ndarray()):
    """out[s, i, j] = sum_t w[t] a[t, i] b[t, j] over the rows t of segment s (start[s] <= t <
    start[s + 1]; rows sorted by segment), in row order: per-cell sums of the surface operator's
    point products (``nitsche.py``), one thread per segment (no atomics: the same sums every run)."""
    for s in range(out.shape[0]):
        for i, j in ti.ndrange(a.shape[1], b.shape[1]):
            acc = 0.0
            for t in range(start[s], start[s + 1]):
                acc += w[t] * a[t, i] * b[t, j]
            out[s, i, j] = acc


@ti.kernel(fastcache=True)
def surface_add(mode: ti.template(), slots: ti.types.ndarray(), n: ti.i32, comp: ti.types.ndarray(),
                pos: ti.types.ndarray(), sx: ti.types.ndarray(), mask: ti.types.ndarray(), dinv: ti.types.ndarray(),
                c2: float, step: ti.types.ndarray(), x: ti.types.ndarray(), y: ti.types.ndarray()):
    """What S x (``sx`` [k], at the surface DOFs comp[k], pos[k]) adds to A x in each mode of
    :func:`stress_divergence`, after it, at the surface DOFs ``slots[:n]`` (those of the part it
    ran over): APPLY y += mask sx, RESIDUAL y -= mask sx, CHEBYSHEV step and x -= c2 dinv sx. A
    pass over the few surface DOFs instead of a full [d, size] array of S x read by the divergence
    (10 bytes per unknown on the 256^3 shell); each DOF once: no races."""
    for i in range(n):
        k = slots[i]
        a, p = comp[k], pos[k]
        v = sx[k]
        if ti.static(mode == APPLY):
            y[a, p] = stored(y, y[a, p] + mask[a, p] * v)
        elif ti.static(mode == RESIDUAL):
            y[a, p] = stored(y, y[a, p] - mask[a, p] * v)
        else:
            dv = c2 * dinv[a, p] * v
            step[a, p] = stored(step, step[a, p] - dv)
            x[a, p] = stored(x, x[a, p] - dv)
