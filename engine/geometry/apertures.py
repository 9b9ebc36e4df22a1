"""Face apertures and cells' area vectors, exact by the scan conversion's column sums.

The solid's area on a grid plane x_a = p, inside one face's square, is the signed projected area
(onto that plane, up-facing + along a) of the surface fragments above p in the square's column:
the scan conversion of ``fractions.py`` with axis a taken as its vertical axis, at cell size, and
one reverse cumulative sum per column. The same scan, without the sum, gives each cell's area
vector int n dA of the surface in it, for open pieces too. Apertures so taken satisfy every cell's
divergence theorem to round-off,

    sum_a (alpha(a, I + e_a) - alpha(a, I)) h^(d-1) e_a = -int_(surface in I) n dA,

which a finite-volume divergence needs to give a constant field none (``staggered.held``).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .surface import Surface

CHUNK_BYTES = 32 * 2**20  # the scan's dense [x, y(, z)] arrays per chunk of columns
PLANE_TOLERANCE = 1e-9  # [cells]: a facet this close to a plane of cell faces lies on it


def face_apertures(surface: Surface, origin: np.ndarray, spacing: float, axis: int, faces: np.ndarray) -> np.ndarray:
    """Solid share [k] in [0, 1] of the ``axis``-faces at cell indices ``faces`` [k, d] of a grid of
    ``origin`` [d] [m] and ``spacing`` [m]: face (a, I) is the square (segment) of cell I's lower
    a-face, in the plane x_a = origin_a + spacing I_a. ``surface``: closed, outward-oriented."""
    facets = surface.vertices[surface.faces]
    out = np.zeros(len(faces))
    for wanted, at, cover in _covers(facets, origin, spacing, axis, faces):
        above = np.cumsum(cover[..., ::-1], axis=-1)[..., ::-1]  # the area at each layer's lower plane
        out[wanted] = above[at]
    return np.clip(out, 0.0, 1.0)


def cell_area_vectors(facets: np.ndarray, origin: np.ndarray, spacing: float, cells: np.ndarray) -> np.ndarray:
    """int n dA [k, d] [m^(d-1)] of the pieces ``facets`` [M, d, d] (oriented as a ``Surface``'s faces,
    closed or not) inside each of ``cells`` [k, d] (indices) of the grid of ``origin`` and ``spacing``."""
    d = facets.shape[-1]
    out = np.zeros((len(cells), d))
    for axis in range(d):
        for wanted, at, cover in _covers(facets, origin, spacing, axis, cells):
            out[wanted, axis] = cover[at]
    return out * spacing ** (d - 1)


def _covers(facets: np.ndarray, origin: np.ndarray, spacing: float, axis: int,
            cells: np.ndarray) -> Iterator[tuple[np.ndarray, tuple, np.ndarray]]:
    """The scan with ``axis`` vertical over the columns of ``cells`` [k, d], in chunks: (which
    cells [j], their index into the chunk's arrays, the chunk's cover [x, y(, z)]: each cell's signed
    projected area, in cells, of the fragments inside it)."""
    from ..runtime import ensure_initialized
    from . import kernels

    cells = np.asarray(cells, dtype=np.int64)
    d = facets.shape[-1]
    if not len(cells) or not len(facets):
        return
    ensure_initialized()
    # the scan's last axis is ``axis``: 3D cyclic (orientation kept), 2D a swap (solid side flipped)
    order = [(axis + 1 + k) % d for k in range(d)]
    f = ((np.asarray(facets, dtype=float) - np.asarray(origin, dtype=float)) / spacing)[:, :, order]
    local = cells[:, order]
    if d == 2 and axis == 0:
        f = f[:, ::-1]  # reversed segments keep the solid on their left after the swap
    if d == 3:  # facets parallel to the scan axis have no projected area
        e1, e2 = f[:, 1, :2] - f[:, 0, :2], f[:, 2, :2] - f[:, 0, :2]
        up = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    else:
        up = f[:, 0, 0] - f[:, 1, 0]
    f = f[up != 0]
    if not len(f):
        return
    # a facet lying on a plane of cell faces belongs to the cell on its solid side (whose face there is
    # then a wall): just below the plane if it faces up, just above if down, whatever the round-off
    z = f[:, :, -1]
    flat = (np.ptp(z, axis=1) <= PLANE_TOLERANCE) & (np.abs(z - np.round(z[:, :1])).max(axis=1) <= PLANE_TOLERANCE)
    side = np.where(up[up != 0] > 0, -PLANE_TOLERANCE, PLANE_TOLERANCE)
    f[flat, :, -1] = np.round(z[flat, :1]) + side[flat, None]
    # columns of the wanted cells; layers over every facet along the axis (a column sum needs all)
    lo = local[:, :-1].min(axis=0)
    zlo = int(np.floor(f[:, :, -1].min())) - 1
    nz = int(np.ceil(f[:, :, -1].max())) + 1 - zlo
    shift = np.append(lo, zlo)
    f = f - shift
    local = local - shift
    span = local[:, :-1].max(axis=0) + 1
    tail = tuple(int(n) for n in span[1:]) + (nz,)
    width = max(1, CHUNK_BYTES // (8 * int(np.prod(tail))))
    first_lo, first_hi = f[:, :, 0].min(axis=1), f[:, :, 0].max(axis=1)
    scan = kernels.scan_triangles if d == 3 else kernels.scan_segments
    for x0 in range(0, int(span[0]), width):
        n0 = min(width, int(span[0]) - x0)
        wanted = np.nonzero((local[:, 0] >= x0) & (local[:, 0] < x0 + n0) & (local[:, -1] >= 0) & (local[:, -1] < nz))[0]
        if not len(wanted):
            continue
        volume = np.zeros((n0,) + tail)
        cover = np.zeros_like(volume)
        sel = (first_hi >= x0) & (first_lo <= x0 + n0)
        if sel.any():
            scan(np.ascontiguousarray(f[sel]), x0, volume, cover)
        at = local[wanted]
        yield wanted, (at[:, 0] - x0,) + tuple(at[:, k] for k in range(1, d)), cover
