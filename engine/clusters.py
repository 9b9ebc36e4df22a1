"""Quadrature on surfaces finer than the grid: small pieces merged into clusters (for engine.boundary).

A scanned or finely tessellated mesh puts dozens of triangles in every grid cell, and a rule per
triangle makes the surface terms' cost follow the triangle count, not the grid: a 327,680-triangle
sphere at resolution 48 spent 30 of its 36 s in them, most of it in the coarse multigrid levels'
hold terms, which took the fine level's 1.8 M points each. Where a coarse rule will do, pieces much
smaller than the spacing are therefore merged per cluster: a cube of side ``size``, and normals
within about NORMAL_STEP of each other, so that a sharp edge or the two sides of a thin wall never
share one. Each cluster gets the 2 (d - 1) point rule that matches its measure, centroid and second
moments in its tangent plane: points at the centroid +- sqrt(d - 1) sigma_k along the principal axes
of the second moment (the unscented rule; for a single straight segment it is 2-point Gauss).
Integrands smooth on the cluster's scale are integrated to third order in its size. The measure,
the first moments and the area vector are exact: a constant traction keeps its resultant and
moment, a pressure on a closed surface stays in balance. The cluster's normal is its area vector
over its measure, unit to O((size * curvature)^2).
"""

from __future__ import annotations

import numpy as np

# normals are binned by their components on this step: pieces in one cluster differ by < ~5 degrees
NORMAL_STEP = 0.05


def clustered_rule(facets: np.ndarray, measure: np.ndarray, normals: np.ndarray,
                   size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature of small surface pieces ``facets`` [M, d, d] (measures [M] > 0 [m^2 | m], unit
    outward normals [M, d]) merged into clusters of side ``size`` [m]. Returns points [Q, d] [m],
    weights [Q] summing to the pieces' total measure, and outward normals [Q, d] (each cluster's
    area vector over its measure)."""
    m, d = facets.shape[0], facets.shape[2]
    if m == 0:
        return np.zeros((0, d)), np.zeros(0), np.zeros((0, d))
    centre = facets.mean(axis=1)  # [M, d]
    key = np.concatenate([np.floor(centre / size), np.round(normals / NORMAL_STEP)], axis=1).astype(np.int64)
    key -= key.min(axis=0)
    dims = key.max(axis=0) + 1
    if np.prod(dims.astype(float)) < 2.0**62:  # one 1D sort of linear keys (rows sort as bytes: 1.1 s at 1.3 M)
        _, group = np.unique(np.ravel_multi_index(tuple(key.T), tuple(int(n) for n in dims)), return_inverse=True)
    else:
        _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.ravel()
    count = int(group.max()) + 1
    area = np.bincount(group, weights=measure, minlength=count)
    mean = np.stack([np.bincount(group, weights=measure * centre[:, k], minlength=count) for k in range(d)], 1)
    mean /= area[:, None]
    vector = np.stack([np.bincount(group, weights=measure * normals[:, k], minlength=count) for k in range(d)], 1)
    normal = vector / area[:, None]  # not normalised: the area vector stays exact (free bodies' balance)
    # second moment about the cluster's centroid: each simplex's own (measure / (d (d + 1)) times the
    # sum of its vertices' outer products about its centroid) plus its centroid's offset
    spread = facets - centre[:, None, :]
    own = np.einsum("m,mki,mkj->mij", measure / (d * (d + 1)), spread, spread)
    off = centre - mean[group]
    moment = (own + measure[:, None, None] * off[:, :, None] * off[:, None, :]).reshape(m, d * d)
    second = np.stack([np.bincount(group, weights=moment[:, k], minlength=count) for k in range(d * d)], 1)
    second = second.reshape(count, d, d)
    # in the tangent plane only: a curved cluster's spread along its normal would take points off it
    unit = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    tangent = np.eye(d)[None] - unit[:, :, None] * unit[:, None, :]
    second = tangent @ second @ tangent / area[:, None, None]
    value, axis = np.linalg.eigh(second)  # ascending: the first is the normal's (zero)
    arm = np.sqrt(np.clip(value[:, 1:], 0.0, None) * (d - 1))[:, None, :] * axis[:, :, 1:]  # [G, d, d - 1]
    arms = np.concatenate([arm, -arm], axis=2).transpose(0, 2, 1)  # [G, 2 (d - 1), d]
    per = arms.shape[1]
    points = (mean[:, None, :] + arms).reshape(-1, d)
    return points, np.repeat(area / per, per), np.repeat(normal, per, axis=0)
