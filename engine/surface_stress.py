"""Stress on the surface, for every method: a method's raw stress at the surface vertices, made to
carry the traction the boundaries apply.

A method knows its stress best inside the body; at the surface its raw value (a one-sided fit, an
element polynomial) says little about sigma n, which the boundary conditions know exactly: zero
on a free surface, the applied traction on a loaded patch. Each vertex's stress is therefore the
symmetric tensor closest to the raw one (Frobenius norm) among those with sigma n = t for the
facets around it whose traction is known: one condition per face meeting at the vertex (one where
the surface is smooth, one per side of a sharp edge), with that face's mean normal and the loads'
traction at the vertex with that normal (:func:`recover`). On a flat free face that replaces the
normal row of sigma and keeps the in-plane stresses; at a free edge or corner it zeroes what the
faces say. Facets of a displacement patch carry an unknown reaction and add no condition.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .blas import on_one_thread
from .boundary import Prescribed, SurfaceLoad, _measure_and_normal, select_patch
from .geometry.surface import Surface
from .grid import axis_pairs
from .material import stress, strain_fields

STIFF = 1e8  # weight of the traction conditions against the raw stress (per unit area share)
FEATURE_ANGLE = 30.0  # degrees: facets around a vertex whose normals differ more belong to different faces


@dataclass(frozen=True)
class FacetTractions:
    """What the boundaries fix of sigma n on each facet of a surface: ``known`` [F] bool (free or
    loaded; False on displacement patches), the surface ``loads`` and ``members`` [L, F] bool, the
    known facets in each load's patch (none: a free facet), ``normals`` [F, d] unit outward,
    ``areas`` [F] [m^2 | m]."""

    known: np.ndarray
    loads: tuple[SurfaceLoad, ...]
    members: np.ndarray
    normals: np.ndarray
    areas: np.ndarray


def facet_tractions(surface: Surface, loads: list[SurfaceLoad], prescribed: list[Prescribed]) -> FacetTractions:
    """Classify the facets of ``surface``: a facet belongs to a boundary's patch when at least half
    its area lies in the patch (later loads add to earlier ones, as the methods apply them)."""
    facets = surface.vertices[surface.faces]
    areas, normals = _measure_and_normal(facets)
    known = np.ones(len(facets), dtype=bool)
    for bc in prescribed:
        known &= ~_in_patch(bc.region, facets, areas, bc.name)
    members = np.array([_in_patch(load.region, facets, areas, load.name) & known for load in loads],
                       dtype=bool).reshape(len(loads), len(facets))
    return FacetTractions(known, tuple(loads), members, normals, areas)


def _in_patch(region, facets: np.ndarray, areas: np.ndarray, name: str) -> np.ndarray:
    pieces, source = select_patch(region, facets, name)
    covered = np.bincount(source, weights=_measure_and_normal(pieces)[0], minlength=len(facets))
    return covered >= 0.5 * areas


@on_one_thread
def recover(surface: Surface, raw: np.ndarray, tractions: FacetTractions, load_scale: float = 1.0,
            feature_angle: float = FEATURE_ANGLE) -> np.ndarray:
    """Stress [m, d, d] [Pa] at the surface vertices from the method's raw stress ``raw`` [m, d, d]
    (NaN rows stay NaN) with sigma n = ``load_scale`` t where the incident facets' traction is known.

    The facets around a vertex are grouped into the faces that meet there (:func:`_faces_at`:
    normals within ``feature_angle`` of each other), and each face gives one condition with its
    unit mean normal (weighted as in :func:`_normal_weights`) and the loads' traction at the vertex
    with that normal, each load by its patch's share of the face. On a smooth surface that is
    one condition per vertex; asking it of every facet would pin the tangential stresses too (on a
    facetted sphere under pressure each tilted facet normal adds -p to the hoop stress; at a
    256-gon hole's rim two wall facets 1.4 degrees apart zero it). ``feature_angle`` 0: every facet
    is its own face."""
    d = surface.dim
    raw = np.asarray(raw, dtype=float)
    m = len(surface.vertices)
    k = tractions.known
    faces = surface.faces[k]
    normals = tractions.normals[k]
    corner_v = faces.ravel()  # [F * d]: the vertex of each (facet, corner)
    corner_f = np.repeat(np.arange(len(faces)), d)
    weight = _normal_weights(surface.vertices, faces)
    total = np.bincount(corner_v, weights=weight, minlength=m)
    pairs = axis_pairs(d)
    nv = d + len(pairs)
    lhs = np.zeros((m, nv, nv))
    rhs = np.zeros((m, nv))
    if len(corner_v):
        members = tractions.members[:, k][:, corner_f]
        _add_faces(lhs, rhs, surface.vertices, corner_v, normals[corner_f], (tractions.loads, members, load_scale),
                   weight, total, np.cos(np.radians(feature_angle)))
    # the raw stress in the Frobenius norm (in Voigt slots the shear counts twice)
    metric = np.concatenate([np.ones(d), 2 * np.ones(len(pairs))])
    s_raw = to_voigt(raw)
    good = np.all(np.isfinite(s_raw), axis=1)
    lhs[:, range(nv), range(nv)] += metric
    rhs += metric * np.where(good[:, None], s_raw, 0.0)
    out = np.full((m, nv), np.nan)
    out[good] = np.linalg.solve(lhs[good], rhs[good][..., None])[..., 0]
    return from_voigt(out, d)


def _add_faces(lhs: np.ndarray, rhs: np.ndarray, points: np.ndarray, vertex: np.ndarray, normals: np.ndarray,
               loads: tuple[tuple[SurfaceLoad, ...], np.ndarray, float], weight: np.ndarray, total: np.ndarray,
               cos_angle: float) -> None:
    """Add to the vertices' normal equations one condition per face meeting there: the
    incidences (vertex [N], facet normal [N, d], weight [N]) grouped by :func:`_faces_at`, each
    group with its unit mean normal n, its share of the weight and the traction sum_l s_l t_l(x, n):
    ``loads`` = (the loads, members [L, N] whether each incidence's facet is in load l's patch, the
    load scale), s_l load l's share of the group's weight, x the vertex (``points`` [m, d]).

    The loads are evaluated at the vertex with n rather than averaged over the facets: a pressure's
    facet tractions -p n_f average to -p |mean n_f| n, short of -p n by the facets' spread (4e-3 p
    on an icosphere of 642 vertices, whatever the grid), and sigma n = t then held no uniform state."""
    d = normals.shape[1]
    group = _faces_at(vertex, normals, cos_angle)
    g_w = np.bincount(group, weights=weight).astype(float)
    g_n = np.stack([np.bincount(group, weights=weight * normals[:, j]) for j in range(d)], 1)
    g_v = np.zeros(len(g_w), dtype=np.int64)
    g_v[group] = vertex
    g_n /= np.maximum(np.linalg.norm(g_n, axis=1), 1e-300)[:, None]
    g_t = np.zeros_like(g_n)
    each, members, scale = loads
    for load, member in zip(each, members):
        share = np.bincount(group, weights=weight * member, minlength=len(g_w)) / np.maximum(g_w, 1e-300)
        on = share > 0
        if on.any():
            g_t[on] += scale * share[on, None] * load.tractions(points[g_v[on]], g_n[on])
    a_f, b_f = _conditions(g_n, g_t, d)
    share = g_w / total[g_v]
    np.add.at(lhs, g_v, STIFF * share[:, None, None] * a_f)
    np.add.at(rhs, g_v, STIFF * share[:, None] * b_f)


def _faces_at(vertex: np.ndarray, normals: np.ndarray, cos_angle: float) -> np.ndarray:
    """Group id [N] of each incidence (its vertex [N], facet normal [N, d]): greedily, the first
    ungrouped incidence of a vertex seeds a group that takes every ungrouped incidence of that
    vertex whose normal is within the angle of the seed's; a box corner gives 3 groups, a hole's
    rim 2 (its wall's facets turning by a degree each stay one)."""
    group = np.full(len(vertex), -1, dtype=np.int64)
    next_id = 0
    while (group < 0).any():
        open_ = np.nonzero(group < 0)[0]
        seed = np.full(vertex.max() + 1, len(vertex), dtype=np.int64)
        np.minimum.at(seed, vertex[open_], open_)
        s = seed[vertex[open_]]
        join = (np.einsum("ij,ij->i", normals[open_], normals[s]) >= cos_angle) | (open_ == s)  # a seed joins its own
        ids = np.unique(vertex[open_][join], return_inverse=True)[1]
        group[open_[join]] = next_id + ids
        next_id += int(ids.max()) + 1 if len(ids) else 0
    return group


def _normal_weights(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Weight [F * d] of each (facet, corner) in its vertex's normal: Max's (1999) |a x b| /
    (|a|^2 |b|^2) for the two edges a, b leaving the corner in 3D, 1 / length in 2D; both give the
    exact normal where the vertices lie on a sphere / circle (area weights are first order on an
    irregular mesh: 9e-3 p of error in the recovered stress of a pressurised icosphere shell)."""
    corners = vertices[faces]  # [F, d, d]
    d = faces.shape[1]
    if d == 2:
        length = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
        return np.repeat(1.0 / np.maximum(length, 1e-300), 2)
    out = np.empty((len(faces), 3))
    for k in range(3):
        a = corners[:, (k + 1) % 3] - corners[:, k]
        b = corners[:, (k + 2) % 3] - corners[:, k]
        out[:, k] = np.linalg.norm(np.cross(a, b), axis=1) / np.maximum(
            np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b), 1e-300)
    return out.ravel()


def _conditions(normals: np.ndarray, traction: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Normal equations (A^T A [N, nv, nv], A^T t [N, nv]) of sigma n = t in Voigt slots."""
    pairs = axis_pairs(d)
    nv = d + len(pairs)
    rows = np.zeros((len(normals), d, nv))
    for a in range(d):
        rows[:, a, a] = normals[:, a]
    for q, (a, b) in enumerate(pairs):
        slot = d + _voigt_order(d).index((a, b))
        rows[:, a, slot] = normals[:, b]
        rows[:, b, slot] = normals[:, a]
    return np.einsum("nai,naj->nij", rows, rows), np.einsum("nai,na->ni", rows, traction)


def _voigt_order(d: int) -> list[tuple[int, int]]:
    """The shear pairs in Voigt order (yz, xz, xy | xy)."""
    return [(1, 2), (0, 2), (0, 1)] if d == 3 else [(0, 1)]


def to_voigt(sigma: np.ndarray) -> np.ndarray:
    """Symmetric tensors [..., d, d] -> Voigt [..., 6 | 3] (xx, yy, zz, yz, xz, xy | xx, yy, xy)."""
    d = sigma.shape[-1]
    order = _voigt_order(d)
    return np.stack([sigma[..., a, a] for a in range(d)] + [sigma[..., a, b] for a, b in order], axis=-1)


def from_voigt(voigt: np.ndarray, d: int) -> np.ndarray:
    """Voigt [..., 6 | 3] -> symmetric tensors [..., d, d]."""
    order = _voigt_order(d)
    out = np.empty(voigt.shape[:-1] + (d, d))
    for a in range(d):
        out[..., a, a] = voigt[..., a]
    for i, (a, b) in enumerate(order):
        out[..., a, b] = out[..., b, a] = voigt[..., d + i]
    return out


def surface_fields(surface: Surface, raw: np.ndarray, names: list[str], lame: tuple[float, float],
                   tractions: FacetTractions, load_scale: float = 1.0) -> dict[str, np.ndarray]:
    """The requested stress fields ("strain", "stress", "von_mises", "pressure") at the surface
    vertices from the raw vertex stress [m, d, d] [Pa], after :func:`recover`; the strain is the
    recovered stress through the inverse material law."""
    d = surface.dim
    lam, mu = lame
    sigma = to_voigt(recover(surface, raw, tractions, load_scale))
    # eps = (sigma - lambda tr(eps) I) / (2 mu), tr(eps) = tr(sigma) / (d lambda + 2 mu)  (plane strain in 2D)
    trace = sigma[..., :d].sum(axis=-1, keepdims=True) / (d * lam + 2 * mu)
    strain = sigma / (2 * mu)
    strain[..., :d] -= lam * trace / (2 * mu)
    return strain_fields(strain, names, lam, mu, d)


class SurfaceStress:
    """Mixin of a method (both use it): its surface's facet tractions, classified once, and the
    surface stress fields from its raw strain at the surface vertices. Needs ``surface``,
    ``surface_loads``, ``prescribed`` and ``material``."""

    _tractions: FacetTractions | None = None

    def facet_tractions(self) -> FacetTractions:
        """Which surface facets are free, loaded or held (computed once)."""
        if self._tractions is None:
            self._tractions = facet_tractions(self.surface, self.surface_loads, self.prescribed)
        return self._tractions

    def surface_stress(self, strain: np.ndarray, names: list[str], load_scale: float = 1.0) -> dict[str, np.ndarray]:
        """The requested stress fields at the surface vertices (:func:`surface_fields`) from the
        method's raw Voigt strain there [m, 6 | 3], with the surface loads scaled by ``load_scale``."""
        d = self.surface.dim
        lam, mu = self.material.lame
        raw = from_voigt(stress(strain, lam, mu, d), d)
        return surface_fields(self.surface, raw, names, (lam, mu), self.facet_tractions(), load_scale)
