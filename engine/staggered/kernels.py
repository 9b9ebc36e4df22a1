"""Taichi kernels of the staggered elasticity operator, its multigrid transfers and vector algebra.

All kernels loop over the kept tiles of a ``TileLayout`` (``coords`` [nt, d], ``tmap``) and are
generic in the dimension ``d`` (a compile-time argument; loops over axes are unrolled, nothing
else is). Per-component arrays are [d, size] (size = (nt + 1) 8^d, the last tile the zero
tile, which no kernel writes). ``full`` [nt] flags tiles whose cell and edge fractions are all 1:
they take the constant-coefficient path and read no fractions.

The operator is applied in two passes: the weighted stresses at cells and edges, then their
discrete divergence at the faces (each a gather, so there are no atomics and no races).
"""

import taichi as ti

B = 8
BITS = 3
PAIRS = {2: ((0, 1),), 3: ((0, 1), (0, 2), (1, 2))}


@ti.func
def unit(d: ti.template(), a: ti.template()):
    return ti.Vector([1 if k == a else 0 for k in range(d)], dt=ti.i32)


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
def near(d: ti.template(), nbr: ti.types.ndarray(), t: ti.i32, c, o) -> ti.i32:
    """Flat position of local coordinates c + o (|o_k| < B) of tile t, through the table of the
    3^d neighbouring tiles (the zero tile where one is not kept): no bounds checks, no tile map."""
    code = 0
    l = 0
    for k in ti.static(range(d)):
        ck = c[k] + o[k]
        code = code * 3 + ((ck + B) >> BITS)
        l = l * B + (ck & (B - 1))
    return nbr[t, code] * (B**d) + l


@ti.kernel
def weighted_stresses(d: ti.template(), tiles: ti.types.ndarray(), nbr: ti.types.ndarray(), full: ti.types.ndarray(),
                      u: ti.types.ndarray(), vc: ti.types.ndarray(), ve: ti.types.ndarray(),
                      lam: float, mu: float, inv_h: float, sc: ti.types.ndarray(), se: ti.types.ndarray()):
    """sc[a] = Vc (2 mu eps_aa + lam tr eps) at cells; se[q] = Ve 2 mu eps_ab at edges of pair q,
    in the tiles ``tiles`` [m]."""
    for i, l in ti.ndrange(tiles.shape[0], B**d):
        t = tiles[i]
        c = local_coords(d, l)
        p = t * (B**d) + l
        eps = ti.Vector([0.0] * d)
        for a in ti.static(range(d)):
            eps[a] = (u[a, near(d, nbr, t, c, unit(d, a))] - u[a, p]) * inv_h
        w = 1.0
        if full[t] == 0:
            w = vc[p]
        tr = eps.sum()
        for a in ti.static(range(d)):
            sc[a, p] = w * (2.0 * mu * eps[a] + lam * tr)
        for q in ti.static(range(len(PAIRS[d]))):
            a, b = ti.static(PAIRS[d][q])
            g = (u[a, p] - u[a, near(d, nbr, t, c, -unit(d, b))]
                 + u[b, p] - u[b, near(d, nbr, t, c, -unit(d, a))]) * inv_h
            wq = 1.0
            if full[t] == 0:
                wq = ve[q, p]
            se[q, p] = wq * mu * g


