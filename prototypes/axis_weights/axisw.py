"""Prototype: the mu part of each strain term weighed by a control-volume weight whose first moments are
the solid's along the axes that term's row forces do not difference (eps_aa: the axes k != a; the shear
eps_ab on edges along c: c only); the lambda term keeps the plain fractions. Installs on top of the
cut_cell_centroids harness (its assembled operator and PARDISO), replacing its correction."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "cut_cell_centroids"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "fitted_weights"))
import numpy as np
import scipy.sparse as sp

import cutstrain
from engine.staggered import assembly
from engine.staggered import elasticity as _el

G = cutstrain.G
KEEP = float(os.environ.get("KEEP", "0.25"))
LAMBDA = float(os.environ.get("LAMBDA", "0"))   # share of the lambda term's weights moved (pairwise: eps_a eps_b along the other axes)
SHEAR = os.environ.get("AXSHEAR", "1") == "1"
ALIGN = float(os.environ.get("ALIGN", "0"))
SKIPHELD = os.environ.get("SKIPHELD", "0") == "1"   # no weight leaves a volume within a cell of a hold's points


def moved(V, cen, axes):
    """weights [box]: V with each cut volume's weight moved toward its solid centroid along ``axes``."""
    import fit
    fit.KEEP = KEEP
    c = np.zeros_like(cen)
    for k in axes:
        c[..., k] = cen[..., k]
    if ALIGN:   # only volumes whose centroid offset lies within ALIGN of one axis (a cut parallel to a grid plane)
        norm = np.linalg.norm(cen, axis=-1)
        c = np.where((np.abs(cen).max(axis=-1) >= ALIGN * norm)[..., None], c, 0.0)
    held = G.get("heldmask")
    if SKIPHELD and held is not None and held.shape == V.shape:
        c[held] = 0.0
    return np.where(V > 0, fit.fitted(V, c), 0.0)


FLAT = float(os.environ.get("FLAT", "0"))   # > 0: only volumes whose fill equals their a-neighbours' to FLAT


def flat_along(V, a, tol):
    """bool [box]: V's neighbours along a that hold material have V's fill to ``tol`` (a face parallel to a)."""
    ok = np.ones(V.shape, bool)
    for sh in (1, -1):
        nb = np.roll(V, sh, axis=a)
        ok &= (nb <= 0) | (np.abs(nb - V) <= tol)
    return ok


def pair_deltas(cell, cen):
    """(a, b) -> [box] weight change of the normal term eps_a eps_b: moved along the axes other than a and b."""
    d = cell.ndim
    out = {}
    for a in range(d):
        for b in range(d):
            axes = [k for k in range(d) if k not in (a, b)]
            c = cen
            if FLAT > 0 and a == b:
                c = np.where(flat_along(cell, a, FLAT)[..., None], cen, 0.0)
            out[(a, b)] = out[(b, a)] if (b, a) in out else moved(cell, c, axes) - cell
    return out


def correction(cell, h, lam, mu, origin, edges=None):
    box = cell.shape
    d = len(box)
    P = int(np.prod(box))
    _, cen = G["moments"](origin, h, box)
    b_cell, b_edge = assembly.strain_operators(tuple(s - 1 for s in box), h)
    dK = sp.csr_matrix((d * P, d * P))
    dw = pair_deltas(cell, cen)
    only = os.environ.get("AXES")
    for (a, b), w in dw.items():
        if only is not None and str(a) not in only:
            continue
        coef = (2 * mu if a == b else 0.0) + LAMBDA * lam
        if coef:
            dK = dK + b_cell[a * P:(a + 1) * P].T @ sp.diags(coef * w.ravel()) @ b_cell[b * P:(b + 1) * P]
    if SHEAR and edges is not None and G.get("edge_moments") is not None:
        for (a, b), Be in b_edge.items():
            c = [k for k in range(d) if k not in (a, b)]
            Ve = np.asarray(edges[(a, b)])
            dw = moved(Ve, G["edge_moments"][(a, b)], c) - Ve
            dK = dK + Be.T @ sp.diags(4 * mu * dw.ravel()) @ Be
    return (h**d * dK).tocsr()


