"""Prototype: cut cells' normal strains read at their solid's centroid, with per-face transverse slopes
(central where both neighbours are active) so that the energy's linear term has an exact Green identity."""
import math
import os
import numpy as np
import scipy.sparse as sp
from engine.staggered import assembly, multigrid
from engine.staggered.operator import Level

G = {"moments": None, "on": True, "beta": 0.05}   # moments(grid_origin, h, shape) -> (V [box], cen [box, d]) offsets/h


def box_moments(lo, hi):
    def f(origin, h, box):
        d = len(box)
        idx = np.indices(box).reshape(d, -1).T
        clo = np.asarray(origin) + h * idx
        chi = clo + h
        a = np.maximum(clo, lo); b = np.minimum(chi, hi)
        ext = np.clip(b - a, 0, None)
        V = np.prod(ext, axis=1) / h**d
        cen = np.where(ext > 0, ((a + b) / 2 - (clo + h / 2)) / h, 0.0)
        S = np.zeros((len(V), d, d))
        for k in range(d):
            S[:, k, k] = V * (ext[:, k] / h) ** 2 / 12
        G["S"] = S.reshape(tuple(box) + (d, d))
        return V.reshape(box), cen.reshape(tuple(box) + (d,))
    return f


def _lookup(arrays, box):
    """f(a, J [n, d]) -> arrays[a] at J, False outside the index box."""
    def at(a, J):
        ok = np.all((J >= 0) & (J < np.asarray(box)), axis=1)
        out = np.zeros(len(J), bool)
        out[ok] = arrays[a][tuple(J[ok].T)]
        return out
    return at


def _curvature(a, b, J0, J1, isact, eye):
    """(mask, samples, coefficient) of h^2 d_bb u_a between the samples J0 and J1 = J0 + e_b: central
    from the samples beyond both, else one-sided."""
    lo_, hi_ = isact(a, J0 - eye[b]), isact(a, J1 + eye[b])
    both = lo_ & hi_; olo = lo_ & ~hi_; ohi = hi_ & ~lo_
    return [(both, J1 + eye[b], 0.5), (both, J1, -0.5), (both, J0, -0.5), (both, J0 - eye[b], 0.5),
            (olo, J1, 1.0), (olo, J0, -2.0), (olo, J0 - eye[b], 1.0),
            (ohi, J1 + eye[b], 1.0), (ohi, J1, -2.0), (ohi, J0, 1.0)]


def _moved(V):
    """Control volumes whose strains move: the cut ones, with EXTEND also those beside a cut or empty one."""
    if not G.get("extend"):
        return (V > 1e-12) & (V < 1 - 1e-12)
    notfull = V < 1 - 1e-12
    near = notfull.copy()
    for k in range(V.ndim):
        for sh in (1, -1):
            near |= np.roll(notfull, sh, axis=k)
    return (V > 1e-12) & near


