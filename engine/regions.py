"""Regions of space that boundary conditions select: which points they hold, which surface they cut.

The job spec names a region by its shape (``schemas.regions``). Here each shape becomes a small
object with ``contains(points)`` (displacement conditions select material sample points) and
``clip(facets)`` (traction and pressure act on the part of the surface inside the region).
Box and half-space are intersections of half-spaces, so their clipping is exact (Sutherland-
Hodgman, one plane at a time). A ball is not polyhedral: its clipping subdivides facets until a
piece is provably inside or outside, or smaller than ``tolerance``, and then decides a piece by its
centroid; the area it can misassign is bounded by ``tolerance`` times the length of the patch rim.
Membership is closed: points on the boundary are inside (a fixed face lying exactly on a box face
is selected). Clipping by planes is closed to within a round-off tolerance: surfaces that come out of
hex slicing sit up to ~1e-13 relative off the mesh's own planes, and a face that a user put exactly
on a region's plane must still be selected whole.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import VoxelasticError
from .subdivision import split_facets


ROUNDOFF = 1e-10  # relative: slicing round-off is ~1e-14, real geometry (>= 1e-6 of a cell) is far above


@dataclass(frozen=True)
class Halfspaces:
    """Intersection of half-spaces ``normals @ x <= offsets``; normals [p, d] unit, offsets [p] [m].

    No half-spaces at all is the whole space (the ``all`` region)."""

    normals: np.ndarray
    offsets: np.ndarray

    def contains(self, points: np.ndarray, slack: float = 0.0) -> np.ndarray:
        """Points [n, d] inside (closed, widened by ``slack`` [m]) -> bool [n]."""
        points = np.asarray(points, dtype=float)
        if len(self.offsets) == 0:
            return np.ones(len(points), dtype=bool)
        return np.all(points @ self.normals.T <= self.offsets + slack, axis=1)

    def clip(self, facets: np.ndarray, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Exact parts of facets [N, d, d] (triangles / segments) inside: (pieces [M, d, d], source
        facet index [M]). Clipped triangles are fan-triangulated; orientation is kept. Vertices within
        ``tolerance`` [m] of a plane count as on it (default ``ROUNDOFF`` times the largest coordinate
        or offset), so nothing is cut off or dropped by round-off alone."""
        facets = np.asarray(facets, dtype=float)
        if tolerance is None:
            scale = max(np.abs(facets).max(initial=0.0), np.abs(self.offsets).max(initial=0.0))
            tolerance = ROUNDOFF * max(scale, np.finfo(float).tiny)
        # Most facets lie wholly inside or wholly outside some plane: only the rest are cut one by one.
        side = facets @ self.normals.T - self.offsets  # [N, vertices, planes]
        side = np.where(np.abs(side) <= tolerance, 0.0, side)
        whole = np.all(side <= 0, axis=(1, 2))
        cut = ~whole & ~np.any(np.all(side > 0, axis=1), axis=1)
        if not cut.any():
            return facets[whole], np.nonzero(whole)[0]
        pieces, source = self._clip_each(facets[cut], np.nonzero(cut)[0], tolerance)
        pieces = np.concatenate([facets[whole], pieces])
        source = np.concatenate([np.nonzero(whole)[0], source])
        order = np.argsort(source, kind="stable")  # in facet order, as if each had been cut
        return pieces[order], source[order]

    def _clip_each(self, facets: np.ndarray, index: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`clip` facet by facet, plane by plane (facets [N, d, d] numbered by ``index`` [N])."""
        d = facets.shape[-1]
        poly = [facets[i] for i in range(len(facets))]
        source = [int(i) for i in index]
        for n, c in zip(self.normals, self.offsets):
            kept_poly, kept_source = [], []
            for p, s in zip(poly, source):
                q = _clip_polygon(p, n, c, tolerance) if d == 3 else _clip_segment(p, n, c, tolerance)
                if q is not None:
                    kept_poly.append(q)
                    kept_source.append(s)
            poly, source = kept_poly, kept_source
        if d == 2:
            pieces = np.array(poly).reshape(-1, 2, 2)
            return pieces, np.asarray(source, dtype=np.int64)
        tris, owner = [], []
        for p, s in zip(poly, source):
            for k in range(1, len(p) - 1):
                tris.append((p[0], p[k], p[k + 1]))
                owner.append(s)
        return np.array(tris).reshape(-1, 3, 3), np.asarray(owner, dtype=np.int64)


@dataclass(frozen=True)
class Ball:
    """|x - center| <= radius; center [d] [m], radius [m]."""

    center: np.ndarray
    radius: float

    def contains(self, points: np.ndarray, slack: float = 0.0) -> np.ndarray:
        points = np.asarray(points, dtype=float)
        return np.linalg.norm(points - self.center, axis=1) <= self.radius + slack

    def clip(self, facets: np.ndarray, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Parts of facets [N, d, d] inside, to within ``tolerance`` [m] (default radius / 1000):
        pieces [M, d, d] and their source facet [M]."""
        facets = np.asarray(facets, dtype=float)
        tol = self.radius * 1e-3 if tolerance is None else float(tolerance)
        if not tol > 0:
            raise ValueError(f"tolerance must be positive, got {tolerance}")
        pieces, owner = [], []
        todo, source = facets, np.arange(len(facets))
        while len(todo):
            dist = np.linalg.norm(todo - self.center, axis=2)  # [n, d] corner distances
            inside = np.all(dist <= self.radius, axis=1)  # convex region: all corners in -> all in
            centroid = todo.mean(axis=1)
            reach = np.linalg.norm(todo - centroid[:, None, :], axis=2).max(axis=1)
            outside = np.linalg.norm(centroid - self.center, axis=1) - reach > self.radius
            small = ~inside & ~outside & (reach <= tol)
            take = inside | (small & self.contains(centroid))
            pieces.append(todo[take])
            owner.append(source[take])
            split = ~inside & ~outside & ~small
            todo, parent = split_facets(todo[split])
            source = source[split][parent]
        d = facets.shape[-1]
        # no facets at all (a facing filter that keeps none) leaves the loop unrun
        return (np.concatenate([np.empty((0, d, d)), *pieces]).reshape(-1, d, d),
                np.concatenate([np.empty(0, dtype=np.int64), *owner]).astype(np.int64))


Region = Halfspaces | Ball


def make_region(spec, dim: int) -> Region:
    """The region of a job-spec region model (``schemas.regions``) in ``dim`` dimensions."""
    if getattr(spec, "box", None) is not None:
        lo, hi = (np.asarray(v, dtype=float) for v in spec.box)
        eye = np.eye(dim)
        return Halfspaces(np.concatenate([eye, -eye]), np.concatenate([hi, -lo]))
    if getattr(spec, "sphere", None) is not None:
        return Ball(np.asarray(spec.sphere.center, dtype=float), float(spec.sphere.radius))
    if getattr(spec, "halfspace", None) is not None:
        n = np.asarray(spec.halfspace.normal, dtype=float)
        n = n / np.linalg.norm(n)
        return Halfspaces(n[None, :], np.array([n @ np.asarray(spec.halfspace.point, dtype=float)]))
    if getattr(spec, "all", None):
        return Halfspaces(np.zeros((0, dim)), np.zeros(0))
    raise VoxelasticError(f"region: unknown shape {spec!r}")


def _side(p: np.ndarray, normal: np.ndarray, offset: float, tolerance: float) -> np.ndarray:
    """Signed distances [k] of points p [k, d] to the plane, snapped to 0 within ``tolerance``."""
    side = p @ normal - offset
    return np.where(np.abs(side) <= tolerance, 0.0, side)


def _clip_polygon(p: np.ndarray, normal: np.ndarray, offset: float, tolerance: float) -> np.ndarray | None:
    """Planar polygon p [k, 3] cut to normal . x <= offset (None when nothing is left)."""
    side = _side(p, normal, offset, tolerance)
    if np.all(side <= 0):
        return p
    if np.all(side > 0):
        return None
    out = []
    for i in range(len(p)):
        a, b, sa, sb = p[i], p[(i + 1) % len(p)], side[i], side[(i + 1) % len(p)]
        if sa <= 0:
            out.append(a)
        if (sa <= 0) != (sb <= 0):
            out.append(a + (b - a) * (sa / (sa - sb)))
    return np.array(out) if len(out) >= 3 else None


def _clip_segment(p: np.ndarray, normal: np.ndarray, offset: float, tolerance: float) -> np.ndarray | None:
    sa, sb = _side(p, normal, offset, tolerance)
    if sa <= 0 and sb <= 0:
        return p
    if sa > 0 and sb > 0:
        return None
    cut = p[0] + (p[1] - p[0]) * (sa / (sa - sb))
    return np.array([p[0], cut]) if sa <= 0 else np.array([cut, p[1]])
