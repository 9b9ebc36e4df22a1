"""Planar solids: closed vertex loops or the closed curves of an SVG/DXF drawing -> ``Surface``.

The solid is bounded by oriented segments with the solid on their left: outer boundaries run
counter-clockwise, holes clockwise. Nesting decides which loop is a hole (inside an odd number
of others), whatever orientation the input gives it; loops must not cross themselves or each
other. Placement (scale, then a rigid 3x3 transform) by ``_shared.place``.

Drawings (``drawing_surface``) are read with ``trimesh.load_path``; SVG coordinates are used as
written (y pointing down on screen). A DXF has no fill: its closed curves are loops as above. An
SVG is read element by element (``engine.geometry.svg``): each filled element is the region its
fill rule gives its own subpaths, and the solid is the union of those regions -- as a browser
fills them -- with a warning naming the union where separate shapes overlap. Its boundary, traced
by shapely, gives the loops.
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
from engine.geometry.svg import Shape, read_svg

# Overlap of separate filled shapes below this fraction of the drawing's area is round-off or a touch.
OVERLAP_TOL = 1e-9


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
    placed = [points[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    faces = []
    # Nesting decides every loop's role, so reversing one is bookkeeping, not news for the user:
    # a hole drawn in the outline's direction is how SVG's evenodd rule and most CAD exports draw it.
    for loop, start, depth in zip(placed, offsets, _loop_depths(placed, name, clean)):
        idx = start + np.arange(len(loop))
        segments = np.stack([idx, np.roll(idx, -1)], axis=1)
        if (_signed_area(loop) > 0) != (depth % 2 == 0):
            segments = segments[:, ::-1]
        faces.append(segments)
    surface = Surface(points, np.concatenate(faces).astype(np.int64), True, warnings)
    check_volume(surface, name)
    return surface


def drawing_surface(name: str, data: bytes, file_type: str, *, scale: float = 1.0,
                    transform: np.ndarray | None = None) -> Surface:
    """The planar solid of an SVG/DXF drawing (module docstring), placed as ``polygon_surface``."""
    shapes, notes = read_drawing(name, data, file_type)
    loops, united = _filled_loops(shapes, name)
    surface = polygon_surface(loops, scale=scale, transform=transform, name=name)
    if united:
        count, overlap, drawn, area = united
        notes.append(
            f"united {count} overlapping filled shapes of the drawing (overlap area {overlap * scale**2:.6g} m^2;"
            f" area {drawn * scale**2:.6g} -> {area * scale**2:.6g} m^2); a hole must be a subpath of its"
            " outline's path (fill-rule evenodd, or drawn in the opposite direction)"
        )
    surface.warnings[:0] = notes
    return surface


def read_drawing(name: str, data: bytes, file_type: str) -> tuple[list[Shape], list[str]]:
    """The closed curves of an SVG/DXF drawing, discretised by trimesh, as shapes: an SVG's
    filled elements with their fill rules, a DXF's curves as one group of outlines; and notes."""
    if file_type not in path_formats():
        raise GeometryError(f"cannot read '{name}': dimension 2 needs an SVG or DXF file")
    if file_type == "svg":
        shapes, notes = read_svg(name, data)
        if not shapes:
            raise GeometryError(f"drawing '{name}' contains no closed curves")
        return shapes, notes
    try:
        path = trimesh.load_path(io.BytesIO(data), file_type=file_type)
        loops = [np.asarray(d, dtype=np.float64) for d in path.discrete]
        dangling = len(path.dangling)
    except Exception as exc:  # noqa: BLE001 - any loader failure is a bad file to the user
        if isinstance(exc, MemoryError):
            raise
        raise GeometryError(f"cannot read '{name}': {describe_error(exc, file_type.upper() + ' drawing')}") from None
    if not loops:
        raise GeometryError(f"drawing '{name}' contains no closed curves")
    if loops[0].shape[1] == 3:
        z = np.concatenate(loops)[:, 2]
        if np.ptp(z) > RIGID_TOL * max(1.0, np.abs(z).max()):
            raise GeometryError(f"drawing '{name}' is not planar (z varies by {np.ptp(z):.3g})")
        loops = [loop[:, :2] for loop in loops]
    return [Shape(loops, None)], [f"ignored {dangling} open curves of the drawing"] if dangling else []


# --- fill rules -------------------------------------------------------------------------------