def correction(cell, h, lam, mu, origin, edges=None):
    box = cell.shape
    d = len(box)
    P = math.prod(box)
    V, cen = G["moments"](origin, h, box)
    Vc = cell
    cut = _moved(Vc)
    # active DOF (a, J): cell J or J - e_a has material
    act = []
    for a in (range(d) if G.get("act") is None else []):
        s = Vc > 0
        sh = np.zeros_like(s); sl = [slice(None)] * d; sl2 = [slice(None)] * d
        sl[a] = slice(1, None); sl2[a] = slice(None, -1)
        sh[tuple(sl)] = s[tuple(sl2)]
        act.append(s | sh)
    if G.get("act") is not None:
        act = [np.asarray(x, bool) for x in G["act"]]
    eye = np.eye(d, dtype=int)
    def gid(a, J):
        return a * P + np.ravel_multi_index(tuple(J.T), box)
    isact = _lookup(act, box)
    wet = _lookup(G["wet"], box) if G.get("wet") is not None and G.get("wetonly") else None

    def iswet(a, J):
        return isact(a, J) if wet is None else wet(a, J) & isact(a, J)

    def slope(a, k, J):
        return _slopes(a, k, J, iswet, isact, eye, G.get("order2", False))
    if G.get("skipheld") and G.get("heldmask") is not None and G["heldmask"].shape == cut.shape:
        cut = cut & ~G["heldmask"]
    if G.get("skiploaded") and G.get("loadedmask") is not None and G["loadedmask"].shape == cut.shape:
        cut = cut & ~G["loadedmask"]
    if os.environ.get("SKIPINNER") == "1":
        cc_ = np.asarray(origin) + h * (np.indices(cut.shape).reshape(d, -1).T + 0.5)
        cut = cut & (np.linalg.norm(cc_, axis=1).reshape(cut.shape) > 0.75)
    if os.environ.get("SKIPOUTER") == "1":
        cc_ = np.asarray(origin) + h * (np.indices(cut.shape).reshape(d, -1).T + 0.5)
        cut = cut & (np.linalg.norm(cc_, axis=1).reshape(cut.shape) < 0.75)
    cells = np.argwhere(cut)
    I = cells
    rows, cols, vals = [], [], []
    n = len(I)
    b_cell, _ = assembly.strain_operators(tuple(s - 1 for s in box), h)
    ridx = np.arange(n)
    Drows = [[] for _ in range(d)]; Dcols = [[] for _ in range(d)]; Dvals = [[] for _ in range(d)]
    for a in range(d):
        # plain eps_aa
        for J, c in ((I + eye[a], 1.0 / h), (I, -1.0 / h)):
            rows.append(a * n + ridx); cols.append(gid(a, np.clip(J, 0, np.asarray(box) - 1))); vals.append(np.full(n, c))
        if G.get("along", True):
            m = cen[tuple(I.T)][:, a]
            J0, J1 = I, I + eye[a]
            for mask, JJ, c in _curvature(a, a, J0, J1, isact, eye):
                sel = mask & (m != 0)
                rows.append(a * n + ridx[sel]); cols.append(gid(a, JJ[sel])); vals.append(c * m[sel] / h)
                Drows[a].append(a * n + ridx[mask]); Dcols[a].append(gid(a, JJ[mask])); Dvals[a].append(np.full(mask.sum(), c / h))
        for k in range(d):
            if k == a:
                continue
            m = cen[tuple(I.T)][:, k]  # (xbar_k - c_k) / h
            for J, sgn in ((I + eye[a], 1.0), (I, -1.0)):
                for mask, JJ, c in slope(a, k, J):
                    sel = mask & (m != 0)
                    rows.append(a * n + ridx[sel]); cols.append(gid(a, JJ[sel])); vals.append(sgn * c * m[sel] / h)
                    Drows[k].append(a * n + ridx[mask]); Dcols[k].append(gid(a, JJ[mask])); Dvals[k].append(np.full(mask.sum(), sgn * c / h))
    R = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(d * n, d * P))
    R0 = sp.csr_matrix((np.concatenate(vals[:0] + [np.full(n, 1.0 / h), np.full(n, -1.0 / h)] * d),
                        (np.concatenate([a * n + ridx for a in range(d) for _ in (0, 1)]),
                         np.concatenate([gid(a, np.clip(J, 0, np.asarray(box) - 1)) for a in range(d) for J in (I + eye[a], I)]))),
                       shape=(d * n, d * P))
    C = 2 * mu * np.eye(d) + (0.0 if G.get('muonly') else lam) * np.ones((d, d))
    weight = np.ones(n)
    if G.get("aligned") and (G.get("cellnormal") is not None or os.environ.get("ALIGNFROM") == "centroid"):
        # moved in full where the cell's surface faces a grid axis, not at all beyond ALIGNED degrees;
        # ALIGNFROM=centroid: the direction of the solid's centroid offset stands in for the normal
        nc = G["cellnormal"][tuple(I.T)] if os.environ.get("ALIGNFROM") != "centroid" else cen[tuple(I.T)]
        size = np.linalg.norm(nc, axis=1)
        tilt = np.degrees(np.arccos(np.clip(np.abs(nc).max(axis=1) / np.maximum(size, 1e-300), 0.0, 1.0)))
        weight = np.where(size > 0, np.clip(1.0 - tilt / G["aligned"], 0.0, 1.0), 0.0)
    G["weight"] = weight
    W = sp.kron(sp.csr_matrix(C), sp.diags(Vc[tuple(I.T)] * h**d * weight))
    dK = (1 - G['beta']) * (R.T @ W @ R - R0.T @ W @ R0)
    if G.get("second", False) and "S" in G:
        Dm = [sp.csr_matrix((np.concatenate(Dvals[k]) if Dvals[k] else np.zeros(0), (np.concatenate(Drows[k]) if Drows[k] else np.zeros(0, int), np.concatenate(Dcols[k]) if Dcols[k] else np.zeros(0, int))), shape=(d * n, d * P)) for k in range(d)]
        Sc = G["S"][tuple(I.T)]
        for j in range(d):
            for k in range(d):
                Wjk = sp.kron(sp.csr_matrix(C), sp.diags(Sc[:, j, k] * h**d))
                dK = dK + (1 - G['beta']) * (Dm[j].T @ Wjk @ Dm[k])

    if G.get("shear") and edges is not None and "edge_moments" in G:
        for (pa, pb), Ve in edges.items():
            Ve = np.asarray(Ve)
            cutE = _moved(Ve)
            E = np.argwhere(cutE)
            ne = len(E)
            if not ne:
                continue
            cenE = G["edge_moments"][(pa, pb)]
            mE = cenE[tuple(E.T)]  # [ne, d] offsets / h from the edge
            er = np.arange(ne)
            rr, cc, vv = [], [], []
            r0, c0, v0 = [], [], []
            DR = [[] for _ in range(d)]; DC = [[] for _ in range(d)]; DV = [[] for _ in range(d)]
            for a, b in ((pa, pb), (pb, pa)):   # half: (u_a(E) - u_a(E - e_b)) / (2h)
                J1, J0 = E, E - eye[b]
                for JJ, cf in ((J1, 0.5 / h), (J0, -0.5 / h)):
                    ok = isact(a, JJ)
                    rr.append(er[ok]); cc.append(gid(a, JJ[ok])); vv.append(np.full(ok.sum(), cf))
                    r0.append(er[ok]); c0.append(gid(a, JJ[ok])); v0.append(np.full(ok.sum(), cf))
                for k in range(d):
                    m = mE[:, k]
                    if k == b:  # along b: curvature of u_a across the two samples
                        for mask, JJ, c in _curvature(a, b, J0, J1, isact, eye):
                            sel = mask & (m != 0)
                            rr.append(er[sel]); cc.append(gid(a, JJ[sel])); vv.append(0.5 * c * m[sel] / h)
                            DR[k].append(er[mask]); DC[k].append(gid(a, JJ[mask])); DV[k].append(np.full(mask.sum(), 0.5 * c / h))
                        continue
                    for J, sgn in ((J1, 1.0), (J0, -1.0)):
                        for mask, JJ, c in slope(a, k, J):
                            sel = mask & (m != 0)
                            rr.append(er[sel]); cc.append(gid(a, JJ[sel])); vv.append(0.5 * sgn * c * m[sel] / h)
                            DR[k].append(er[mask]); DC[k].append(gid(a, JJ[mask])); DV[k].append(np.full(mask.sum(), 0.5 * sgn * c / h))
            Rs = sp.csr_matrix((np.concatenate(vv), (np.concatenate(rr), np.concatenate(cc))), shape=(ne, d * P))
            R0s = sp.csr_matrix((np.concatenate(v0), (np.concatenate(r0), np.concatenate(c0))), shape=(ne, d * P))
            Ws = sp.diags(4 * mu * Ve[tuple(E.T)] * h**d)
            dK = dK + (1 - G['beta']) * (Rs.T @ Ws @ Rs - R0s.T @ Ws @ R0s)
            if G.get("second") and (pa, pb) in G.get("edge_S", {}):
                SE = G["edge_S"][(pa, pb)][tuple(E.T)]
                Dm = [sp.csr_matrix((np.concatenate(DV[k]), (np.concatenate(DR[k]), np.concatenate(DC[k]))), shape=(ne, d * P)) for k in range(d)]
                for j in range(d):
                    for k in range(d):
                        dK = dK + (1 - G['beta']) * (Dm[j].T @ sp.diags(4 * mu * SE[:, j, k] * h**d) @ Dm[k])
    G['R'] = R.tocsr(); G['I'] = I; G['cen'] = cen; G['n'] = n
    G['dR'] = ((R - R0).tocsr(), Vc[tuple(I.T)] * h**d, I, box, n)
    return dK.tocsr()


