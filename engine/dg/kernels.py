"""Taichi kernels of the DG method: elastic element, interface and Nitsche blocks, warping.

Inputs are scalar integrals of basis products already reduced from moments (``assembly``);
these kernels apply the material law and the flux structure to them. A block of an element
pair is [3 nb, 3 nb] with rows (component p, basis I) at p * nb + I. Loops over the three
components are unrolled (``ti.static``), loops over basis functions are not (unrolling them as
well made the kernels compile for minutes). All arrays are float64 whatever the runtime's default.
"""

import gstaichi as ti

from .. import runtime  # noqa: F401 - first: its Taichi patches make the decorators below quick

F64 = ti.f64
ND3 = ti.types.ndarray(dtype=F64, ndim=3)
ND4 = ti.types.ndarray(dtype=F64, ndim=4)
ND5 = ti.types.ndarray(dtype=F64, ndim=5)
ND6 = ti.types.ndarray(dtype=F64, ndim=6)
ND1 = ti.types.ndarray(dtype=F64, ndim=1)
NI1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
NL1 = ti.types.ndarray(dtype=ti.i64, ndim=1)
ND2 = ti.types.ndarray(dtype=F64, ndim=2)


@ti.func
def delta(p, q) -> F64:
    return 1.0 if p == q else 0.0


@ti.kernel(fastcache=True)
def element_blocks(D: ND5, mu: F64, lam: F64, out: ND3):
    """out[b] = int_K eps(v) : C : eps(u) from D[b, a, c, I, J] = int_K d_a psi_I d_c psi_J dV.

    Entry ((p, I), (q, J)) = mu delta_pq sum_a D_aa + mu D_qp + lam D_pq.
    """
    nb = D.shape[3]
    for b, I, J in ti.ndrange(D.shape[0], nb, nb):
        trace = D[b, 0, 0, I, J] + D[b, 1, 1, I, J] + D[b, 2, 2, I, J]
        for p in ti.static(range(3)):
            for q in ti.static(range(3)):
                out[b, p * nb + I, q * nb + J] = (mu * delta(p, q) * trace + mu * D[b, q, p, I, J]
                                                  + lam * D[b, p, q, I, J])


@ti.func
def traction(N: ti.template(), b, X, Y, I, J, p, q, axis, mu: F64, lam: F64) -> F64:
    """int_f psi^X_I (sigma(psi^Y_J e_q) e_axis)_p from N[b, X, Y, a, I, J] = int_f psi^X_I d_a psi^Y_J."""
    return (mu * (delta(p, q) * N[b, X, Y, axis, I, J] + delta(q, axis) * N[b, X, Y, p, I, J])
            + lam * delta(p, axis) * N[b, X, Y, q, I, J])


@ti.kernel(fastcache=True)
def face_blocks(M: ND5, P: ND5, N: ND6, axis: NI1, eta: ND1, mu: F64, lam: F64, w_pen: F64, w_minus: F64,
                w_plus: F64, out: ND4):
    """Interface blocks out[f, c] of the side pairs (X, Y) = (0, 0), (1, 1), (0, 1) for c = 0, 1, 2 (X: test
    side, Y: trial side; 0 = minus, 1 = plus); the pair (1, 0) is the transpose of (0, 1), which the
    assembly mirrors.

    Symmetric interior penalty (Kaufmann et al. eq. 21) with normal n = e_axis, jump [u] = (u- - u+) x n:
    - consistency * (int [v] : {sigma(u)} + int [u] : {sigma(v)}) + penalty, the penalty
    eta_f int (mu ([u].[v] + [u]_n [v]_n) + lam Pi[u]_n Pi[v]_n): the shear part of C : (j x n) : (w x n)
    on the whole jump, the volumetric part only on the normal jump's projection Pi onto P_{k-1}(f),
    which is all the consistency term lam {div u} [v]_n sees (div u has degree k - 1). Penalising the
    whole normal jump with lam forces normal continuity as lam grows, and P_k fields with continuous
    normal traces cannot follow a divergence-free field on a hex grid: locking (docs/design-notes.md).
    Weights pick parts: w_pen the penalty, w_minus / w_plus the consistency terms whose stress is
    taken on the minus / plus side (warping rotates them with that side's rotation, section 6.1);
    (1, 1, 1) is IP, (1, 0, 0) Babuska-Zlamal. M[f, X, Y, I, J] = int_f psi^X_I psi^Y_J,
    P[f, X, Y, I, J] = int_f Pi psi^X_I Pi psi^Y_J.
    """
    nb = M.shape[3]
    for f, c in ti.ndrange(M.shape[0], 3):  # a plain inner loop: parallel over entries took 1.5x as long
        X = 1 if c == 1 else 0
        Y = 0 if c == 0 else 1
        sx = 1.0 - 2.0 * X
        sy = 1.0 - 2.0 * Y
        wx = w_minus if X == 0 else w_plus
        wy = w_minus if Y == 0 else w_plus
        ax = axis[f]
        for I in range(nb):
            for J in range(nb):
                for p in ti.static(range(3)):
                    for q in ti.static(range(3)):
                        pen = sx * sy * eta[f] * (mu * M[f, X, Y, I, J] * (delta(p, q) + delta(p, ax) * delta(q, ax))
                                                  + lam * P[f, X, Y, I, J] * delta(p, ax) * delta(q, ax))
                        cons = -0.5 * (wy * sx * traction(N, f, X, Y, I, J, p, q, ax, mu, lam)
                                       + wx * sy * traction(N, f, Y, X, J, I, q, p, ax, mu, lam))
                        out[f, c, p * nb + I, q * nb + J] = w_pen * pen + cons


