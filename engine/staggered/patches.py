"""Vertex-patch smoothing (additive Schwarz) for the staggered operator near incompressibility.

The operator's lambda (div u)^2 term makes A nearly singular on divergence-free fields: point
smoothers (Jacobi, the Chebyshev polynomials of D^-1 A) cannot reduce errors there and the V-cycle
stalls as nu -> 1/2. Exact solves on the patches of faces around each grid vertex (``m = d 2^(d-1)``
faces: 4 in 2D, 12 in 3D) contain a local basis of the divergence-free fields (discrete curls), so
M^-1 = sum_V R_V^T (R_V A R_V^T)^-1 R_V smooths them as well as the rest (Schoeberl 1999; Arnold,
Falk & Winther 2000). It is symmetric, so Chebyshev iteration on M^-1 A keeps the V-cycle a CG
preconditioner; the coarse levels must then receive the divergence unchanged
(``kernels.FACE`` transfers).

Storage: a vertex whose patch sees only weights 1 (cells and edges full, every face free, no
surface term, uniform mass) shares one inverse per level; only the others (near cut cells, holds
and ghosts) store their own [m, m] inverse. ``VertexPatches.bytes`` says how much that is.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.ndimage as ndi

from ..runtime import device_array
from . import patch_kernels
from .operator import Level
from .patch_kernels import _code, _corners, _cube, _edge_terms, _patch_dofs, _slot

CHUNK = 65_536  # vertices per pass of the host assembly (~75 MB of [m, m] blocks in 3D)


class VertexPatches:
    """The additive Schwarz operator M^-1 of ``level`` (its unknowns, shift and surface terms as
    they are now: build a new one after they change)."""

    def __init__(self, level: Level) -> None:
        self.level = level
        d, lay = level.dim, level.layout
        self.m = d * 2 ** (d - 1)
        dofs = patch_kernels._patch_dofs(d)
        has, bad = self._vertices()
        custom = np.nonzero(has & bad)[0].astype(np.int32)
        plain = np.nonzero(has & ~bad)[0]
        # the shared inverse: the matrix of any vertex that needs no inverse of its own
        listed = np.concatenate([plain[:1], custom]).astype(np.int32)
        mats = self._matrices(listed)
        if len(plain):
            reference = mats[0]
        else:
            reference = np.eye(self.m)
        mats = mats[1:] if len(plain) else mats
        if level.surface is not None and len(custom):
            mats = self._with_surface(mats, custom, dofs)
        self.custom = len(custom)
        inv = np.concatenate([_inverse(reference[None]), _inverse(mats)]) if len(custom) else _inverse(reference[None])
        cmap = np.zeros(level.size, dtype=np.int32)
        cmap[custom] = np.arange(1, len(custom) + 1, dtype=np.int32)
        self.cmap = device_array(cmap)
        self.inv = device_array(inv, level.dtype)
        self.bytes = int(inv.size * np.dtype(level.dtype).itemsize + cmap.nbytes)

    def _vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """(has [size], bad [size]) over flat positions: vertices whose patch holds a free DOF, and
        those whose patch matrix differs from the shared one (a weight other than 1, a masked or
        surface DOF, a non-uniform mass within the 3^d block around the vertex)."""
        level, lay, d = self.level, self.level.layout, self.level.dim
        n = lay.count * lay.tile_size
        free = level.free
        # the patch of V holds the a-faces V - o (o_a = 0): the DOF at p is in the patches p + o
        has = np.zeros(lay.box, dtype=bool)
        for a in range(d):
            f = lay.dense(free[a].astype(np.uint8)) > 0
            for o in itertools.product((0, 1), repeat=d):
                if o[a] == 0:
                    has |= _shifted(f, o)
        # "good": every weight 1, every face free (outside the kept tiles nothing is good)
        good = (level.vc_host == 1.0) & np.all(level.ve_host == 1.0, axis=0) & np.all(free, axis=0)
        if level.shift != 0.0:
            good &= np.all(level.vf_host == 1.0, axis=0)
            if level.ghost_inertia is not None:
                good &= np.all(level.ghost_inertia == 0.0, axis=0)
        if level.surface is not None:
            good[level.surface.pos] = False
        dense = lay.dense(good.astype(np.uint8))
        for a in range(d):
            dense = ndi.minimum_filter1d(dense, 3, axis=a, mode="constant")
        flat_has = lay.flat(has.astype(np.uint8)) > 0
        flat_bad = lay.flat(dense) == 0
        flat_has[n:] = False
        return flat_has, flat_bad

    def _matrices(self, verts: np.ndarray) -> np.ndarray:
        """[len(verts), m, m] the patch blocks of K + shift M (f64, host), in chunks."""
        out = np.zeros((len(verts), self.m, self.m))
        for start in range(0, len(verts), CHUNK):
            part = slice(start, start + CHUNK)
            out[part] = patch_matrices(self.level, verts[part])
        return out

    def _with_surface(self, mats: np.ndarray, verts: np.ndarray, dofs) -> np.ndarray:
        """``mats`` plus the surface terms' S between the free patch DOFs they touch."""
        level, lay = self.level, self.level.layout
        sf = level.surface
        size = level.size
        S = sf.matrix().tocsr()
        keys = sf.comp.astype(np.int64) * size + sf.pos
        order = np.argsort(keys)
        index = np.full((len(verts), self.m), -1, dtype=np.int64)
        for a, o, s in dofs:
            pos = lay.positions(lay.indices()[verts] - np.asarray(o))
            key = a * size + np.maximum(pos, 0)
            k = np.minimum(np.searchsorted(keys[order], key), len(keys) - 1)
            hit = (pos >= 0) & (keys[order][k] == key) & level.free[a, np.maximum(pos, 0)]
            index[:, s] = np.where(hit, order[k], -1)
        for i, j in itertools.product(range(self.m), repeat=2):
            on = (index[:, i] >= 0) & (index[:, j] >= 0)
            if on.any():
                mats[on, i, j] += np.asarray(S[index[on, i], index[on, j]]).ravel()
        return mats

    def apply(self, mode: int, r, x, step, c1: float, c2: float) -> None:
        """``patch_kernels.schwarz_step`` on this level (see there for the modes)."""
        lv = self.level
        patch_kernels.schwarz_step(lv.dim, mode, lv.layout.count * lv.layout.tile_size, lv.nbr, self.cmap,
                                   self.inv, lv.mask, r, x, step, c1, c2)