_orig_stiffness = assembly.stiffness


def stiffness(cell, edges, spacing, lam, mu):
    K = _orig_stiffness(cell, edges, spacing, lam, mu)
    fine = G.get("grid") is None or abs(spacing - G["grid"].spacing) < 1e-12 * spacing
    if G["on"] and G["moments"] is not None and fine:
        K = K + correction(np.asarray(cell), spacing, lam, mu, G["origin"], edges)
    return K.tocsr()


assembly.stiffness = stiffness
_orig_init = multigrid.CoarseSolver.__init__


def _set_held(level):
    if level.hold is None or level.origin is None:
        return
    lay = level.layout
    h = level.spacing
    x = level.hold.quadrature(2 * h).points
    I = np.floor((x - np.asarray(level.origin)) / h).astype(np.int64)
    mask = np.zeros(tuple(lay.box), bool)
    d = level.dim
    import itertools as _it
    for off in _it.product((-1, 0, 1), repeat=d):
        J = I + np.asarray(off)
        ok = np.all((J >= 0) & (J < np.asarray(lay.box)), axis=1)
        mask[tuple(J[ok].T)] = True
    G["heldmask"] = mask


def _set_wet(level):
    _set_held(level)
    lay = level.layout
    if level.vf_host is not None:
        G["wet"] = [lay.dense(level.vf_host[a] >= 0.5) for a in range(level.dim)]