def box_edge_moments(lo, hi, grid):
    out = {}
    d = grid.dim
    box = tuple(n + 1 for n in grid.shape)
    for a in range(d):
        for b in range(a + 1, d):
            s = np.eye(d)[a] + np.eye(d)[b]
            _, out[(a, b)] = cutstrain.box_moments(lo, hi)(np.asarray(grid.origin) - 0.5 * grid.spacing * s,
                                                          grid.spacing, box)
    return out


def _div(self, load, f):
    """The divergence form's pressure with the moved mu weights: the moved operator's residual of the
    affine field whose stress is -p I (its mu part 2 mu eps_aa = -2 mu p / (3 K) on the moved weights)."""
    cutstrain._orig_div(self, load, f)
    if not G["on"] or load.pressure is None or os.environ.get("DIVFIX", "1") != "1":
        return
    level = self.level
    lay = level.layout
    d, h = lay.dim, level.spacing
    cell = lay.dense(level.vc_host)
    box = cell.shape
    P = int(np.prod(box))
    _, cen = G["moments"](G["origin"], h, box)
    b_cell, _ = assembly.strain_operators(tuple(s - 1 for s in box), h)
    centres = np.asarray(G["origin"]) + h * (np.indices(box).reshape(d, -1).T + 0.5)
    near = np.asarray(load.region.contains(centres, slack=0.5 * h), dtype=bool)
    bulk = level.lam + 2 * level.mu / d
    eps = -float(load.pressure) / (d * bulk)
    fx = np.zeros(d * P)
    for (a, b), w in pair_deltas(cell, cen).items():
        coef = (2 * level.mu if a == b else 0.0) + LAMBDA * level.lam
        fx += b_cell[a * P:(a + 1) * P].T @ (np.where(near, w.ravel(), 0.0) * coef * eps * h**d)
    pos = lay.positions(np.indices(box).reshape(d, -1).T)
    for a in range(d):
        part = fx[a * P:(a + 1) * P]
        ok = (pos >= 0) & (part != 0)
        np.add.at(f[a], pos[ok], part[ok])


def mode(name: str) -> None:
    """``on``: this prototype's weights (exact moments) in place of the engine's flat layers; ``engine``:
    the engine as it is (its flat_layers.py); ``off``: neither (the plain
    fractions)."""
    G["on"] = name == "on"
    try:
        from engine.staggered import flat_layers
    except ImportError:  # the engine without the patch: nothing to switch off
        return
    if name != "engine":
        flat_layers.correction = lambda level, *rest: None
        flat_layers.moved_weights = lambda level, *rest: [(np.zeros(0, np.int64), np.zeros(0))] * level.dim


cutstrain.correction = correction
_el.StaggeredElasticity._divergence_load = _div


# LOADFIX=1: the quadrature loads' normal component at the ends of the moved a-lines reach the rows as
# the energy's uniaxial partition does: each end row's load scaled by 1 + alpha dw / V, alpha the mu
# share of a uniaxial sigma_aa (1 / (1 + nu))
_orig_load_vector = _el.StaggeredElasticity._load_vector


def _load_vector(self, points):
    f = _orig_load_vector(self, points)
    if not G["on"] or os.environ.get("LOADFIX") != "1":
        return f
    level = self.level
    lay = level.layout
    d, h = lay.dim, level.spacing
    cell = lay.dense(level.vc_host)
    box = cell.shape
    _, cen = G["moments"](G["origin"], h, box)
    alpha = 2 * (level.lam + level.mu) / (d * level.lam + 2 * level.mu) if d == 3 else 1.0
    eye = np.eye(d, dtype=int)
    for a in range(d):
        dw = pair_deltas(cell, cen)[(a, a)]
        idx = np.argwhere(dw != 0)
        for sign, face in ((1, eye[a]), (-1, 0 * eye[a])):
            nb = idx + sign * eye[a]
            ok = np.all((nb >= 0) & (nb < np.asarray(box)), axis=1)
            end = np.zeros(len(idx), bool)
            end[ok] = cell[tuple(nb[ok].T)] <= 0
            rows = lay.positions(idx[end] + face)
            good = rows >= 0
            I = idx[end][good]
            if not len(I):
                continue
            # the face's mean traction (a uniform one is exact) times the moved weight: nothing added in all
            t = f[a, rows[good]].sum() / (h ** (d - 1) * cell[tuple(I.T)].sum())
            f[a, rows[good]] += alpha * t * h ** (d - 1) * dw[tuple(I.T)]
    return f


_el.StaggeredElasticity._load_vector = _load_vector