def patch_matrices(level: Level, verts: np.ndarray) -> np.ndarray:
    """[n, m, m] the block of K + shift M (f64) on the patch of each vertex at the flat positions
    ``verts`` [n]; a slot whose face is not free gets a unit row and column. Cell terms: the 2^d
    cells V - o, each reading one face per component (-1/h at its low face, +1/h at its high face):
    h^{d-2} Vc (2 mu delta_ab + lambda) s_a s_b; shear terms: the edges (a, b) whose stencil reads a
    patch face (``patch_kernels._edge_terms``), h^{d-2} mu Ve c_i c_j."""
    d, lay = level.dim, level.layout
    m = d * 2 ** (d - 1)
    index = lay.indices()[verts]
    near = {}
    for o in _cube(d):
        pos = lay.positions(index + np.asarray(o))
        near[_code(d, o)] = (np.maximum(pos, 0), pos >= 0)

    def read(values: np.ndarray, o: tuple[int, ...]) -> np.ndarray:
        pos, kept = near[_code(d, o)]
        return np.where(kept, values[pos], 0.0)

    scale = level.spacing ** (d - 2)
    lam, mu = level.lam, level.mu
    out = np.zeros((len(verts), m, m))
    for o in _corners(d):
        w = scale * read(level.vc_host, tuple(-x for x in o))
        for a, b in itertools.product(range(d), repeat=2):
            ia = _slot(d, a, tuple(0 if k == a else x for k, x in enumerate(o)))
            ib = _slot(d, b, tuple(0 if k == b else x for k, x in enumerate(o)))
            sign = (1.0 if o[a] else -1.0) * (1.0 if o[b] else -1.0)
            out[:, ia, ib] += w * (sign * (lam + (2.0 * mu if a == b else 0.0)))
    for q in range(len(level.ve_host)):
        for offset, taps in _edge_terms(d, q):
            w = (scale * mu) * read(level.ve_host[q], offset)
            for (si, ci), (sj, cj) in itertools.product(taps, repeat=2):
                out[:, si, sj] += w * (ci * cj)
    mass = level.mass.to_numpy() if (level.shift != 0.0 and level.mass is not None) else None
    for a, o, s in _patch_dofs(d):
        back = tuple(-x for x in o)
        if mass is not None:
            out[:, s, s] += level.shift * read(mass[a], back)
        masked = read(level.free[a].astype(np.float64), back) == 0
        out[masked, s, :] = 0.0
        out[masked, :, s] = 0.0
        out[masked, s, s] = 1.0
    return out


def _shifted(a: np.ndarray, offset: tuple[int, ...]) -> np.ndarray:
    """out[I] = a[I - offset] (False beyond the box)."""
    out = np.zeros_like(a)
    dst = tuple(slice(o, None) for o in offset)
    src = tuple(slice(0, n - o) for o, n in zip(offset, a.shape))
    out[dst] = a[src]
    return out


def _inverse(mats: np.ndarray) -> np.ndarray:
    """Batched inverse of symmetric blocks [n, m, m]; a singular block (a piece of material the
    patch holds entirely, free to move rigidly) gets its pseudo-inverse."""
    try:
        return np.linalg.inv(mats)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(mats, hermitian=True)