def build_proto(level, jhold=False):
    """The fine level's operator K (+ the correction) + S on its free DOFs, kept as ``level._proto``."""
    lay = level.layout
    G["act"] = [lay.dense(level.active[a]) for a in range(level.dim)]
    _set_wet(level)
    d = lay.dim
    cells = tuple(n - 1 for n in lay.box)
    idx = lay.indices()
    pos = np.nonzero(np.all(idx < np.asarray(lay.box), axis=1))[0]
    idx = idx[pos]
    comp = np.repeat(np.arange(d), len(idx))
    flat_pos = np.tile(pos, d)
    free = level.free[comp, flat_pos]
    gidv = assembly.dof_index(comp, np.tile(idx, (d, 1)), cells)
    cell = lay.dense(level.vc_host)
    edges = {p: lay.dense(level.ve_host[q]) for q, p in enumerate(multigrid.axis_pairs(d))}
    K = assembly.stiffness(cell, edges, level.spacing, level.lam, level.mu).tocsr()
    if jhold and level.surface is not None:
        K = K + jprime_hold(level)
    order = gidv[free]
    A = K[order][:, order].tocsr()
    fc, fp = comp[free], flat_pos[free]
    if level.surface is not None and not jhold:
        A = A + multigrid._on_free(level.surface, level.surface.matrix(), fc, fp, level.size)
    level._proto = (A.tocsr(), fc, fp)
    return level._proto[0]


def init(self, level, name="coarsest multigrid level"):
    G["act"] = [level.layout.dense(level.active[a]) for a in range(level.dim)]
    _set_wet(level)
    _orig_init(self, level, name)
    if G.get("grid") is None or abs(level.spacing - G["grid"].spacing) < 1e-12 * level.spacing:
        build_proto(level)


_orig_mg = multigrid.Multigrid.__init__


def mg_init(self, fine, **kw):
    _orig_mg(self, fine, **kw)
    if getattr(fine, "_proto", None) is None and G["on"]:
        if G.get("jhold") and fine.surface is not None:
            build_proto_j(fine)
        else:
            build_proto(fine)


multigrid.Multigrid.__init__ = mg_init