def _filled_loops(shapes: list[Shape], name: str):
    """(loops of the solid the shapes fill, None or (shapes united, overlap area, sum of their
    areas, area of the union) when separate shapes overlap), in drawing units."""
    if all(shape.rule is None for shape in shapes):
        return [loop for shape in shapes for loop in shape.loops], None  # nesting decides, as given
    regions = [_region(shape.loops, shape.rule or "evenodd") for shape in shapes]
    regions = [r for r in regions if not r.is_empty]
    solid = shapely.union_all(regions)
    if solid.is_empty:
        raise GeometryError(f"drawing '{name}': its filled shapes enclose no area")
    drawn = float(sum(r.area for r in regions))
    overlap = drawn - solid.area
    united = None
    if overlap > OVERLAP_TOL * solid.area:
        overlapping = set()
        for i, j in shapely.STRtree(regions).query(regions).T:  # pairs with overlapping boxes
            if i < j and regions[i].intersection(regions[j]).area > OVERLAP_TOL * solid.area:
                overlapping |= {int(i), int(j)}
        united = (len(overlapping), overlap, drawn, float(solid.area))
    loops = []
    for polygon in shapely.get_parts(shapely.normalize(solid)):
        for ring in (polygon.exterior, *polygon.interiors):
            loops.append(np.asarray(ring.coords)[:-1])
    return loops, united


def _region(loops: list[np.ndarray], rule: str):
    """The region a fill rule gives closed curves: the faces of their arrangement whose winding
    number is nonzero (``nonzero``) or odd (``evenodd``)."""
    loops = [p for p in loops if len(p) >= 3]
    if not loops:
        return shapely.Polygon()
    noded = shapely.union_all([shapely.LineString(np.vstack([p, p[:1]])) for p in loops])
    faces = np.asarray(shapely.get_parts(shapely.polygonize(shapely.get_parts(noded))))
    if len(faces) == 0:
        return shapely.Polygon()
    points = shapely.get_coordinates(shapely.point_on_surface(faces))
    winding = sum(_winding(p, points) for p in loops)
    filled = winding != 0 if rule == "nonzero" else winding % 2 == 1
    return shapely.union_all(faces[filled])


def _winding(loop: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Winding number [q] of a closed polyline loop [p, 2] about points [q, 2] off it (crossings
    of the ray to +x, counted with the edge's direction)."""
    a, b = loop[None, :, :], np.roll(loop, -1, axis=0)[None, :, :]
    x, y = points[:, None, 0], points[:, None, 1]
    side = (b[..., 0] - a[..., 0]) * (y - a[..., 1]) - (x - a[..., 0]) * (b[..., 1] - a[..., 1])
    up = (a[..., 1] <= y) & (b[..., 1] > y) & (side > 0)
    down = (a[..., 1] > y) & (b[..., 1] <= y) & (side < 0)
    return up.sum(axis=1) - down.sum(axis=1)


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
        raise GeometryError(f"polygon '{name}': loop {i} is not a simple closed curve: {_why_not_simple(p)}")
    if flat or _signed_area(p) == 0.0:
        raise GeometryError(f"polygon '{name}': loop {i} encloses no area ({distinct} distinct points)")
    return p


def _signed_area(loop: np.ndarray) -> float:
    x, y = loop[:, 0], loop[:, 1]
    with np.errstate(over="ignore", invalid="ignore"):  # coordinates near 1e200: refused by range later
        return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


# shapely's reasons a single ring is no simple closed curve ('Self-intersection[0.5 0.5]'), in words
_NOT_SIMPLE = {"Self-intersection": "it crosses itself", "Ring Self-intersection": "it touches itself"}


def _why_not_simple(loop: np.ndarray) -> str:
    """Why a loop [p, 2] is no simple closed curve, and where, in the loop's own coordinates."""
    reason = shapely.is_valid_reason(shapely.Polygon(loop))
    kind, _, point = reason.partition("[")
    words = _NOT_SIMPLE.get(kind, "it crosses or touches itself")
    try:
        x, y = (float(v) for v in point.rstrip("]").split()[:2])
    except ValueError:  # the loop as given is valid (its placement's round-off made the fault): no point to name
        return words
    return f"{words} at ({x:.6g}, {y:.6g})"


def _loop_depths(loops: list[np.ndarray], name: str, given: list[np.ndarray]) -> np.ndarray:
    """How many other loops enclose each loop; loops must not cross themselves or each other.
    ``given``: the loops before placement, whose coordinates a message names."""
    polygons = [shapely.Polygon(p) for p in loops]
    for i, polygon in enumerate(polygons):
        if not polygon.is_valid:
            raise GeometryError(f"polygon '{name}': loop {i} is not a simple closed curve: {_why_not_simple(given[i])}")
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
