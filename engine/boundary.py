"""Boundary conditions as both methods see them: what acts, on which surface patch, with which value.

Every boundary acts on its *surface patch*: the part of the mesh surface inside its region,
optionally only the facets facing a given way (``facing`` in schemas/json/job.schema.json). A
displacement boundary holds the solid's surface there, per component (``Prescribed``); traction
and pressure act there (``SurfaceLoad``). This module turns a job spec (plus the Python API's callables) into those
objects (:func:`make_boundaries`), clips patches with errors that say what is wrong
(:func:`select_patch`), integrates over them (:func:`surface_quadrature`) and evaluates tractions
(:func:`tractions`). How a method turns a boundary into its own unknowns stays in the method.

Units: positions [m], tractions, pressures and stresses [Pa], displacements [m], weights [m^2]
(3D) or [m] (2D).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .clusters import clustered_rule
from .errors import BoundaryError
from .geometry.surface import Surface
from .regions import Region, make_region
from .subdivision import lattice_pieces, split_facets, subdivided

PointFunction = Callable[[np.ndarray], np.ndarray]


def evaluate(function: PointFunction, points: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray:
    """A Python-API function at points [N, d] as floats [N, *shape] (a constant [*shape] is
    broadcast); BoundaryError naming ``what`` when it raises or returns another shape."""
    n = len(points)
    try:
        raw = np.asarray(function(points))
        if np.iscomplexobj(raw):  # float() would drop the imaginary part with a warning alone
            raise TypeError("it returned complex numbers")
        value = np.asarray(raw, dtype=float)
    except Exception as exc:  # the user's code: say whose, keep the cause
        raise BoundaryError(f"{what}: the function raised {type(exc).__name__}: {exc}") from exc
    if value.shape == shape:
        value = np.broadcast_to(value, (n, *shape))
    if value.shape != (n, *shape):
        wanted = f"[{', '.join(map(str, (n, *shape)))}]"
        constant = f"[{', '.join(map(str, shape))}]" if shape else "one value"
        raise BoundaryError(f"{what}: the function returned shape {list(value.shape)} for {n} points; expected "
                            f"{wanted} (or {constant} for a constant)")
    return value

# A displacement patch covering more than this share of a body's surface gets a warning: usually a
# half-space whose normal points the wrong way (the normal points out of the region).
WIDE_HOLD = 0.5
# with ``merge``, surface pieces at most this times the rule's spacing long are merged into clusters
# of that side (engine.clusters)
CLUSTER = 0.25


@dataclass
class Prescribed:
    """Displacement of the surface patch of ``region``: ``value`` [d] with None for free
    components, or a callable points [N, d] -> [N, d] [m] (then ``components`` says which are
    prescribed; default all)."""

    region: object
    value: tuple | PointFunction
    name: str
    components: tuple[bool, ...] | None = None

    def mask(self, d: int) -> np.ndarray:
        """The prescribed components [d] bool."""
        if callable(self.value):
            return np.asarray(self.components if self.components is not None else (True,) * d, dtype=bool)
        return np.array([v is not None for v in self.value], dtype=bool)

    def values(self, points: np.ndarray) -> np.ndarray:
        """Prescribed displacement [N, d] [m] at points [N, d] (0 in free components); BoundaryError
        naming the boundary when it is not finite."""
        n, d = points.shape
        if callable(self.value):
            g = evaluate(self.value, points, (d,), f"{self.name}: the displacement")
        else:
            g = np.broadcast_to(np.array([0.0 if v is None else float(v) for v in self.value]), (n, d))
        if not np.all(np.isfinite(g)):
            raise BoundaryError(f"{self.name}: the prescribed displacement is not finite at some surface points")
        return np.where(self.mask(d)[None, :], g, 0.0)


@dataclass
class SurfaceLoad:
    """Traction on the surface patch of ``region``: exactly one of traction [d] or callable [Pa],
    pressure [Pa] (positive pushes in), stress [d, d] or callable points -> [N, d, d] [Pa]. ``form``
    is how the staggered method applies a stress field or pressure: "quadrature" (sigma n on the
    surface) or "divergence" (thesis eq. 4.16); DG always integrates on the surface."""

    region: object
    name: str
    traction: object = None
    pressure: float | None = None
    stress: object = None
    form: str = "quadrature"

    def tractions(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Traction [Q, d] [Pa] at surface points [Q, d] with unit outward normals [Q, d]."""
        return tractions(points, normals, name=self.name, traction=self.traction, pressure=self.pressure,
                         stress=self.stress)