@ti.kernel
def stress_divergence(d: ti.template(), tiles: ti.types.ndarray(), nbr: ti.types.ndarray(), mask: ti.types.ndarray(),
                      sc: ti.types.ndarray(), se: ti.types.ndarray(), scale: float, x: ti.types.ndarray(),
                      m: ti.types.ndarray(), shift: float, y: ti.types.ndarray()):
    """y = mask (h^{d-1} div(weighted stresses) + shift m x): the operator K (+ shift M) at the
    faces of the tiles ``tiles`` (whose stresses and their neighbours' must be current)."""
    for i, l in ti.ndrange(tiles.shape[0], B**d):
        t = tiles[i]
        c = local_coords(d, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            f = sc[a, near(d, nbr, t, c, -unit(d, a))] - sc[a, p]
            for q in ti.static(range(len(PAIRS[d]))):
                qa, qb = ti.static(PAIRS[d][q])
                if ti.static(qa == a or qb == a):
                    b = ti.static(qb if qa == a else qa)
                    f += se[q, p] - se[q, near(d, nbr, t, c, unit(d, b))]
            if shift != 0.0:  # uniform branch: statics never read the mass and x here
                f += shift * m[a, p] * x[a, p] / scale
            y[a, p] = mask[a, p] * scale * f


@ti.kernel
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
            dinv[a, p] = 0.0
            if mask[a, p] != 0 and diag > 0:
                dinv[a, p] = 1.0 / diag


@ti.kernel
def active_faces(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(),
                 vc: ti.types.ndarray(), active: ti.types.ndarray()):
    """active[a, p] = 1 where a cell on either side of the face holds material."""
    nt = coords.shape[0]
    for t, l in ti.ndrange(nt, B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            active[a, p] = ti.select(vc[p] + vc[address(d, tmap, I - unit(d, a), nt)] > 0, 1, 0)


@ti.kernel
def prune_edges(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(),
                active: ti.types.ndarray(), ve: ti.types.ndarray()):
    """Zero the edge weights whose shear stencil reaches an inactive face: such a face would be
    an unknown held by nothing else, free to cancel the shear (a zero-energy mechanism), so the
    term adds no stiffness and only makes the operator singular."""
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


@ti.kernel
def boundary_band(d: ti.template(), coords: ti.types.ndarray(), tmap: ti.types.ndarray(), vc: ti.types.ndarray(),
                  fixed: ti.types.ndarray(), band: ti.types.ndarray()):
    """band[p] = 1 where a cut cell (0 < vc < 1) or a prescribed DOF (``fixed`` [size]) lies in the
    3^d block around position p."""
    nt = coords.shape[0]
    for t, l in ti.ndrange(nt, B**d):
        I = index_of(d, coords, t, l)
        hit = 0
        for s in range(3**d):
            o = ti.Vector([0] * d, dt=ti.i32)
            code = s
            for k in ti.static(range(d)):
                o[d - 1 - k] = code % 3 - 1
                code //= 3
            q = address(d, tmap, I + o, nt)
            if (vc[q] > 0 and vc[q] < 1) or fixed[q] != 0:
                hit = 1
        band[t * (B**d) + l] = hit


@ti.kernel
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
        vc[p] = c / 2**d
        for a in ti.static(range(d)):
            f = 0.0
            for s in range(2**d):
                o = ti.Vector([(s >> k) & 1 for k in ti.static(range(d))], dt=ti.i32)
                f += fine_vc[address(d, fine_tmap, 2 * J - 2 - unit(d, a) + o, fine_zero)]
            vf[a, p] = f / 2**d
        for q in ti.static(range(len(PAIRS[d]))):
            a, b = ti.static(PAIRS[d][q])
            e = 0.0
            for s in range(2**d):
                o = ti.Vector([(s >> k) & 1 for k in ti.static(range(d))], dt=ti.i32)
                e += fine_vc[address(d, fine_tmap, 2 * J - 2 - unit(d, a) - unit(d, b) + o, fine_zero)]
            ve[q, p] = e / 2**d


@ti.func
def prolongation_weights(d: ti.template(), a: ti.template(), I, corner: ti.i32):
    """Coarse index and weight of corner ``corner`` (bit k: second coarse sample along axis k) of
    the multilinear interpolation of the a-component at fine index I."""
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


@ti.kernel
def prolong_add(d: ti.template(), coords: ti.types.ndarray(), parents: ti.types.ndarray(),
                mask: ti.types.ndarray(), coarse: ti.types.ndarray(), x: ti.types.ndarray()):
    """x += mask P coarse (P: multilinear interpolation of each component on its own faces)."""
    for t, l in ti.ndrange(coords.shape[0], B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            v = 0.0
            for corner in range(2**d):
                J, w = prolongation_weights(d, a, I + 2, corner)
                v += w * coarse[a, parent_address(d, parents, coords, t, J)]
            x[a, p] = x[a, p] + mask[a, p] * v  # a plain store: no atomic, each p has one writer


@ti.kernel
def restrict_add(d: ti.template(), dtype: ti.template(), coords: ti.types.ndarray(), parents: ti.types.ndarray(),
                 zero: ti.i32, fine: ti.types.ndarray(), out: ti.types.ndarray()):
    """out += P^T fine, scattered from the fine DOFs with the prolongation's own weights (so the
    restriction is its exact transpose); nothing lands in the coarse zero tile (``zero``, the
    coarse tile count). ``dtype``: the arrays' float type. Callers zero ``out`` first, mask after."""
    for t, l in ti.ndrange(coords.shape[0], B**d):
        I = index_of(d, coords, t, l)
        p = t * (B**d) + l
        for a in ti.static(range(d)):
            r = fine[a, p]
            if r != 0.0:
                for corner in range(2**d):
                    J, w = prolongation_weights(d, a, I + 2, corner)
                    q = parent_address(d, parents, coords, t, J)
                    if w != 0.0 and q < zero * (B**d):
                        ti.atomic_add(out[a, q], ti.cast(w * r, dtype))


@ti.kernel
def jacobi_update(d: ti.template(), x: ti.types.ndarray(), dinv: ti.types.ndarray(), b: ti.types.ndarray(),
                  y: ti.types.ndarray(), omega: float):
    """x += omega D^-1 (b - y) where y = A x."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            x[a, p] = x[a, p] + omega * dinv[a, p] * (b[a, p] - y[a, p])


@ti.kernel
def chebyshev_step(d: ti.template(), tiles: ti.types.ndarray(), x: ti.types.ndarray(), step: ti.types.ndarray(),
                   dinv: ti.types.ndarray(), b: ti.types.ndarray(), y: ti.types.ndarray(), c1: float, c2: float):
    """step = c1 step + c2 D^-1 (b - y); x += step (one step of the Chebyshev recurrence) in the
    tiles ``tiles``."""
    for i, l in ti.ndrange(tiles.shape[0], B**d):
        p = tiles[i] * (B**d) + l
        for a in ti.static(range(d)):
            s = c1 * step[a, p] + c2 * dinv[a, p] * (b[a, p] - y[a, p])
            step[a, p] = s
            x[a, p] = x[a, p] + s


@ti.kernel
def scaled(d: ti.template(), x: ti.types.ndarray(), s: ti.types.ndarray(), omega: float, out: ti.types.ndarray()):
    """out = omega s x (elementwise)."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            out[a, p] = omega * s[a, p] * x[a, p]


@ti.kernel
def residual(d: ti.template(), b: ti.types.ndarray(), y: ti.types.ndarray(), r: ti.types.ndarray()):
    """r = b - y."""
    for p in range(b.shape[1]):
        for a in ti.static(range(d)):
            r[a, p] = b[a, p] - y[a, p]


@ti.kernel
def dot(d: ti.template(), x: ti.types.ndarray(), y: ti.types.ndarray()) -> ti.f64:
    s = ti.cast(0.0, ti.f64)
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            s += ti.cast(x[a, p], ti.f64) * ti.cast(y[a, p], ti.f64)
    return s


@ti.kernel
def axpy(d: ti.template(), alpha: ti.f64, x: ti.types.ndarray(), y: ti.types.ndarray()):
    """y += alpha x."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            y[a, p] = y[a, p] + alpha * x[a, p]


@ti.kernel
def xpby(d: ti.template(), x: ti.types.ndarray(), beta: ti.f64, y: ti.types.ndarray()):
    """y = x + beta y."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            y[a, p] = x[a, p] + beta * y[a, p]


@ti.kernel
def copy(d: ti.template(), src: ti.types.ndarray(), dst: ti.types.ndarray()):
    for p in range(src.shape[1]):
        for a in ti.static(range(d)):
            dst[a, p] = src[a, p]


@ti.kernel
def fill(d: ti.template(), x: ti.types.ndarray(), value: float):
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            x[a, p] = value


@ti.kernel
def multiply(d: ti.template(), x: ti.types.ndarray(), m: ti.types.ndarray()):
    """x *= m (elementwise)."""
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            x[a, p] = x[a, p] * m[a, p]


@ti.kernel
def count_nonfinite(d: ti.template(), x: ti.types.ndarray()) -> ti.i32:
    bad = 0
    for p in range(x.shape[1]):
        for a in ti.static(range(d)):
            if ti.math.isnan(x[a, p]) or ti.math.isinf(x[a, p]):
                bad += 1
    return bad
