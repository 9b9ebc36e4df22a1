"""Ghost samples: displacement samples outside the material that join the unknowns where a boundary's
surface points interpolate from them.

A surface point between the last active sample and the surface reads the displacement from the
samples around it; where the sample beyond the surface is missing, the renormalised interpolation
(``sampling.interpolate``) reads a constant extrapolation instead, so a load and a probe on a face
act up to h/2 inside it (the stress suite's cantilever: tip spread 7.14% over 16 sub-cell offsets
at W/8 with that, 2.78% with the ghosts).
A missing sample that an edge holding material ties to the body is determined by the discrete
energy as it stands (its edge was only pruned for want of the sample), so it can be an unknown:
then the interpolation is the full multilinear one there, and the load the transpose of it is
consistent with the energy (the shear edge's fraction and the load's weight on the ghost both grow
as the surface moves past the last sample).

Which samples are candidates is the caller's (``sampling.stencil_samples``): for loads, the
corners beyond the surface along its normal's dominant axis; a ghost beside a face (along it)
would take load the constant stress does not put there and break the patch tests.

A ghost holds no material, so it has no face fraction and no mass of its own: in dynamics a load
on it would move it at once. It is given the mass of the material its tying edges hold
(:func:`ghost_inertia`): the time a shear wave takes to cross a cell, as for its neighbours.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from ..grid import Grid
from . import kernels
from .layout import TileLayout, cell_bodies

if TYPE_CHECKING:
    from .operator import Level


def _tying_edges(d: int, a: int) -> Iterator[tuple[int, int, tuple[int, int]]]:
    """The shear edges that read sample (a, I): (pair number q, other axis b, (index shift, the
    other sample's shift)) for E = I (which also reads u_a(I - e_b)) and E = I + e_b (u_a(I + e_b)):
    edge (a, b) at E reads u_a(E), u_a(E - e_b), u_b(E), u_b(E - e_a)."""
    for q, pair in enumerate(kernels.PAIRS[d]):
        if a in pair:
            b = pair[1] if pair[0] == a else pair[0]
            yield q, b, (0, -1)
            yield q, b, (1, 1)


def ghost_faces(layout: TileLayout, vc: np.ndarray, ve: np.ndarray, candidates: list[np.ndarray],
                least: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Active faces [d, size] bool: those beside material (a cell on either side holds some), and
    the ``candidates`` (per component a [k, d] sample indices) that share an edge holding at least
    ``least`` of material (exact fractions ve, before any sliver is raised) with three active
    samples; a candidate no edge ties stays out, and so does one whose edges hold material of two
    bodies (:func:`_one_body`). Also the positions [k, d] (grid index units, the samples' own) of
    the candidates left out for that.

    ``least``: a sliver edge's weight is raised to the operator's least (MIN_FRACTION), so a ghost it
    ties would add that stiffness; where a float32 face lies through samples (a 0.3 m box on a 0.05 m
    grid: 0.15 stored as 0.15000000596) its edges hold 1.2e-7 and each constant shear stress came out
    1.15e-3 off. Left out, the point's weight on the ghost (as small as the sliver) is renormalised.
    The caller passes the mesh's round-off: real slivers on curved holds keep their ghosts (all of
    them below MIN_FRACTION left out, the held annulus's L1 error at N = 256 rose 8%)."""
    d = layout.dim
    active = _beside_material(layout, vc)
    eye = np.eye(d, dtype=np.int64)
    bodies = None

    def on(a: int, index: np.ndarray) -> np.ndarray:
        p = layout.positions(index)
        return (p >= 0) & active[a, np.maximum(p, 0)]

    extra, apart = [], [np.zeros((0, d))]
    for a, cand in enumerate(candidates):
        p = layout.positions(cand)
        cand = cand[(p >= 0) & ~active[a, np.maximum(p, 0)]]
        # reads: the edges that would read the ghost once it is an unknown (any material: slivers are
        # raised, not dropped); tied: those holding more than the round-off, which make it one
        reads = np.zeros((len(cand), 2 * (d - 1)), dtype=bool)
        tied = np.zeros_like(reads)
        for j, (q, b, (shift, other)) in enumerate(_tying_edges(d, a)):
            edge = cand + shift * eye[b]
            pe = layout.positions(edge)
            held = ve[q, np.maximum(pe, 0)]
            reads[:, j] = ((pe >= 0) & (held > 0) & on(a, cand + other * eye[b]) & on(b, edge)
                           & on(b, edge - eye[a]))
            tied[:, j] = reads[:, j] & (held >= least)
        keep = tied.any(axis=1)
        if keep.any():
            if bodies is None:
                bodies = layout.flat(cell_bodies(layout, vc))
            one = _one_body(layout, bodies, a, cand[keep], reads[keep])
            apart.append(cand[keep][~one] + 0.5 - 0.5 * eye[a])
            keep[keep] = one
        extra.append((a, layout.positions(cand[keep])))
    for a, p in extra:
        active[a, p] = True
    return active, np.concatenate(apart)


def _one_body(layout: TileLayout, bodies: np.ndarray, a: int, cand: np.ndarray, tied: np.ndarray) -> np.ndarray:
    """Whether the edges that read samples (a, ``cand`` [k, d]) (``tied`` [k, edges] of
    :func:`_tying_edges`, slivers included) hold the material of one body only. A ghost between two bodies less than two cells apart
    would couple them through its shear edges, in some motions and not others: two squares 1.44 cells
    apart then had neither one body's rigid modes nor two's (one relative motion costs energy, one
    does not), and a free pair was refused as unbalanced. Each edge's four cells touch along it, so
    its material is one body's."""
    d = layout.dim
    eye = np.eye(d, dtype=np.int64)
    low = np.full(len(cand), np.iinfo(np.int32).max)
    high = np.zeros(len(cand), dtype=np.int64)
    for j, (_, b, (shift, _)) in enumerate(_tying_edges(d, a)):
        edge = cand + shift * eye[b]
        for sa, sb in itertools.product((0, 1), repeat=2):  # the edge's four cells
            p = layout.positions(edge - sa * eye[a] - sb * eye[b])
            label = np.where(tied[:, j] & (p >= 0), bodies[np.maximum(p, 0)], 0)
            low = np.where(label > 0, np.minimum(low, label), low)
            high = np.maximum(high, label)
    return (high == 0) | (low == high)


def float32_fraction(grid: Grid) -> float:
    """The fraction [1] of a control volume that a face's float32 round-off can fill: four units of
    float32's last place at the grid's largest coordinate, over h (meshes arrive in float32: STL,
    PLY, GLB)."""
    corners = np.abs([grid.origin, np.asarray(grid.origin) + grid.spacing * np.asarray(grid.shape)])
    return 4.0 * 2.0**-24 * float(corners.max()) / grid.spacing


def ghost_inertia(level: Level) -> np.ndarray:
    """Mass fractions [d, size] of the level's ghost samples (zero elsewhere): the largest fraction
    of the edges that tie each to the body. Its mass rho h^d ve over the edges' stiffness mu ve
    h^(d-2) gives the shear crossing time of a cell, like the samples inside; the body's mass grows
    by that of a layer of ghosts, O(h) of the loaded surface's."""
    lay, d = level.layout, level.dim
    ghost = level.active & ~_beside_material(lay, level.vc_host)
    out = np.zeros((d, lay.size))
    index = lay.indices()
    eye = np.eye(d, dtype=np.int64)
    for a in range(d):
        p = np.nonzero(ghost[a, : len(index)])[0]
        for q, b, (shift, _) in _tying_edges(d, a):
            pe = lay.positions(index[p] + shift * eye[b])
            out[a, p] = np.maximum(out[a, p], np.where(pe >= 0, level.ve_host[q, np.maximum(pe, 0)], 0.0))
    return out


def _beside_material(layout: TileLayout, vc: np.ndarray) -> np.ndarray:
    """[d, size] bool: faces with a cell holding material on either side."""
    found = np.zeros((layout.dim, layout.size), dtype=np.int32)
    kernels.active_faces(layout.dim, np.ascontiguousarray(layout.coords, dtype=np.int32),
                         np.ascontiguousarray(layout.tile_map, dtype=np.int32),
                         np.ascontiguousarray(vc, dtype=np.float64), found)
    return found.astype(bool)