@dataclass
class Boundaries:
    """What a job's boundaries and loads are, independent of the method."""

    prescribed: list[Prescribed] = field(default_factory=list)
    loads: list[SurfaceLoad] = field(default_factory=list)
    body_force: np.ndarray | PointFunction | None = None  # [d] or callable [N/m^3]


class PredicateRegion:
    """A region given by a callable mask points [N, d] -> bool [N] (Python API). Surface facets
    count by their centroid, so patches are resolved to the facet size."""

    def __init__(self, mask: PointFunction, name: str = "region") -> None:
        self.mask, self.name = mask, name

    def contains(self, points: np.ndarray, slack: float = 0.0) -> np.ndarray:
        inside = evaluate(self.mask, np.asarray(points, dtype=float), (), f"{self.name}: the region")
        if not np.all(np.isfinite(inside)):  # NaN != 0 would count as inside
            raise BoundaryError(f"{self.name}: the region's function returned NaN or infinity")
        return inside != 0

    def clip(self, facets: np.ndarray, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        keep = np.nonzero(self.contains(np.asarray(facets).mean(axis=1)))[0]
        return np.asarray(facets)[keep], keep


@dataclass(frozen=True)
class Facing:
    """``region`` restricted, on surfaces, to the facets whose outward normal is within
    ``max_angle_deg`` of ``direction`` [d] (membership of points is the region's own)."""

    region: object
    direction: np.ndarray
    max_angle_deg: float

    def contains(self, points: np.ndarray, slack: float = 0.0) -> np.ndarray:
        return self.region.contains(points, slack)

    def distance(self, points: np.ndarray) -> np.ndarray:
        return region_distance(self.region, points)

    def clip(self, facets: np.ndarray, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        facets = np.asarray(facets, dtype=float)
        _, normals = _measure_and_normal(facets)
        direction = np.asarray(self.direction, dtype=float)
        # the same small slack as plane clipping: a facet at exactly the angle is kept
        faces = normals @ (direction / np.linalg.norm(direction)) >= math.cos(math.radians(self.max_angle_deg)) - 1e-12
        pieces, source = self.region.clip(facets[faces], tolerance)
        return pieces, np.nonzero(faces)[0][source]


def make_boundaries(spec, functions, material) -> Boundaries:
    """The boundaries of a validated job spec, with the Python API's ``functions`` (an
    ``engine.pipeline.Functions``) replacing values and regions by name; ``material`` gives the
    density for gravity."""
    d = spec.dimension
    out = Boundaries()
    _check_function_names(spec, functions)
    for i, b in enumerate(spec.boundaries):
        name = b.name or f"boundaries.{i}"
        region = PredicateRegion(functions.regions[name], name) if name in functions.regions else make_region(b.region, d)
        if getattr(b, "facing", None) is not None:
            region = Facing(region, np.asarray(b.facing.direction, dtype=float), float(b.facing.max_angle_deg))
        if b.kind == "displacement":
            value = functions.displacement.get(name, b.value)
            out.prescribed.append(Prescribed(region, value, name, tuple(v is not None for v in b.value)))
        elif b.kind == "traction":
            if name in functions.stress:
                out.loads.append(SurfaceLoad(region, name, stress=functions.stress[name], form=functions.stress_form))
            else:
                value = functions.traction.get(name, np.asarray(b.value, dtype=float))
                out.loads.append(SurfaceLoad(region, name, traction=value))
        else:
            out.loads.append(SurfaceLoad(region, name, pressure=float(b.value), form=functions.pressure_form))
    out.body_force = functions.body_force
    if out.body_force is None and spec.loads.gravity is not None and any(g != 0 for g in spec.loads.gravity):
        out.body_force = material.density * np.asarray(spec.loads.gravity, dtype=float)
    return out


def _check_function_names(spec, functions) -> None:
    """BoundaryError for a Python-API function keyed by a name that is no boundary of its kind in
    ``spec`` (it would be ignored: a typo's function never runs)."""
    kinds = {b.name or f"boundaries.{i}": b.kind for i, b in enumerate(spec.boundaries)}
    for group, allowed in (("displacement", ("displacement",)), ("traction", ("traction",)),
                           ("stress", ("traction",)), ("regions", ("displacement", "traction", "pressure"))):
        for key in getattr(functions, group):
            if kinds.get(key) not in allowed:
                have = [n for n, k in kinds.items() if k in allowed]
                raise BoundaryError(f"functions.{group}: {key!r} names no {' or '.join(allowed)} boundary of the spec "
                                    f"(those are: {', '.join(map(repr, have)) or 'none'}); name a boundary by its "
                                    "`name`, or boundaries.<i> when it has none")


def select_patch(region, facets: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The pieces of ``facets`` [N, d, d] inside ``region`` (pieces [M, d, d], source facet [M]).
    A region that selects no surface of positive measure is a BoundaryError naming the boundary
    and how far the region is from the surface."""
    facets = np.asarray(facets, dtype=float)
    pieces, source = region.clip(facets)
    if len(pieces) and _measure_and_normal(pieces)[0].sum() > 0:
        return pieces, source
    if isinstance(region, Facing):  # the region may hold surface that faces another way
        inner, _ = region.region.clip(facets)
        area, normals = _measure_and_normal(inner) if len(inner) else (np.zeros(0), None)
        if area.sum() > 0:
            mean = (area[:, None] * normals).sum(axis=0)
            mostly = f"; it faces mostly {_direction(mean)}" if np.linalg.norm(mean) > 0.5 * area.sum() else ""
            raise BoundaryError(
                f"{name}: none of the {area.sum():.4g} {'m^2' if facets.shape[-1] == 3 else 'm'} of surface in its "
                f"region faces within {region.max_angle_deg:g} degrees of {_direction(region.direction)}{mostly}; "
                "`facing.direction` is the outward normal of the facets to keep"
            )
    where = ""
    gap = region_distance(region, facets.reshape(-1, facets.shape[-1]))
    if gap is not None and len(gap):
        where = f" (its region is {gap.min():.4g} m from the nearest surface vertex)"
    facing = " that faces the given direction" if isinstance(region, Facing) else ""
    raise BoundaryError(
        f"{name}: the region holds no part of the mesh surface{facing}{where}; every boundary acts on the surface "
        "inside its region: move or widen the region so that it takes in the surface it should act on"
    )


def _direction(vector: np.ndarray) -> str:
    unit = np.asarray(vector, dtype=float) / np.linalg.norm(vector)
    return "(" + ", ".join(f"{c:.3g}" for c in np.where(np.abs(unit) < 5e-4, 0.0, unit)) + ")"


def region_distance(region, points: np.ndarray) -> np.ndarray | None:
    """Distance [N] [m] from points [N, d] to ``region`` (0 inside; a lower bound for an
    intersection of half-spaces that is not a box), or None when the region cannot say."""
    if isinstance(region, Facing):
        return region_distance(region.region, points)
    from .regions import Ball, Halfspaces

    points = np.asarray(points, dtype=float)
    if isinstance(region, Ball):
        return np.maximum(np.linalg.norm(points - region.center, axis=1) - region.radius, 0.0)
    if isinstance(region, Halfspaces):
        if len(region.offsets) == 0:
            return np.zeros(len(points))
        over = np.maximum(points @ region.normals.T - region.offsets, 0.0)  # [N, planes]
        d = points.shape[1]
        axis_box = len(region.offsets) == 2 * d and np.allclose(np.abs(region.normals), np.vstack([np.eye(d)] * 2))
        return np.linalg.norm(over, axis=1) if axis_box else over.max(axis=1)
    return None


def check_holds(prescribed: list[Prescribed], surface: Surface) -> list[str]:
    """Raise BoundaryError when two displacement boundaries prescribe different values of one
    component on a common part of the surface (a point holds one displacement: a solve would
    average them silently); return a warning for each whose patch covers more than WIDE_HOLD of the
    surface (usually a half-space whose normal points the wrong way)."""
    facets = surface.vertices[surface.faces]
    total = _measure_and_normal(facets)[0].sum()
    patches = [bc.region.clip(facets)[0] for bc in prescribed]
    for i, j in itertools.combinations(range(len(prescribed)), 2):
        _check_overlap(prescribed[i], patches[i], prescribed[j], surface.dim)
    out = []
    for bc, pieces in zip(prescribed, patches):
        share = _measure_and_normal(pieces)[0].sum() / total if total > 0 and len(pieces) else 0.0
        if share > WIDE_HOLD:
            out.append(
                f"{bc.name}: the displacement boundary holds {share:.0%} of the surface; if it should hold less, check "
                "the region (a half-space holds the side its normal points away from: the normal points out of it)"
            )
    return out


def exclusive_holds(prescribed: list[Prescribed], surface: Surface) -> list[Prescribed]:
    """The displacement boundaries with every component of every surface point held once: where a
    boundary prescribes a component an earlier one already holds there (with the same value:
    :func:`check_holds` refuses others), that part of its patch is taken out for that component. Both
    methods add one Nitsche term per boundary, so two agreeing clamps on one face counted its
    consistency and penalty terms twice: the solution of a different problem (DG: a pulled bar's held
    face slid and its end moved 2%; staggered 0.7%). A boundary left holding nothing is dropped."""
    facets = surface.vertices[surface.faces]
    d = surface.dim
    out = []
    for i, bc in enumerate(prescribed):
        pieces = bc.region.clip(facets)[0]
        # per component, the earlier boundaries that hold it on a part of this patch
        covering = {a: tuple(j for j in range(i) if prescribed[j].mask(d)[a] and _overlap(prescribed[j], pieces))
                    for a in np.nonzero(bc.mask(d))[0]}
        if not any(covering.values()):
            out.append(bc)
            continue
        for others in sorted(set(covering.values())):
            comps = tuple(bool(covering.get(a) == others) for a in range(d))
            region = _Without(bc.region, tuple(prescribed[j].region for j in others)) if others else bc.region
            if len(region.clip(facets)[0]):
                out.append(Prescribed(region, _only(bc, comps), bc.name, comps if callable(bc.value) else None))
    return out


def _overlap(a: Prescribed, pieces: np.ndarray) -> bool:
    """Whether ``a``'s patch takes in a part of positive measure of ``pieces`` [M, d, d]."""
    if not len(pieces):
        return False
    common, _ = a.region.clip(pieces)
    return len(common) > 0 and _measure_and_normal(common)[0].sum() > 1e-9 * _measure_and_normal(pieces)[0].sum()


def _only(bc: Prescribed, comps: tuple[bool, ...]):
    """``bc``'s value with the components outside ``comps`` free."""
    if callable(bc.value):
        return bc.value
    return tuple(v if keep else None for v, keep in zip(bc.value, comps))


@dataclass(frozen=True)
class _Without:
    """``region`` less the surface the ``others`` take in: pieces straddling an other's edge are cut
    down to ``RIM`` of the surface's size and kept by where most of their measure lies."""

    region: object
    others: tuple

    def contains(self, points: np.ndarray, slack: float = 0.0) -> np.ndarray:
        inside = self.region.contains(points, slack)
        for other in self.others:
            inside &= ~other.contains(points)
        return inside

    def clip(self, facets: np.ndarray, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        facets = np.asarray(facets, dtype=float)
        pieces, source = self.region.clip(facets, tolerance)
        if not len(pieces):
            return pieces, source
        pts = facets.reshape(-1, facets.shape[-1])
        rim = RIM * float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        for other in self.others:
            pieces, source = _outside(pieces, source, other, rim)
        return pieces, source


RIM = 1e-4  # where _Without resolves an other region's edge, as a share of the surface's size


def _outside(pieces: np.ndarray, source: np.ndarray, other, rim: float) -> tuple[np.ndarray, np.ndarray]:
    """The parts of ``pieces`` [M, d, d] (with their ``source`` facets [M]) that ``other`` does not take in."""
    d = pieces.shape[-1]
    kept, kept_source = [], []
    while len(pieces):
        measure = _measure_and_normal(pieces)[0]
        inner, owner = other.clip(pieces)
        held = np.bincount(owner, weights=_measure_and_normal(inner)[0], minlength=len(pieces)) if len(inner) else \
            np.zeros(len(pieces))
        free = held <= 1e-12 * measure
        covered = held >= (1 - 1e-9) * measure
        reach = np.linalg.norm(pieces - pieces.mean(axis=1, keepdims=True), axis=2).max(axis=1)
        small = ~free & ~covered & (reach <= rim)
        take = free | (small & (held < 0.5 * measure))
        kept.append(pieces[take])
        kept_source.append(source[take])
        split = ~free & ~covered & ~small
        pieces, parent = split_facets(pieces[split])
        source = source[split][parent]
    return np.concatenate(kept).reshape(-1, d, d), np.concatenate(kept_source).astype(np.int64)


def _check_overlap(a: Prescribed, pieces: np.ndarray, b: Prescribed, d: int) -> None:
    """BoundaryError when ``a`` (its patch ``pieces`` [M, d, d]) and ``b`` prescribe one component
    differently on a common part of the surface of positive measure."""
    both = a.mask(d) & b.mask(d)
    if not both.any() or not len(pieces):
        return
    common, _ = b.region.clip(pieces)
    measure = _measure_and_normal(common)[0] if len(common) else np.zeros(0)
    # regions that only touch (a box ending where the next begins) share pieces of no measure
    if measure.sum() <= 1e-9 * _measure_and_normal(pieces)[0].sum():
        return
    points = common[measure > 0].mean(axis=1)
    ga, gb = a.values(points)[:, both], b.values(points)[:, both]
    gap = np.abs(ga - gb)
    if gap.max() <= 1e-9 * max(np.abs(ga).max(), np.abs(gb).max()):
        return  # e.g. two clamps that overlap
    q, k = np.unravel_index(np.argmax(gap), gap.shape)
    axis = "xyz"[np.nonzero(both)[0][k]]
    unit = "m^2" if d == 3 else "m"
    raise BoundaryError(
        f"{a.name} and {b.name}: both prescribe u_{axis} on the same {measure.sum():.4g} {unit} of the surface, with "
        f"different values there ({ga[q, k]:.6g} and {gb[q, k]:.6g} m); a surface point holds one displacement: narrow "
        "a region (or give it a `facing`) so that the two patches do not overlap, or leave that component free (null) "
        "in one of them"
    )


def surface_quadrature(facets: np.ndarray, spacing: float, centroids: bool = False, merge: bool = False,
                       lattice: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature rule on surface pieces ``facets`` [M, d, d] (3D triangles / 2D segments, oriented
    as engine.geometry.surface: 3D right-hand rule outward, 2D solid on the left).

    Pieces with an edge longer than ``spacing`` / 2 [m] are subdivided (``subdivision.subdivided``)
    until none is, so each piece crosses few cells of a piecewise-multilinear grid field; with
    ``lattice`` (an origin [d] [m]) they are cut instead at the planes ``spacing`` / 2 apart from it
    (``subdivision.lattice_pieces``), so each lies in one box of them; on each piece a
    degree-5 Gauss rule (3-point Gauss-Legendre / 7-point Radon-Dunavant) integrates, or with
    ``centroids`` the one-point rule (exact for linear integrands: the measure and first moments
    of each piece; with ``lattice``, one point for all of a facet's pieces in a box). With ``merge``,
    pieces no longer than CLUSTER ``spacing`` (a mesh finer than the grid) are merged into clusters of
    that side, each with a rule exact to its second moments (:mod:`engine.clusters`): points follow the
    grid, not the triangle count. Zero-area pieces are dropped. Returns points [Q, d] [m], weights [Q]
    [m^2 | m] (summing to the total area / length to round-off) and unit outward normals [Q, d] (a
    cluster's: its area vector over its measure, unit to O((size * curvature)^2)).
    """
    facets = np.asarray(facets, dtype=float)
    if facets.ndim != 3 or facets.shape[1] != facets.shape[2] or facets.shape[2] not in (2, 3):
        raise ValueError(f"facets: expected shape [M, d, d] with d = 2 or 3, got {facets.shape}")
    if not (math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing: must be a positive finite number, got {spacing}")
    d = facets.shape[2]
    if lattice is not None and centroids:
        return _box_centroids(facets, np.asarray(lattice, dtype=float), 0.5 * spacing)
    facets = subdivided(facets, 0.5 * spacing) if lattice is None else lattice_pieces(facets, lattice, 0.5 * spacing)
    measure, normals = _measure_and_normal(facets)
    keep = measure > 0
    facets, measure, normals = facets[keep], measure[keep], normals[keep]
    if centroids:
        return facets.mean(axis=1), measure, normals
    small = np.zeros(len(facets), dtype=bool)
    if merge:
        small = np.linalg.norm(facets - np.roll(facets, 1, axis=1), axis=2).max(axis=1) <= CLUSTER * spacing
    bary, rule = _gauss_rule(d)
    points = np.einsum("qk,fkj->fqj", bary, facets[~small]).reshape(-1, d)
    weights = (measure[~small, None] * rule[None, :]).ravel()
    rule_normals = np.repeat(normals[~small], len(rule), axis=0)
    if not small.any():
        return points, weights, rule_normals
    merged = clustered_rule(facets[small], measure[small], normals[small], CLUSTER * spacing)
    return tuple(np.concatenate(pair) for pair in zip((points, weights, rule_normals), merged))


def _box_centroids(facets: np.ndarray, origin: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The one-point rule of each facet's part in each box of the lattice ``origin`` + j ``step``
    [m]: its centroid, measure and the facet's unit normal (points [Q, d], weights [Q], normals [Q,
    d]). The cuts leave a part as several triangles (a box's section of a plane has up to six
    sides); one point for all of them is as exact for what is linear in the box, at about a tenth of
    the points (a sphere's 20,480 facets at h = 1/48: 1.35 M triangles)."""
    d = facets.shape[-1]
    pieces, parent = lattice_pieces(facets, origin, step, parents=True)
    measure, _ = _measure_and_normal(pieces)
    keep = measure > 0
    pieces, parent, measure = pieces[keep], parent[keep], measure[keep]
    centre = pieces.mean(axis=1)
    box = np.floor((centre - origin) / step).astype(np.int64)
    lo = box.min(axis=0, initial=0)
    dims = tuple(int(v) for v in box.max(axis=0, initial=0) - lo + 1)
    key = parent * math.prod(dims) + np.ravel_multi_index(tuple((box - lo).T), dims)  # one sort, not rows'
    _, group = np.unique(key, return_inverse=True)
    group = group.ravel()
    weight = np.bincount(group, weights=measure)
    points = np.stack([np.bincount(group, weights=measure * centre[:, k]) for k in range(d)], axis=1) / weight[:, None]
    first = np.zeros(len(weight), dtype=np.int64)
    first[group] = parent
    _, normals = _measure_and_normal(facets[first])
    return points, weight, normals


def boundary_tractions(
    surface: Surface,
    region: Region,
    spacing: float,
    *,
    name: str,
    traction: np.ndarray | PointFunction | None = None,
    pressure: float | None = None,
    stress: np.ndarray | PointFunction | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature of a surface load on the surface patch of ``region``.

    Exactly one of: ``traction`` a constant vector [d] [Pa] or a callable points [Q, d] -> [Q, d];
    ``pressure`` p [Pa], traction -p n (positive pressure pushes into the surface); ``stress`` a
    constant Cauchy stress [d, d] [Pa] or a callable points [Q, d] -> [Q, d, d], traction sigma n
    (manufactured solutions). ``spacing`` is the grid's h [m] (sets the subdivision). ``name``
    names the boundary condition in errors; a region that selects no surface of positive area is
    one (:func:`select_patch`). Returns points [Q, d] [m], weights [Q] [m^2 | m] and tractions [Q, d] [Pa].
    """
    given = [k for k, v in (("traction", traction), ("pressure", pressure), ("stress", stress)) if v is not None]
    if len(given) != 1:
        raise ValueError(f"{name}: give exactly one of traction, pressure or stress, got {given or 'none'}")
    points, weights, normals = patch_quadrature(surface, region, spacing, name=name)
    return points, weights, tractions(points, normals, name=name, traction=traction, pressure=pressure, stress=stress)


def patch_quadrature(surface: Surface, region: Region, spacing: float, *, name: str, lattice: np.ndarray | None = None,
                     centroids: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`surface_quadrature` at ``spacing`` [m] on the surface patch of ``region`` (a region
    holding no surface is an error naming ``name``, :func:`select_patch`), its pieces cut at the
    planes of ``lattice`` when given, one point per piece with ``centroids``: points [Q, d] [m],
    weights [Q] [m^2 | m], unit outward normals [Q, d]."""
    d = surface.dim
    pieces, _ = select_patch(region, surface.vertices[surface.faces], name)
    return surface_quadrature(pieces.reshape(-1, d, d), spacing, centroids=centroids, lattice=lattice)


def tractions(points: np.ndarray, normals: np.ndarray, *, name: str, traction=None, pressure: float | None = None,
              stress=None) -> np.ndarray:
    """Traction [Q, d] [Pa] at surface points [Q, d] with unit outward normals [Q, d]: -p n for a
    pressure, sigma n for a stress (constant [d, d] or callable), else the traction (constant [d] or
    callable). ValueError naming ``name`` for a wrong shape or a non-finite value."""
    q, d = points.shape
    if pressure is not None:
        t = -float(pressure) * normals
    elif stress is not None:
        if callable(stress):
            sigma = evaluate(stress, points, (d, d), f"{name}: the stress")
        else:
            sigma = np.asarray(stress, dtype=float)
            sigma = np.broadcast_to(sigma, (q, d, d)) if sigma.shape == (d, d) else sigma
        if sigma.shape != (q, d, d):
            raise ValueError(f"{name}.stress: expected [{d}, {d}] or [{q}, {d}, {d}], got {sigma.shape}")
        t = np.einsum("qij,qj->qi", sigma, normals)
    else:
        if callable(traction):
            t = evaluate(traction, points, (d,), f"{name}: the traction")
        else:
            t = np.asarray(traction, dtype=float)
            t = np.broadcast_to(t, (q, d)) if t.shape == (d,) else t
        if t.shape != (q, d):
            raise ValueError(f"{name}.traction: expected [{d}] or [{q}, {d}], got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise BoundaryError(f"{name}: the traction is not finite at some surface points")
    return np.array(t)


def facet_measures(facets: np.ndarray) -> np.ndarray:
    """Area [m^2] (3D triangles) or length [m] (2D segments) [M] of simplices [M, d, d]."""
    return _measure_and_normal(np.asarray(facets, dtype=float))[0]


def area_vectors(facets: np.ndarray) -> np.ndarray:
    """Area [m^2] (3D) or length [m] (2D) times the unit outward normal [M, d] of simplices [M, d, d]."""
    measure, normals = _measure_and_normal(np.asarray(facets, dtype=float))
    return measure[:, None] * normals


def _measure_and_normal(facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area / length [M] and unit outward normal [M, d] of simplices [M, d, d] (zero normal if degenerate).

    The area vector is the generalised cross product of the d - 1 edge vectors: component k is the
    determinant of the edges stacked over e_k, signed (-1)^(d+1) so that it points out in both
    conventions (3D right-hand rule, 2D solid on the left); its length is (d - 1)! times the measure.
    """
    m, d = facets.shape[0], facets.shape[2]
    if m == 0:
        return np.zeros(0), np.zeros((0, d))
    edges = facets[:, 1:] - facets[:, :1]  # [M, d-1, d]
    rows = np.broadcast_to(np.eye(d)[None, :, None, :], (m, d, 1, d))
    stacked = np.concatenate([np.broadcast_to(edges[:, None], (m, d, d - 1, d)), rows], axis=2)
    area_vector = (-1) ** (d + 1) * np.linalg.det(stacked)  # [M, d]
    norm = np.linalg.norm(area_vector, axis=1)
    normals = area_vector / np.where(norm > 0, norm, 1.0)[:, None]
    return norm / math.factorial(d - 1), normals


def _gauss_rule(d: int) -> tuple[np.ndarray, np.ndarray]:
    """Degree-5 rule on the reference simplex of a (d-1)-dimensional facet: barycentric points [q, d]
    and weights [q] summing to 1 (fractions of the facet's measure)."""
    if d == 2:
        x, w = np.polynomial.legendre.leggauss(3)
        t = 0.5 * (1.0 + x)
        return np.stack([1.0 - t, t], axis=1), 0.5 * w
    r = math.sqrt(15.0)
    points, weights = [np.full(3, 1.0 / 3.0)], [9.0 / 40.0]
    for c, w in (((6.0 - r) / 21.0, (155.0 - r) / 1200.0), ((6.0 + r) / 21.0, (155.0 + r) / 1200.0)):
        for k in range(3):
            p = np.full(3, c)
            p[k] = 1.0 - 2.0 * c
            points.append(p)
            weights.append(w)
    return np.array(points), np.array(weights)
