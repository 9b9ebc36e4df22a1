"""Planar solids: closed vertex loops or the closed curves of an SVG/DXF drawing -> ``Surface``.

The solid is bounded by oriented segments with the solid on their left: outer boundaries run
counter-clockwise, holes clockwise. Nesting decides which loop is a hole (inside an odd number
of others), whatever orientation the input gives it; loops must not cross themselves or each
other. Drawings are read with ``trimesh.load_path``; SVG coordinates are used as written
(y pointing down on screen). Placement (scale, then a rigid 3x3 transform) by ``_shared.place``.
"""

from __future__ import annotations

import io

import numpy as np
import shapely
import trimesh
from trimesh.exchange.load import path_formats

from engine.errors import GeometryError
from engine.geometry._shared import RIGID_TOL, check_volume, describe_error, place
from engine.geometry.surface import Surface


def polygon_surface(
    loops: list,
    *,
    scale: float = 1.0,
    transform: np.ndarray | None = None,
    name: str = "polygon",
) -> Surface:
    """A planar solid from closed vertex loops: each loop [p, 2] [m], first point not repeated
    (a repeated closing point is dropped). Loops nested in an odd number of others are holes,
    whatever their given orientation; each loop is reoriented so the solid is on the left of
    every segment (outer counter-clockwise, holes clockwise). Vertex order is kept: a reversed
    loop keeps its vertices and swaps its segments' ends.
    """
    if len(loops) == 0:
        raise GeometryError(f"polygon '{name}' has no loops")
    warnings: list[str] = []
    clean = [_clean_loop(loop, i, name, warnings) for i, loop in enumerate(loops)]
    points, _ = place(np.concatenate(clean), scale, transform, name)  # orientation fixed below
    offsets = np.cumsum([0] + [len(c) for c in clean])
    clean = [points[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    faces, reversed_count = [], 0
    for loop, start, depth in zip(clean, offsets, _loop_depths(clean, name)):
        idx = start + np.arange(len(loop))
        segments = np.stack([idx, np.roll(idx, -1)], axis=1)
        if (_signed_area(loop) > 0) != (depth % 2 == 0):
            segments = segments[:, ::-1]
            reversed_count += 1
        faces.append(segments)
    if reversed_count:
        warnings.append(
            f"reversed {reversed_count} of {len(clean)} loops so that outer boundaries run"
            " counter-clockwise and holes clockwise"
        )
    surface = Surface(points, np.concatenate(faces).astype(np.int64), True, warnings)
    check_volume(surface, name)
    return surface


def read_drawing(name: str, data: bytes, file_type: str) -> tuple[list[np.ndarray], list[str]]:
    """Closed curves of an SVG/DXF drawing, discretised by trimesh: ([p, 2] loops, notes)."""
    if file_type not in path_formats():
        raise GeometryError(f"cannot read drawing '{name}': dimension 2 needs an SVG or DXF file")
    try:
        path = trimesh.load_path(io.BytesIO(data), file_type=file_type)
        loops = [np.asarray(d, dtype=np.float64) for d in path.discrete]
        dangling = len(path.dangling)
    except Exception as exc:  # noqa: BLE001 - any loader failure is a bad file to the user
        if isinstance(exc, MemoryError):
            raise
        raise GeometryError(f"cannot read drawing '{name}': {describe_error(exc, file_type.upper() + ' drawing')}") from None
    if not loops:
        raise GeometryError(f"drawing '{name}' contains no closed curves")
    if loops[0].shape[1] == 3:
        z = np.concatenate(loops)[:, 2]
        if np.ptp(z) > RIGID_TOL * max(1.0, np.abs(z).max()):
            raise GeometryError(f"drawing '{name}' is not planar (z varies by {np.ptp(z):.3g})")
        loops = [loop[:, :2] for loop in loops]
    return loops, [f"ignored {dangling} open curves of the drawing"] if dangling else []


# --- loops ------------------------------------------------------------------------------------


def _clean_loop(loop, i: int, name: str, warnings: list[str]) -> np.ndarray:
    try:
        p = np.array(loop, dtype=np.float64)
    except (TypeError, ValueError):
        raise GeometryError(f"polygon '{name}': loop {i} must be a list of [x, y] points") from None
    if p.ndim != 2 or p.shape[1] != 2:
        raise GeometryError(f"polygon '{name}': loop {i} must have shape [p, 2], got {list(p.shape)}")
    bad = int((~np.isfinite(p).all(axis=1)).sum())
    if bad:
        raise GeometryError(
            f"polygon '{name}': loop {i} has {bad} points with non-finite coordinates (NaN or infinity)"
        )
    distinct = len(np.unique(p, axis=0))
    repeat = np.all(p == np.roll(p, -1, axis=0), axis=1)
    if repeat.any() and len(p) > 1:
        # The closing copy of the first point is expected; other repeats are zero-length segments.
        extra = int(repeat.sum()) - int(repeat[-1])
        if extra:
            warnings.append(f"loop {i}: removed {extra} repeated consecutive points")
        p = p[~repeat]
    flat = distinct < 3 or np.linalg.matrix_rank(p - p.mean(axis=0)) < 2
    if not flat and _signed_area(p) == 0.0 and not shapely.Polygon(p).is_valid:  # a bowtie's lobes cancel
        raise GeometryError(f"polygon '{name}': loop {i} is not a simple closed curve "
                            f"({shapely.is_valid_reason(shapely.Polygon(p))})")
    if flat or _signed_area(p) == 0.0:
        raise GeometryError(f"polygon '{name}': loop {i} encloses no area ({distinct} distinct points)")
    return p


def _signed_area(loop: np.ndarray) -> float:
    x, y = loop[:, 0], loop[:, 1]
    with np.errstate(over="ignore", invalid="ignore"):  # coordinates near 1e200: refused by range later
        return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _loop_depths(loops: list[np.ndarray], name: str) -> np.ndarray:
    """How many other loops enclose each loop; loops must not cross themselves or each other."""
    polygons = [shapely.Polygon(p) for p in loops]
    for i, polygon in enumerate(polygons):
        if not polygon.is_valid:
            reason = shapely.is_valid_reason(polygon)
            raise GeometryError(f"polygon '{name}': loop {i} is not a simple closed curve ({reason})")
    depth = np.zeros(len(loops), dtype=np.int64)
    for i, j in shapely.STRtree(polygons).query(polygons).T:  # pairs with overlapping boxes
        if i >= j:
            continue
        a, b = polygons[i], polygons[j]
        if a.equals(b):
            raise GeometryError(f"polygon '{name}': loops {i} and {j} coincide")
        if b.contains(a):
            depth[i] += 1
        elif a.contains(b):
            depth[j] += 1
        elif a.overlaps(b) or a.boundary.crosses(b.boundary):
            raise GeometryError(f"polygon '{name}': loops {i} and {j} cross each other")
    return depth
