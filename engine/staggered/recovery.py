"""Strain where it is asked for: a weighted linear fit of the cell-centre strains around a point.

The staggered strains live at cell centres (normal strains from the cell's faces, shear strains
the fraction-weighted mean of its edges): second order there, but a probe that took its cell's
value was h/2 off, first order. Here each point gets the linear least-squares fit of the strains
of the 4^d cells whose centres lie within 2h along every axis, weighted by a quadratic B-spline
of the distance (so the fit moves smoothly with the point) times the cell's trust (its solid
fraction: a sliver's strain is barely determined by the energy). A linear fit reproduces linear
strain fields exactly, so the value is second order inside the body; at the surface it is a
one-sided fit from the cells that hold material, which is what the surface stress starts from.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..blas import on_one_thread
from ..grid import Grid

SUPPORT = 2.0  # kernel half-width, cells: 4 cell centres per axis around every point
CHUNK = 8_192  # points per pass: ~70 MB of temporaries in 3D (4^3 neighbours, 4 x 4 normal equations)
MIN_TRUST = 1e-12  # a cell holding less than this fraction takes no part


def fit_strain(grid: Grid, strain: np.ndarray, trust: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Strain [P, c] at points [P, d] [m] fitted from cell values ``strain`` [*grid.shape, c]
    (any per-cell quantity; NaN cells are skipped) with per-cell ``trust`` [*grid.shape] in [0, 1].
    Points with no trusted cell within reach get NaN; with too few for a linear fit (a thin part,
    a corner), the weighted mean."""
    d = grid.dim
    points = np.asarray(points, dtype=float).reshape(-1, d)
    values = np.asarray(strain, dtype=float)
    c = values.shape[d:]
    flat = values.reshape(values.shape[:d] + (-1,))
    ok = np.isfinite(flat).all(axis=-1) & (trust > MIN_TRUST)
    shape = np.asarray(grid.shape)
    offsets = np.array(list(itertools.product(range(-1, 3), repeat=d)), dtype=np.int64)  # [4^d, d]
    out = np.full((len(points), flat.shape[-1]), np.nan)
    origin, h = np.asarray(grid.origin, dtype=float), grid.spacing
    for start in range(0, len(points), CHUNK):
        x = (points[start:start + CHUNK] - origin) / h - 0.5  # in cell-centre index units
        base = np.floor(x).astype(np.int64)
        cells = base[:, None, :] + offsets[None]  # [N, K, d]
        inside = np.all((cells >= 0) & (cells < shape), axis=2)
        safe = np.where(inside[..., None], cells, 0)
        idx = tuple(safe[..., k] for k in range(d))
        usable = inside & ok[idx]
        rel = cells - x[:, None, :]  # [N, K, d], cell centre minus point, in cells
        weight = np.prod(_bspline(rel / SUPPORT), axis=2) * np.where(usable, trust[idx], 0.0)
        v = np.where(usable[..., None], flat[idx], 0.0)  # [N, K, c]
        out[start:start + CHUNK] = _linear_fit(rel, weight, v)
    return out.reshape((len(points),) + c)


def _bspline(t: np.ndarray) -> np.ndarray:
    """Quadratic B-spline of support |t| < 1 (scaled to 1 at 0)."""
    a = np.abs(t)
    return np.where(a < 1 / 3, 1 - 3 * a**2, np.where(a < 1, 1.5 * (1 - a) ** 2, 0.0))


@on_one_thread
def _linear_fit(rel: np.ndarray, weight: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Value at rel = 0 of the weighted least-squares linear fit, per point: rel [N, K, d],
    weight [N, K], values [N, K, c] -> [N, c]; the weighted mean where the fit is degenerate."""
    n, k, d = rel.shape
    basis = np.concatenate([np.ones((n, k, 1)), rel], axis=2)  # [N, K, d + 1]
    wbt = (basis * weight[..., None]).swapaxes(1, 2)  # [N, d + 1, K]
    # batched matmuls, not einsums: 0.29-0.58 -> 0.10 s for 30k points of 64 neighbours (docs/benchmarks.md)
    normal = wbt @ basis  # [N, d+1, d+1]
    rhs = wbt @ values
    total = weight.sum(axis=1)
    mean = rhs[:, 0] / np.where(total > 0, total, 1.0)[:, None]  # row 0 of wb^T v is sum_k w v
    # a fit is kept where the normal matrix is well conditioned relative to its size
    scale = np.maximum(np.abs(normal).max(axis=(1, 2)), 1e-300)
    eig = np.linalg.eigvalsh(normal / scale[:, None, None])
    good = (total > 0) & (eig[:, 0] > 1e-6)
    out = np.where(total[:, None] > 0, mean, np.nan)
    if good.any():
        sol = np.linalg.solve(normal[good], rhs[good])  # [G, d+1, c]
        out[good] = sol[:, 0, :]
    return out