multigrid.CoarseSolver.__init__ = init
_orig_apply = Level.apply


def apply(self, x, y, part=None):
    if part is None and getattr(self, "_proto", None) is not None:
        A, comp, pos = self._proto
        xn = x.to_numpy()
        yn = np.zeros_like(xn)
        yn[comp, pos] = A @ xn[comp, pos]
        y.from_numpy(yn)
        return
    _orig_apply(self, x, y, part)


Level.apply = apply
_orig_residual = Level.residual


def residual(self, x, b, r):
    if getattr(self, "_proto", None) is not None:
        A, comp, pos = self._proto
        xn = x.to_numpy(); bn = b.to_numpy()
        rn = np.zeros_like(xn)
        rn[comp, pos] = bn[comp, pos] - A @ xn[comp, pos]
        r.from_numpy(rn)
        return
    _orig_residual(self, x, b, r)


Level.residual = residual

# ---- general meshes: exact cell first moments from the DG slicer
from engine.staggered import elasticity as _el

_orig_post = _el.StaggeredElasticity.__post_init__


def _loaded_mask(elastic, grid):
    """Cells within one cell of a surface load's patch (any form): quadrature points at h / 2."""
    from engine.boundary import patch_quadrature
    import itertools as _it
    box = tuple(n + 1 for n in grid.shape)
    mask = np.zeros(box, bool)
    h, d = grid.spacing, grid.dim
    for load in elastic.surface_loads:
        x, _, _ = patch_quadrature(elastic.surface, load.region, 0.5 * h, name=load.name)
        I = np.floor((x - np.asarray(grid.origin)) / h).astype(np.int64)
        for off in _it.product((-1, 0, 1), repeat=d):
            J = I + np.asarray(off)
            ok = np.all((J >= 0) & (J < np.asarray(box)), axis=1)
            mask[tuple(J[ok].T)] = True
    return mask


def subcell_moments(fractions):
    """(V, centroid offsets / h) per cell from the h/2 sub-cells' fractions: each sub-cell's solid
    taken at the sub-cell's centre (an approximation; exact for full sub-cells)."""
    grid = fractions.grid
    d = grid.dim
    box = tuple(n + 1 for n in grid.shape)
    sub = fractions.subcells.dense()
    V = np.zeros(box); M = np.zeros(box + (d,))
    import itertools as _it
    for off in _it.product((0, 1), repeat=d):
        part = sub[tuple(slice(o, None, 2) for o in off)] / 2**d
        sl = tuple(slice(0, n) for n in part.shape)
        V[sl] += part
        for k in range(d):
            M[sl + (k,)] += part * (off[k] - 0.5) * 0.5
    cen = np.where(V[..., None] > 0, M / np.maximum(V, 1e-300)[..., None], 0.0)

    def f(origin, h, boxshape):
        assert tuple(boxshape) == box, (boxshape, box)
        return V, cen
    return f


def _cell_normals(surface, grid):
    """[box, d] unit area-weighted mean outward normal of the surface in each cell (0 where none)."""
    from engine.boundary import surface_quadrature
    d, h = grid.dim, grid.spacing
    box = tuple(n + 1 for n in grid.shape)
    x, w, nrm = surface_quadrature(surface.vertices[surface.faces], h)
    I = np.clip(np.floor((x - np.asarray(grid.origin)) / h).astype(np.int64), 0, np.asarray(box) - 1)
    acc = np.zeros(box + (d,))
    for k in range(d):
        np.add.at(acc[..., k], tuple(I.T), w * nrm[:, k])
    norm = np.linalg.norm(acc, axis=-1, keepdims=True)
    return np.where(norm > 0, acc / np.maximum(norm, 1e-300), 0.0)


