"""Bodies the staggered grid joins: separate solids of the mesh that share a cell.

The energy weighs each control volume by all the solid inside it, whatever body it belongs to, so
two bodies closer than a cell act as one solid there: two bars stacked 1 cm apart on a 6 cm grid bent
as one welded bar (tip 0.032 m against 0.187 m for two bars), a bar cut through by a 5 mm gap held its
loose half. DG slices each cell into its connected pieces and keeps them apart. The warning names
the bodies and where; it cannot tell a gap from a contact, so it says what either means.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..boundary import area_vectors
from ..geometry.surface import Surface
from ..geometry.topology import shells
from ..grid import Grid
from ..subdivision import subdivided
from .layout import cell_bodies
from .operator import Level

MAX_BODIES = 500  # beyond this many separate solids (a scan's specks) the check is skipped
JOINED = "separate bodies of the mesh share grid cells"  # how the warning is found again
CLOSE = "separate bodies lie less than two cells apart"


def joined_bodies_warning(surface: Surface, level: Level, grid: Grid) -> list[str]:
    """A warning [0 or 1] when outer shells of the closed ``surface`` fall into one connected region
    of cells holding material on ``level`` (the fine level) of ``grid``."""
    if not surface.closed:
        return []
    count, shell = _shells(surface)
    if count < 2:
        return []
    facets = surface.vertices[surface.faces]
    h = grid.spacing
    volume = np.bincount(shell, weights=_volume_terms(facets), minlength=count)
    outer = np.nonzero(volume > 0)[0]
    if not 2 <= len(outer) <= MAX_BODIES:
        return []
    labels = cell_bodies(level.layout, level.vc_host)
    origin = np.asarray(grid.origin, dtype=float)
    owners: dict[int, set[int]] = {}
    points: dict[int, np.ndarray] = {}
    for s in outer:
        pieces = subdivided(facets[shell == s], 0.5 * h)
        vectors = area_vectors(pieces)
        size = np.linalg.norm(vectors, axis=1)
        keep = size > 0
        # a point just inside the solid: its cell holds this body's material
        x = pieces[keep].mean(axis=1) - 1e-3 * h * vectors[keep] / size[keep, None]
        index = np.clip(np.floor((x - origin) / h).astype(np.int64), 0, np.asarray(labels.shape) - 1)
        found = labels[tuple(index.T)]
        points[int(s)] = x
        for lab in np.unique(found[found > 0]):
            owners.setdefault(int(lab), set()).add(int(s))
    joined = [sorted(ss) for ss in owners.values() if len(ss) > 1]
    if not joined:
        return []
    bodies = sorted({s for ss in joined for s in ss})
    # where two of them come closest
    a, b = joined[0][:2]
    gap, nearest = cKDTree(points[b]).query(points[a])
    i = int(np.argmin(gap))
    near = ", ".join(f"{c:.4g}" for c in 0.5 * (points[a][i] + points[b][nearest[i]]))
    return [
        f"{len(bodies)} {JOINED} (h = {h:.4g} m), e.g. near ({near}) m: the "
        "staggered method joins bodies that lie within a cell of each other into one solid there (bonded where they "
        "touch, and also across a gap narrower than a cell); if they should stay apart, refine the grid until each "
        "gap spans more than a cell, or use method.kind 'dg', which keeps the bodies apart"
    ]


def _shells(surface: Surface) -> tuple[int, np.ndarray]:
    """(count, shell label per face [k]): triangles joined across manifold edges (3D), segments
    across vertices two of them share (2D)."""
    faces, n = surface.faces, len(surface.vertices)
    if surface.dim == 3:
        return shells(faces, n)[:2]
    counts = np.bincount(faces.reshape(-1), minlength=n)
    corner = np.argsort(faces.reshape(-1), kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])[counts == 2]
    a, b = corner[start] // 2, corner[start + 1] // 2
    return connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(len(faces),) * 2), directed=False)


def _volume_terms(facets: np.ndarray) -> np.ndarray:
    """Each face's term [k] of the enclosed volume (3D) or area (2D) by the divergence theorem."""
    if facets.shape[-1] == 3:
        return np.einsum("ij,ij->i", facets[:, 0], np.cross(facets[:, 1], facets[:, 2])) / 6.0
    return (facets[:, 0, 0] * facets[:, 1, 1] - facets[:, 1, 0] * facets[:, 0, 1]) / 2.0


def close_bodies_warning(level: Level) -> list[str]:
    """A warning [0 or 1] when ghost samples were left out of ``level`` (the fine level) because they
    lie between two bodies (``ghosts.ghost_faces``): the faces there act inside the solid."""
    apart = level.ghosts_apart
    if apart is None or not len(apart):
        return []
    h = level.spacing
    near = ", ".join(f"{c:.4g}" for c in np.asarray(level.origin) + h * apart[0])
    return [
        f"{CLOSE} (h = {h:.4g} m), e.g. near ({near}) m: a displacement sample between two of them would tie "
        f"them together, so {len(apart)} such sample(s) are left out, and where a boundary acts on the faces that "
        "look at each other it reads and loads the solid up to h/2 inside them (two squares 1.44 cells apart under "
        "a constant stress: 37% of it off in their corner cells); refine the grid until each gap spans more than two "
        "cells, or use method.kind 'dg', which keeps the bodies apart"
    ]
