"""Prototype: cell energy weights = the solid integral of each cell's renormalised multilinear hat
(the partition the multilinear trace of loads and holds uses), replacing the cell fractions."""
import itertools
import numpy as np
from engine import pipeline as _pl
from engine.geometry.fractions import volume_fractions as _vf

SPEC = {"box": None, "inside": None, "q": 12}


def _w1d(n, o, h, lo, hi, m=4000):
    act = np.array([(min(o + h * (i + 1), hi) - max(o + h * i, lo)) > 0 for i in range(n)])
    x = np.linspace(lo, hi, m * max(1, int(np.ceil((hi - lo) / h))) + 1)
    xm = 0.5 * (x[1:] + x[:-1]); dx = np.diff(x)
    t = (xm - o) / h - 0.5
    b = np.floor(t).astype(int); f = t - b
    w = np.zeros(n)
    for J, g in ((b, 1 - f), (b + 1, f)):
        ok = (J >= 0) & (J < n)
        g = np.where(ok, g, 0.0)
        g = np.where(ok, g * act[np.clip(J, 0, n - 1)], 0.0)
        if J is b: g0, J0 = g, J
        else: g1, J1 = g, J
    s = g0 + g1
    for J, g in ((J0, g0), (J1, g1)):
        ok = (J >= 0) & (J < n) & (s > 0)
        np.add.at(w, J[ok], (g[ok] / s[ok]) * dx[ok] / h)
    return w


def box_weights(grid, lo, hi):
    ws = [_w1d(grid.shape[k], grid.origin[k], grid.spacing, lo[k], hi[k]) for k in range(grid.dim)]
    out = ws[0]
    for w in ws[1:]:
        out = np.multiply.outer(out, w)
    return out


def sampled_weights(V, grid, inside, q):
    d, h = grid.dim, grid.spacing
    o = np.asarray(grid.origin, float)
    act = V > 0
    W = np.zeros(V.shape)
    cells = np.argwhere(act)
    sub = (np.indices((q,) * d).reshape(d, -1).T + 0.5) / q
    corners = np.array(list(itertools.product((0, 1), repeat=d)))
    shape = np.asarray(V.shape)
    for c0 in range(0, len(cells), max(1, 200000 // len(sub))):
        C = cells[c0:c0 + max(1, 200000 // len(sub))]
        pts = (C[:, None, :] + sub[None]).reshape(-1, d)   # in cell units
        ins = inside(o + h * pts).astype(float)
        t = pts - 0.5
        b = np.floor(t).astype(int); f = t - b
        gs, Js = [], []
        for cr in corners:
            J = b + cr
            g = np.prod(np.where(cr, f, 1 - f), axis=1)
            ok = np.all((J >= 0) & (J < shape), axis=1)
            Jc = np.clip(J, 0, shape - 1)
            g = np.where(ok & act[tuple(Jc.T)], g, 0.0)
            gs.append(g); Js.append(Jc)
        s = np.sum(gs, axis=0)
        for g, J in zip(gs, Js):
            ok = (s > 0) & (ins > 0)
            np.add.at(W, tuple(J[ok].T), g[ok] / s[ok] / q**d)
    return W


def _replace(fr):
    grid = fr.grid
    bs = fr.control[(0,) * grid.dim]
    V = bs.dense()
    if SPEC["box"] is not None:
        W = box_weights(grid, *SPEC["box"])
    else:
        W = sampled_weights(V, grid, SPEC["inside"], SPEC["q"])
    W = np.where(V > 0, W, 0.0)
    idx, _ = bs.nonzero()
    where = np.nonzero(bs.data)
    bs.data[where] = W[tuple(idx.T)]
    print("hat weights: total", W.sum(), "fractions", V.sum(), "min w/V on active", (W[V > 0] / V[V > 0]).min(),
          "max", (W[V > 0] / V[V > 0]).max(), flush=True)
    return fr


def install():
    _pl._GEOMETRY["fractions"] = ("fractions", lambda s, g: _replace(_vf(s, g)))