def _post(self, fractions):
    G["grid"] = fractions.grid
    if G.get("aligned") and os.environ.get("ALIGNFROM") != "centroid":
        G["cellnormal"] = _cell_normals(self.surface, fractions.grid)
    if G.get("skiploaded"):
        G["loadedmask"] = _loaded_mask(self, fractions.grid)
    if G.get("subcell") and fractions.subcells is not None:
        G["moments"] = subcell_moments(fractions)
        G["origin"] = np.asarray(fractions.grid.origin, float)
    elif G.get("slice", False):
        G["moments"] = sliced_moments(self.surface, fractions.grid)
        if G.get("shear"):
            G["edge_moments"] = edge_moments(self.surface, fractions.grid)
        G["origin"] = np.asarray(fractions.grid.origin, float)
    _orig_post(self, fractions)


_el.StaggeredElasticity.__post_init__ = _post


def _box_moments(cut, box):
    """(V [box], centroid offsets [box, d] in h, central second moments [box, d, d] in h^2 units times V)
    of the pieces of ``cut`` summed per cell of the index box."""
    d = 3
    ex = cut.exponents
    col = lambda e: int(np.nonzero((ex == e).all(1))[0][0])  # noqa: E731
    pc = tuple(cut.piece_cell.T)
    V = np.zeros(box); M = np.zeros(box + (d,)); M2 = np.zeros(box + (d, d))
    np.add.at(V, pc, cut.moments[:, col(np.zeros(d, int))])
    eye = np.eye(d, dtype=int)
    for j in range(d):
        np.add.at(M[..., j], pc, cut.moments[:, col(eye[j])])
        for k in range(d):
            np.add.at(M2[..., j, k], pc, cut.moments[:, col(eye[j] + eye[k])])
    cen = np.where(V[..., None] > 0, M / np.maximum(V, 1e-300)[..., None], 0.0)
    return V, cen, M2 - V[..., None, None] * cen[..., :, None] * cen[..., None, :]


def sliced_moments(surface, grid):
    from engine.geometry.slicing import slice_cells
    box = tuple(n + 1 for n in grid.shape)
    V, cen, G["S"] = _box_moments(slice_cells(surface, grid, degree=2), box)

    def f(origin, h, boxshape):
        assert tuple(boxshape) == box, (boxshape, box)
        return V, cen
    return f


_orig_div = _el.StaggeredElasticity._divergence_load


def _div(self, load, f):
    _orig_div(self, load, f)
    if not (G["on"] and G["moments"] is not None) or load.pressure is None:
        return
    level = self.level
    lay = level.layout
    d = lay.dim
    cell = lay.dense(level.vc_host)
    G["act"] = [lay.dense(level.active[a]) for a in range(d)]
    _set_wet(level)
    correction(np.asarray(cell), level.spacing, level.lam, level.mu, G["origin"])
    dR, w, I, box, n = G["dR"]
    h = level.spacing
    centres = np.asarray(G["origin"]) + h * (I + 0.5)
    near = np.asarray(load.region.contains(centres, slack=0.5 * h), dtype=bool)
    P = int(np.prod(box))
    coef = np.zeros(d * n)
    for a in range(d):
        sig = -float(load.pressure)
        if G.get('muonly'):
            K_ = level.lam + 2 * level.mu / d if d == 3 else level.lam + level.mu
            sig = 2 * level.mu * (-float(load.pressure)) / (d * K_)
        coef[a * n + np.arange(n)] = np.where(near, w * sig * G["weight"], 0.0)
    fx = (1 - G["beta"]) * (dR.T @ coef)  # [d P]
    idx = np.indices(box).reshape(d, -1).T
    pos = lay.positions(idx)
    for a in range(d):
        part = fx[a * P:(a + 1) * P]
        ok = (pos >= 0) & (part != 0)
        np.add.at(f[a], pos[ok], part[ok])


_el.StaggeredElasticity._divergence_load = _div


def edge_moments(surface, grid):
    from engine.geometry.slicing import slice_cells
    from engine.grid import Grid
    d = grid.dim
    box = tuple(n + 1 for n in grid.shape)
    out = {}
    for a in range(d):
        for b in range(a + 1, d):
            s_ = np.eye(d)[a] + np.eye(d)[b]
            g2 = Grid(origin=tuple(np.asarray(grid.origin) - 0.5 * grid.spacing * s_), spacing=grid.spacing,
                      shape=tuple(int(n + o) for n, o in zip(grid.shape, s_)))
            _, out[(a, b)], S = _box_moments(slice_cells(surface, g2, degree=2), box)
            G.setdefault("edge_S", {})[(a, b)] = S
    return out

