"""Whether points lie in the solid, decided from its surface alone: what every method's probes go by.

A point is in the solid when the surface's winding number says so or when it lies on the surface
up to round-off (:func:`surface_tolerance`): a probe given at a mesh vertex, on an edge or a face
(where the winding number is 1/2, or 1/8 at a cube's corner) samples the solid. Everything else is
outside, however close to the material a method's samples reach: a probe 0.05 m beyond a cube's
face used to read the staggered displacement of the face's own samples, half a vector and no warning.
"""

from __future__ import annotations

import numpy as np

from .surface import Surface, point_triangle_distance
from .winding import inside

# A point this close to the surface is on it: the mesh's own vertices and face points given as
# probes, up to the round-off of placing and scaling them (ON_SURFACE cells) and of the file's
# numbers (ROUND_OFF of the part's size: a float32 STL stores 0.65 as 0.64999998)
ON_SURFACE = 1e-9
ROUND_OFF = 1e-6
# faces whose bounding boxes are tested against a point at once: bounds the [faces, d] temporaries
_FACE_CHUNK = 1 << 20


def surface_tolerance(surface: Surface, spacing: float) -> float:
    """Distance [m] within which a point counts as on ``surface`` on a grid of cell size ``spacing`` [m]."""
    lower, upper = surface.bounds
    return max(ON_SURFACE * spacing, ROUND_OFF * float(np.linalg.norm(upper - lower)))


def in_solid(surface: Surface, points: np.ndarray, spacing: float) -> np.ndarray:
    """bool [N]: which ``points`` [N, d] [m] lie in the solid bounded by ``surface``, points on it
    within :func:`surface_tolerance` included."""
    points = np.asarray(points, dtype=float).reshape(-1, surface.dim)
    out = np.zeros(len(points), dtype=bool)
    if not len(points):
        return out
    tol = surface_tolerance(surface, spacing)
    lower, upper = surface.bounds
    near = np.all((points >= lower - tol) & (points <= upper + tol), axis=1)
    if np.any(near):
        out[near] = inside(surface.vertices, surface.faces, points[near])
    for i in np.nonzero(near & ~out)[0]:
        out[i] = surface_distance(surface, points[i], tol) <= tol
    return out


def surface_distance(surface: Surface, point: np.ndarray, reach: float = np.inf) -> float:
    """Distance [m] from ``point`` [d] to ``surface``; inf when no face comes within ``reach`` [m]
    (only faces whose bounding box does are measured)."""
    point = np.asarray(point, dtype=float)
    best = np.inf
    faces = np.asarray(surface.faces)
    for start in range(0, len(faces), _FACE_CHUNK):
        corners = surface.vertices[faces[start:start + _FACE_CHUNK]]  # [F, d, d]
        close = np.all((corners.min(axis=1) - reach <= point) & (point <= corners.max(axis=1) + reach), axis=1)
        if not np.any(close):
            continue
        if surface.dim == 3:
            gap = point_triangle_distance(point, corners[close])
        else:
            gap = _segment_distance(point, corners[close])
        best = min(best, float(gap.min()))
    return best


def _segment_distance(p: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distances [S] from point p [2] to segments [S, 2, 2]."""
    a, b = segments[:, 0], segments[:, 1]
    ab = b - a
    length2 = np.einsum("sd,sd->s", ab, ab)
    t = np.clip(np.einsum("sd,sd->s", p - a, ab) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ab - p, axis=1)