@ti.kernel(fastcache=True)
def nitsche_blocks(M: ND5, P: ND5, Nn: ND5, mask: ND2, eta: ND1, mu: F64, lam: F64, w_pen: F64, w_cons: F64,
                   out: ND3):
    """Weak Dirichlet blocks on a surface patch (u- = g, v- = 0, sigma- = sigma+; eq. 21).

    M[b, a, c, I, J] = int psi_I psi_J n_a n_c; the mass int psi_I psi_J is its trace over a = c
    (n is a unit vector). P[b, a, c, I, J] = int Pi(psi_I n_a) Pi(psi_J n_c), Pi the projection onto
    the traces of P_{k-1}(K): the volumetric penalty's part, as on interfaces (``face_blocks``).
    w_pen / w_cons weigh the penalty / consistency parts (warping rotates only the latter).
    Nn[b, a, c, I, J] = int psi_I d_a psi_J n_c. mask[b, p] = 1 for prescribed components.
    Entry ((p, I), (q, J)) = -m_p t(I, J; p, q) - m_q t(J, I; q, p) + eta_b m_p m_q
    (mu (delta_pq int psi_I psi_J + M_pq) + lam P_pq), with t the traction of (psi_J e_q) against psi_I.
    """
    nb = M.shape[3]
    for b, I, J in ti.ndrange(M.shape[0], nb, nb):
        mass = M[b, 0, 0, I, J] + M[b, 1, 1, I, J] + M[b, 2, 2, I, J]
        divIJ = Nn[b, 0, 0, I, J] + Nn[b, 1, 1, I, J] + Nn[b, 2, 2, I, J]
        divJI = Nn[b, 0, 0, J, I] + Nn[b, 1, 1, J, I] + Nn[b, 2, 2, J, I]
        for p in ti.static(range(3)):
            for q in ti.static(range(3)):
                t_ij = mu * (delta(p, q) * divIJ + Nn[b, p, q, I, J]) + lam * Nn[b, q, p, I, J]
                t_ji = mu * (delta(p, q) * divJI + Nn[b, q, p, J, I]) + lam * Nn[b, p, q, J, I]
                pen = eta[b] * (mu * (delta(p, q) * mass + M[b, p, q, I, J]) + lam * P[b, p, q, I, J])
                out[b, p * nb + I, q * nb + J] = (w_cons * (-mask[b, p] * t_ij - mask[b, q] * t_ji)
                                                  + w_pen * mask[b, p] * mask[b, q] * pen)


@ti.kernel(fastcache=True)
def add_blocks(data: ND3, slots: NL1, blocks: ND3, pick: NL1, transpose: ti.i32):
    """data[slots[k]] += blocks[pick[k]] (transposed when ``transpose``) for every k; the slots are
    distinct within one call, so the adds need no atomics (one read and one write of each entry:
    numpy's fancy-indexed add made three copies of every block). Parallel over blocks with a plain
    inner loop: 3x faster than parallel over entries, which indexed every entry anew."""
    s = blocks.shape[1]
    for k in range(slots.shape[0]):
        src = pick[k]
        dst = slots[k]
        if transpose:
            for i in range(s):
                for j in range(s):
                    data[dst, i, j] = data[dst, i, j] + blocks[src, j, i]  # a plain store, not an atomic add
        else:
            for i in range(s):
                for j in range(s):
                    data[dst, i, j] = data[dst, i, j] + blocks[src, i, j]


@ti.kernel(fastcache=True)
def rotate_blocks(blocks: ND3, left: NI1, right: NI1, R: ND3, out: ND3):
    """out[b] = R_left[b] blocks[b] R_right[b]^T with the 3x3 rotations acting on components.

    blocks [B, 3 nb, 3 nb]; R [E, 3, 3]; left / right [B] element of the rows / columns.
    """
    nb = blocks.shape[1] // 3
    for b, I, J in ti.ndrange(blocks.shape[0], nb, nb):
        l, r = left[b], right[b]
        for p in ti.static(range(3)):
            for q in ti.static(range(3)):
                acc = 0.0
                for s in ti.static(range(3)):
                    for t in ti.static(range(3)):
                        acc += R[l, p, s] * blocks[b, s * nb + I, t * nb + J] * R[r, q, t]
                out[b, p * nb + I, q * nb + J] = acc