# ---- the hold's flux from the moved strains (mu part)
from engine.staggered import nitsche as _ni

_orig_stress_rows = _ni._stress_rows


def _stress_rows(level, cells, nv, lam):
    rows, keys, vals = _orig_stress_rows(level, cells, nv, lam)
    if not (G["on"] and G.get("flux") and G["moments"] is not None):
        return rows, keys, vals
    if G.get("grid") is not None and abs(level.spacing - G["grid"].spacing) > 1e-12 * level.spacing:
        return rows, keys, vals
    lay = level.layout
    d = lay.dim
    cell = lay.dense(level.vc_host)
    G["act"] = [lay.dense(level.active[a]) for a in range(d)]
    correction(np.asarray(cell), level.spacing, level.lam, level.mu, G["origin"])
    dR, w, I, box, n = G["dR"]
    P = int(np.prod(box))
    # source cell s -> cut row index
    cut_index = {tuple(c): i for i, c in enumerate(I)}
    idx_all = np.indices(box).reshape(d, -1).T
    pos_all = lay.positions(idx_all)
    add_r, add_k, add_v = [rows], [keys], [vals]
    dR = dR.tocsr()
    for s, c in enumerate(cells):
        i = cut_index.get(tuple(c))
        if i is None:
            continue
        for a in range(d):
            row = dR.getrow(a * n + i)
            g = row.indices
            comp = g // P
            pos = pos_all[g % P]
            ok = pos >= 0
            add_r.append(np.full(ok.sum(), s * nv + a))
            add_k.append(comp[ok] * level.size + pos[ok])
            add_v.append(float(os.environ.get("FLUXSCALE", "1")) * (1 - G["beta"]) * 2 * level.mu * row.data[ok])
    return np.concatenate(add_r), np.concatenate(add_k), np.concatenate(add_v)


_ni._stress_rows = _stress_rows

# ---- the hold read through J' (the moved energy's own displacement), fine level, direct solves
from engine.grid import axis_pairs as _pairs


def _slopes(a, k, J, near, here, eye, order2=False):
    """(mask, samples, coefficient) of h d_k u_a at the samples J [n, d]: central where ``near`` holds on
    both sides, else one-sided (three samples with ``order2``) from the sample itself (``here``)."""
    up, dn = J + eye[k], J - eye[k]
    au, ad, c = near(a, up), near(a, dn), here(a, J)
    both = au & ad
    ou, od = au & ~ad & c, ad & ~au & c
    terms = [(both, up, 0.5), (both, dn, -0.5)]
    if order2:
        o2u, o2d = ou & near(a, J + 2 * eye[k]), od & near(a, J - 2 * eye[k])
        terms += [(o2u, J + 2 * eye[k], -0.5), (o2u, up, 2.0), (o2u, J, -1.5),
                  (o2d, J - 2 * eye[k], 0.5), (o2d, dn, -2.0), (o2d, J, 1.5)]
        ou, od = ou & ~o2u, od & ~o2d
    return terms + [(ou, up, 1.0), (ou, J, -1.0), (od, J, 1.0), (od, dn, -1.0)]


