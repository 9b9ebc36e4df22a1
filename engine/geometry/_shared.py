"""Placement and sanity checks shared by 3D meshes (``loading``) and 2D polygons (``polygon``).

Kept apart from both so that ``loading`` can dispatch to ``polygon`` without a circular import.
Placement: ``x' = R (scale * x) + t`` -- the uniform scale first, then the rigid transform
(``transform`` = [[R, t], [0, 1]], 4x4 in 3D and 3x3 in 2D; R orthogonal).
"""

from __future__ import annotations

import numpy as np

from engine.errors import GeometryError
from engine.geometry.surface import Surface

# Relative tolerances: orthogonality of a transform's linear part (also the planarity of a
# drawing), and the enclosed volume (area) below which a surface counts as flat, relative to
# its bounding-box extent^d.
RIGID_TOL = 1e-9
FLAT_TOL = 1e-12
# Largest coordinate magnitude and smallest size after placement [m]: volumes, moments and the
# solvers' norms multiply coordinates (and their powers), which overflow or underflow float64 long
# before the coordinates do. The bundled bar solved to the same scaled answer (1e-11) at sizes of
# 1e-70 .. 1e70 m; at 1e80 m the strain fit overflowed (a LinAlgError), at 1e-80 m the boundary
# patches vanished ("the region holds no part of the mesh surface ... 0 m from the nearest vertex").
MAX_COORDINATE = 1e60
MIN_SIZE = 1e-60
# Farthest a part may lie from the origin, in multiples of its size: the grid, its samples and the
# boundary patches are computed in world coordinates, which keep 16 digits; a 1 m bar at 1e9 m came
# out 23% off (DG 5%) with no word, at 1e8 m within 1.2e-7
MAX_DISTANCE_OVER_SIZE = 1e7


def place(points: np.ndarray, scale: float, transform, name: str) -> tuple[np.ndarray, bool]:
    """x' = R (scale x) + t; returns (points [m, d], whether R mirrors)."""
    d = points.shape[1]
    if not (isinstance(scale, (int, float, np.number)) and np.isfinite(scale) and scale > 0):
        raise GeometryError(f"'{name}': scale must be a finite number > 0, got {scale!r}")
    points = points * float(scale)
    mirrored = False
    if transform is not None:
        try:
            m = np.array(transform, dtype=np.float64)
        except (TypeError, ValueError):
            raise GeometryError(f"'{name}': transform must be a numeric [{d + 1}, {d + 1}] matrix") from None
        if m.shape != (d + 1, d + 1) or not np.isfinite(m).all():
            raise GeometryError(
                f"'{name}': transform must be a finite [{d + 1}, {d + 1}] homogeneous matrix,"
                f" got shape {list(m.shape)}"
            )
        r, t = m[:d, :d], m[:d, d]
        if np.any(m[d] != np.eye(d + 1)[d]) or np.abs(r.T @ r - np.eye(d)).max() > RIGID_TOL:
            raise GeometryError(
                f"'{name}': transform must be rigid: [[R, t], [0, 1]] with R orthogonal"
                " (use scale for resizing)"
            )
        points = points @ r.T + t
        mirrored = bool(np.linalg.det(r) < 0)
    # the message names the spec field (geometry.scale), so the service reports it there
    # at scale 1 the input's own coordinates are out of range: the message names no spec field, so
    # the service reports it at the mesh or polygon
    blame = "" if scale == 1 else f"geometry.scale: scaled by {scale!r}, "
    if not np.isfinite(points).all():
        raise GeometryError(f"{blame}the coordinates of '{name}' overflow")
    reach = float(np.abs(points).max()) if points.size else 0.0
    if reach > MAX_COORDINATE:
        raise GeometryError(f"{blame}'{name}' reaches coordinates of {reach:.3g} m; at most {MAX_COORDINATE:g} m is "
                            "supported")
    size = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 0.0
    if 0 < size < MIN_SIZE:
        raise GeometryError(f"{blame}'{name}' is {size:.3g} m across; at least {MIN_SIZE:g} m is supported")
    if size > 0 and reach > MAX_DISTANCE_OVER_SIZE * size:
        where = "geometry.transform: " if transform is not None else ""
        raise GeometryError(f"{where}'{name}' lies {reach:.3g} m from the origin, {reach / size:.3g} times its size "
                            f"({size:.3g} m): there double precision keeps too few digits of its shape (at most "
                            f"{MAX_DISTANCE_OVER_SIZE:g} times its size); move it towards the origin (the "
                            "translation of geometry.transform, or in the file)")
    return points, mirrored


def check_volume(surface: Surface, name: str) -> None:
    """Raise ``GeometryError`` if the surface encloses no volume (3D) or area (2D)."""
    lo, hi = surface.bounds
    extent = hi - lo
    # About the centre of the bounds: the same for closed surfaces, and for open ones a
    # measure that does not grow with the distance to the origin (a flat sheet gives 0).
    volume = Surface(surface.vertices - (lo + hi) / 2, surface.faces).enclosed_volume()
    what = "volume" if surface.dim == 3 else "area"
    if volume > FLAT_TOL * float(extent.max()) ** surface.dim:
        return
    if extent.min() <= FLAT_TOL * extent.max():
        axis = "xyz"[int(np.argmin(extent))]
        raise GeometryError(f"'{name}' encloses no {what}: it is flat (zero extent along {axis})")
    raise GeometryError(f"'{name}' encloses no {what}: the enclosed {what} is {volume:.6g} after repair")


def describe_error(exc: Exception, what: str) -> str:
    """Why a reader failed, in words for the user: never the exception's own text, which names
    library internals (``StopIteration``, ``KeyError: 'y'``) instead of the problem."""
    if isinstance(exc, UnicodeError):
        return f"it is not a valid {what}: it holds text that is not valid UTF-8/ASCII"
    if isinstance(exc, RecursionError):
        return f"it is not a valid {what}: its structure is nested too deeply"
    return f"it is not a valid {what}, or it is damaged or incomplete"
