"""Hybrid smoothing for the staggered operator near incompressibility: Jacobi on the faces plus
Jacobi on the discrete curls (Hiptmair 1997; Arnold, Falk & Winther 2000).

The lambda (div u)^2 term leaves the divergence-free fields nearly unpenalised: a point smoother
reduces their errors only by the small mu part of the diagonal, and the V-cycle stalls as
nu -> 1/2. The discrete curls of the edge potentials (3D; node stream functions in 2D) are
divergence-free in every cell, four faces each, and span the divergence-free fields locally, so

    M^-1 = D^-1 + C Theta^-1 C^T,   Theta = diag(C^T A C)

smooths them at the mu scale while D^-1 handles the rest. M is symmetric: Chebyshev iteration on
M^-1 A keeps the V-cycle a CG preconditioner. An exact solve on the 12 faces around every vertex
(additive Schwarz; the classical robust smoother, Schoeberl 1999) reached the same iteration
counts at 3.3 operator applies per step and 84 MB of patch inverses on the 64^3 shell; this costs
about one apply and two edge arrays (docs/design-notes.md). Beside held surfaces the curls are
stiff (held cells weigh another divergence), so there, and only there, those vertex patches' exact
solves are added to M^-1 (``patches.py``).
"""

from __future__ import annotations

import itertools

import numpy as np

from ..runtime import device_array, device_zeros
from . import kernels, smoother_kernels
from .patches import band_inverse
from .operator import Level
from .smoother_kernels import PAIRS, curl_taps


class CurlSmoother:
    """M^-1 of ``level`` for its unknowns, shift and surface terms as they are now (build a new one
    after they change). ``apply(mode, r, x, step, c1, c2)``: see ``smoother_kernels.hybrid_step``."""

    def __init__(self, level: Level) -> None:
        self.level = level
        d, lay = level.dim, level.layout
        self.n = lay.count * lay.tile_size
        pairs = len(PAIRS[d])
        theta = device_zeros((pairs, level.size), np.float64)
        mass = level.mass if level.mass is not None else level.mask
        smoother_kernels.curl_diagonal(d, self.n, level.nbr, level.vc, level.ve, level.mask, mass, level.shift,
                                       level.lam, level.mu, level.spacing ** (d - 2), theta)
        theta = theta.to_numpy()
        if level.surface is not None:
            theta += self._surface_part()
        inv = np.where(theta > 0, 1.0 / np.where(theta > 0, theta, 1.0), 0.0)
        inv[:, self.n :] = 0.0
        self.inv_theta = device_array(inv, level.dtype)
        self.t = device_zeros((pairs, level.size), level.dtype)
        self.band = None
        band = band_inverse(level)
        if band is not None:
            comp, pos, z = band
            self.band = (device_array(comp.astype(np.int32)), device_array(pos.astype(np.int32)),
                         device_array(z.indptr.astype(np.int32)), device_array(z.indices.astype(np.int32)),
                         device_array(z.data, np.float64))
            self.band_in, self.band_out = device_zeros((len(comp),), np.float64), device_zeros((len(comp),), np.float64)

    def _surface_part(self) -> np.ndarray:
        """[pairs, size] c^T S c of the curls that touch the surface terms' DOFs (free ones only)."""
        level, lay, d = self.level, self.level.layout, self.level.dim
        sf = level.surface
        S = sf.matrix().tocsr()
        size = level.size
        keys = sf.comp.astype(np.int64) * size + sf.pos
        order = np.argsort(keys)
        index = lay.indices()
        out = np.zeros((len(PAIRS[d]), size))
        for q in range(len(PAIRS[d])):
            taps = curl_taps(d, q)
            # the edges whose curl reads a surface DOF: E = I - offset for a tap (k, offset) and DOF (k, I)
            edges = np.unique(np.concatenate([lay.positions(index[sf.pos[sf.comp == k]] - np.asarray(o))
                                              for k, o, _ in taps]))
            edges = edges[(edges >= 0) & (edges < self.n)]
            if not len(edges):
                continue
            at = np.full((len(edges), len(taps)), -1, dtype=np.int64)
            for i, (k, o, _) in enumerate(taps):
                pos = lay.positions(index[edges] + np.asarray(o))
                key = k * size + np.maximum(pos, 0)
                j = np.minimum(np.searchsorted(keys[order], key), len(keys) - 1)
                hit = (pos >= 0) & (keys[order][j] == key) & level.free[k, np.maximum(pos, 0)]
                at[:, i] = np.where(hit, order[j], -1)
            total = np.zeros(len(edges))
            for (i, ti), (j, tj) in itertools.product(enumerate(taps), repeat=2):
                on = (at[:, i] >= 0) & (at[:, j] >= 0)
                if on.any():
                    total[on] += ti[2] * tj[2] * np.asarray(S[at[on, i], at[on, j]]).ravel()
            out[q, edges] = total
        return out

    def apply(self, mode: int, r, x, step, c1: float, c2: float) -> None:
        """z = mask (D^-1 r + C Theta^-1 C^T r), then ``mode`` (START, STEP, APPLY of
        ``smoother_kernels``) with x, step and the Chebyshev coefficients c1, c2."""
        lv = self.level
        if self.band is not None:  # Z r before the step writes x
            comp, pos, indptr, indices, data = self.band
            kernels.gather(r, comp, pos, self.band_in)
            kernels.csr_apply(indptr, indices, data, self.band_in, self.band_out, 0)
        smoother_kernels.curl_residual(lv.dim, self.n, lv.nbr, r, self.inv_theta, self.t)
        smoother_kernels.hybrid_step(lv.dim, mode, self.n, lv.nbr, lv.dinv, lv.mask, r, self.t, x, step,
                                     float(c1), float(c2))  # numpy scalars defeat the launcher's argument cache
        if self.band is not None:
            smoother_kernels.band_add(mode, comp, pos, self.band_out, lv.mask, float(c2), step, x)