def jprime_hold(level):
    lay = level.layout
    d, h = lay.dim, level.spacing
    box = tuple(lay.box)
    P = int(np.prod(box))
    N = d * P
    origin = np.asarray(level.origin, float)
    eye = np.eye(d, dtype=int)
    isact = _lookup([np.asarray(x, bool) for x in G["act"]], box)

    def gid(a, J):
        return a * P + np.ravel_multi_index(tuple(np.clip(J, 0, np.asarray(box) - 1).T), box)

    quad = level.hold.quadrature(2 * h)
    x, w = quad.points, quad.weights
    nv = d + len(_pairs(d))
    lam, mu = level.lam, level.mu
    big = _ni.traction_bound(lam, mu, d)
    src, sources, fill = _ni._sources(level, np.floor((x - origin) / h).astype(np.int64))
    area = np.bincount(src, weights=w, minlength=len(sources))
    gamma = (_ni.COERCIVITY * big / h**d) * area / fill
    gw = w * gamma[src]
    s_rows, s_keys, s_vals = _ni._stress_rows(level, sources, nv, lam)
    sa, spos = s_keys // level.size, s_keys % level.size
    sidx = lay.index_of(spos).astype(np.int64)
    m = len(sources) * nv
    Sig = sp.csr_matrix((s_vals, (s_rows, sa * P + np.ravel_multi_index(tuple(sidx.T), box))), shape=(m, N))
    voigt = {a: [(a, a)] + [(d + q, b if p == a else p) for q, (p, b) in enumerate(_pairs(d)) if a in (p, b)]
             for a in range(d)}
    I = np.floor((x - origin) / h).astype(np.int64)
    Q = len(x)
    qs = np.arange(Q)
    mass = sp.csr_matrix((N, N))
    F = sp.csr_matrix((N, m))
    for a in range(d):
        rr, cc, vv = [], [], []
        lam1 = (x[:, a] - (origin[a] + h * I[:, a])) / h
        for Jf, lf in ((I, 1 - lam1), (I + eye[a], lam1)):
            ok = isact(a, Jf)
            rr.append(qs[ok]); cc.append(gid(a, Jf[ok])); vv.append(lf[ok])
            for k in range(d):
                if k == a:
                    continue
                t = (x[:, k] - (origin[k] + h * (I[:, k] + 0.5))) / h
                for mask, JJ, c in _slopes(a, k, Jf, isact, isact, eye):
                    rr.append(qs[mask]); cc.append(gid(a, JJ[mask])); vv.append(lf[mask] * t[mask] * c)
        Phi = sp.csr_matrix((np.concatenate(vv), (np.concatenate(rr), np.concatenate(cc))), shape=(Q, N))
        ma = quad.mask[:, a]
        mass = mass + Phi.T @ sp.diags(gw * ma) @ Phi
        for v, j in voigt[a]:
            M = sp.csr_matrix((w * quad.normals[:, j] * ma, (qs, src * nv + v)), shape=(Q, m))
            F = F + Phi.T @ M
    B = (F @ Sig).tocsr()
    return (mass - B - B.T).tocsr()


def build_proto_j(level):
    """build_proto with the hold read through J' (``jprime_hold``)."""
    return build_proto(level, jhold=True)


_init_before_j = multigrid.CoarseSolver.__init__


def init_j(self, level, name="coarsest multigrid level"):
    _init_before_j(self, level, name)
    if G.get("jhold") and level.surface is not None and (G.get("grid") is None or abs(level.spacing - G["grid"].spacing) < 1e-12 * level.spacing):
        from engine.solvers.direct import Cholesky
        A = build_proto_j(level)
        self.factor = Cholesky(A, definite=True)


multigrid.CoarseSolver.__init__ = init_j


def configure_from_env():
    """The switches of the README from the environment (scripts call this after setting on / slice)."""
    e = os.environ.get
    G["beta"] = float(e("BETA", "0.05"))
    for key, var in (("muonly", "MUONLY"), ("shear", "SHEAR"), ("second", "SECOND"), ("extend", "EXTEND"),
                     ("wetonly", "WET"), ("skipheld", "SKIPHELD"), ("jhold", "JHOLD"), ("flux", "FLUX"),
                     ("order2", "ORDER2"), ("skiploaded", "SKIPLOADED"), ("subcell", "SUBCELL")):
        G[key] = e(var) == "1"
    G["along"] = e("ALONG", "1") == "1"
    G["aligned"] = float(e("ALIGNED", "0")) or None
    if G["subcell"]:
        keep_subcells()


def keep_subcells():
    """SUBCELL=1: the pipeline's volume fractions keep their h/2 sub-cells (for ``subcell_moments``)."""
    from engine import pipeline as _pl
    from engine.geometry.fractions import volume_fractions as _vf
    _pl._GEOMETRY["fractions"] = ("fractions", lambda s, g: _vf(s, g, keep_subcells=True))
