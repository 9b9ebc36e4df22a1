"""Prototype: the energy's control-volume weights moved toward each cut volume's solid centroid
(first moments kept, KEEP floor), by replacing the cell and edge fractions the operator weighs."""
import sys, os
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "cut_cell_centroids"))
import numpy as np
from engine import pipeline as _pl
from engine.geometry.fractions import volume_fractions as _vf
from engine.grid import Grid

KEEP = float(os.environ.get("KEEP", "0.25"))   # least share a box keeps of its own weight


def fitted(V, cen, tol=1e-12):
    """weights [box] from fractions V [box] and centroid offsets cen [box, d] (units h)."""
    d = V.ndim
    cut = (V > tol) & (V < 1 - tol)
    t = np.zeros(V.shape + (d,))
    for k in range(d):
        m = cen[..., k]
        t[..., k] = np.where(cut, V * np.abs(m), 0.0)
        # receiver must hold weight
        for sgn in (1, -1):
            recv = np.zeros(V.shape, bool)
            sl_src = [slice(None)] * d; sl_dst = [slice(None)] * d
            if sgn > 0:
                sl_src[k] = slice(0, -1); sl_dst[k] = slice(1, None)
            else:
                sl_src[k] = slice(1, None); sl_dst[k] = slice(0, -1)
            recv[tuple(sl_src)] = V[tuple(sl_dst)] > tol
            side = (m > 0) if sgn > 0 else (m < 0)
            t[..., k] = np.where(side & ~recv, 0.0, t[..., k])
    tot = t.sum(-1)
    cap = (1 - KEEP) * V
    scale = np.where(tot > cap, cap / np.maximum(tot, 1e-300), 1.0)
    t *= scale[..., None]
    w = V - t.sum(-1)
    for k in range(d):
        m = cen[..., k]
        for sgn in (1, -1):
            side = (m > 0) if sgn > 0 else (m < 0)
            give = np.where(side, t[..., k], 0.0)
            sl_src = [slice(None)] * d; sl_dst = [slice(None)] * d
            if sgn > 0:
                sl_src[k] = slice(0, -1); sl_dst[k] = slice(1, None)
            else:
                sl_src[k] = slice(1, None); sl_dst[k] = slice(0, -1)
            w[tuple(sl_dst)] += give[tuple(sl_src)]
    return w


MODE = {"centroids": None, "edges": os.environ.get("EDGES", "1") == "1"}


def box_centroids(lo, hi):
    import cutstrain
    def f(grid, s):
        org = np.asarray(grid.origin) - 0.5 * grid.spacing * np.asarray(s)
        shape = tuple(n + o for n, o in zip(grid.shape, s))
        V, cen = cutstrain.box_moments(lo, hi)(org, grid.spacing, shape)
        return cen
    return f


def sliced_centroids(surface):
    import cutstrain
    from engine.geometry.slicing import slice_cells
    def f(grid, s):
        org = np.asarray(grid.origin) - 0.5 * grid.spacing * np.asarray(s)
        shape = tuple(n + o for n, o in zip(grid.shape, s))
        g2 = Grid(origin=tuple(org), spacing=grid.spacing, shape=shape)
        V, cen, _ = cutstrain._box_moments(slice_cells(surface, g2, degree=2), shape)
        return cen
    return f


def _replace(fr, surface):
    grid = fr.grid
    d = grid.dim
    cf = MODE["centroids"] if MODE["centroids"] is not None else sliced_centroids(surface)
    kinds = [(0,) * d] + ([s for s in fr.control if sum(s) == 2] if MODE["edges"] else [])
    for s in kinds:
        bs = fr.control[s]
        V = bs.dense()
        cen = cf(grid, s)
        assert cen.shape[:d] == V.shape, (cen.shape, V.shape)
        W = np.where(V > 0, fitted(V, cen), 0.0)
        idx, _ = bs.nonzero()
        where = np.nonzero(bs.data)
        bs.data[where] = W[tuple(idx.T)]
    return fr


def install():
    _pl._GEOMETRY["fractions"] = ("fractions", lambda s, g: _replace(_vf(s, g), s))


from engine.staggered import operator as _op


def _snap(v):
    v[np.abs(v - 1.0) < _op.ROUNDOFF] = 1.0
    v[(v > 0) & (v < _op.MIN_FRACTION)] = _op.MIN_FRACTION
    return v


def _weights(fr):
    v = np.where(np.abs(fr - 1.0) < _op.ROUNDOFF, 1.0, fr)
    return np.where((v > 0) & (v < _op.MIN_FRACTION), _op.MIN_FRACTION, v)


_op._snap = _snap
_op.weights = _weights
