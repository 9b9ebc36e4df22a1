"""A face prolongation that keeps every fine cell's divergence equal to its coarse cell's (as
``kernels.FACE`` does) but is linear across the faces instead of constant (a Toth & Roe 2002-type
rule, JCP 180), as a scipy matrix on the host.

Coarse face values U_a(J) (J: coarse cell, the face on its low side along a); a fine face of
component a at fine index I lies in coarse cell J = (I + 2) >> 1 with parity o = (I + 2) & 1:

- on a coarse face plane (o_a = 0): u = U_a(J) + sum_{b != a} (o_b - 1/2) sigma_ab(J) / 2, with
  sigma_ab the slope of U_a along b per coarse width (central, from the two neighbours);
- inside the coarse cell (o_a = 1): the mean of the two plane values at the same transverse
  parity, plus c_a = 1/8 sum_{b != a} [sigma_ba(J + e_b) - sigma_ba(J)] (the mixed derivative of
  the other components, which makes every fine cell's flux balance the coarse cell's share: the
  plane values' transverse slopes change the fine cells' x-fluxes linearly in their y, z parity,
  and the constant c_a cancels exactly that in each of the 2^d fine cells).

The divergence is kept whatever the slopes are, as long as the planes and c_a read the same ones;
``slopes`` says where a slope is taken: "central" (both neighbours active, else 0), "onesided"
(one-sided where one neighbour is inactive) or "interior" (only where the face and both neighbours
have face fraction >= ``full``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def tr_prolongation(fine, coarse, comp: np.ndarray, pos: np.ndarray, slopes: str = "central",
                    full: float = 1.0) -> tuple[sp.csr_matrix, np.ndarray]:
    """(P [n, m], coarse keys a * coarse.size + position [m], every active coarse DOF, sorted) at
    the fine DOFs (comp [n], pos [n]) of two ``operator.Level`` objects."""
    d, cs = fine.dim, coarse.size
    ckeys = np.sort(np.concatenate([a * cs + np.nonzero(coarse.active[a])[0] for a in range(d)]))
    nc = len(ckeys)
    cidx = coarse.layout.index_of(ckeys % cs).astype(np.int64)
    ccomp = ckeys // cs
    eye = np.eye(d, dtype=np.int64)
    vf = coarse.vf_host.reshape(d, -1)

    def lookup(a, K):
        """Coarse DOF number of component a at coarse index K [k, d]; -1 if not active."""
        p = coarse.layout.positions(K)
        key = a * cs + np.maximum(p, 0)
        j = np.minimum(np.searchsorted(ckeys, key), nc - 1)
        return np.where((p >= 0) & (ckeys[j] == key), j, -1)

    def filled(j):
        return (j >= 0) & (vf[ccomp[np.maximum(j, 0)], ckeys[np.maximum(j, 0)] % cs] >= full - 1e-12)

    sig = []  # sig[b] [nc, nc]: slope along b of U at each coarse DOF, per coarse width
    i = np.arange(nc)
    for b in range(d):
        up, dn = lookup(ccomp, cidx + eye[b]), lookup(ccomp, cidx - eye[b])
        across = ccomp != b
        central = (up >= 0) & (dn >= 0) & across
        if slopes == "interior":
            central &= filled(up) & filled(dn) & filled(i)
        r, c, v = [i[central]] * 2, [up[central], dn[central]], [np.full(central.sum(), 0.5), np.full(central.sum(), -0.5)]
        if slopes == "onesided":
            for a_on, one, other in (((up >= 0) & (dn < 0), up, i), ((up < 0) & (dn >= 0), i, dn)):
                o = a_on & across
                r += [i[o], i[o]]
                c += [one[o], other[o]]
                v += [np.full(o.sum(), 1.0), np.full(o.sum(), -1.0)]
        sig.append(sp.csr_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), (nc, nc)))

    comp = np.asarray(comp, dtype=np.int64)
    n = len(comp)
    rows = np.arange(n)
    I = fine.layout.index_of(pos).astype(np.int64) + 2
    J, par = I >> 1, I & 1
    along = par[rows, comp]
    ea = eye[comp]

    def pick(j, w):
        ok = j >= 0
        return sp.csr_matrix((np.broadcast_to(w, j.shape)[ok], (rows[ok], j[ok])), (n, nc))

    out = sp.csr_matrix((n, nc))

    def plane(mask, K, scale):
        nonlocal out
        j = np.where(mask, lookup(comp, K), -1)
        out = out + pick(j, scale)
        for b in range(d):
            out = out + pick(j, np.where(comp != b, (par[:, b] - 0.5) / 2 * scale, 0.0)) @ sig[b]

    plane(along == 0, J, 1.0)
    mid = along == 1
    plane(mid, J, 0.5)
    plane(mid, J + ea, 0.5)
    for b in range(d):  # c_a: the slope along a of U_b on the two b-planes of the coarse cell
        on = mid & (comp != b)
        for base, sign in ((J + eye[b], 1.0), (J, -1.0)):
            j = np.where(on, lookup(np.full(n, b), base), -1)
            for a in range(d):
                out = out + pick(np.where(comp == a, j, -1), sign / 8) @ sig[a]
    out = out.tocsr()
    out.eliminate_zeros()
    return out, ckeys
