"""Taichi kernels of the exact scan conversion (volume of the solid in every sub-cell).

Coordinates are in sub-cell units: sub-cell (i, j[, k]) is the unit box [i, i+1) x [j, j+1) ...
For a closed, outward-oriented surface the solid's indicator is the signed count of facets above
a point (up-facing +1, down-facing -1), so the solid volume in a sub-cell is the sum, over the
facet fragments in its column, of the prisms between each fragment and the sub-cell's floor
(clamped to the sub-cell's height). A fragment lying inside sub-cell (i, j, k) contributes
``∫ (z - k) dA`` to that sub-cell and its signed projected area ``a`` to every sub-cell below it.
The kernels add the first to ``volume`` and the second to ``cover``; the orchestration turns
``cover`` into the "every sub-cell below" part with one cumulative sum per column.
Facets are clipped by the grid planes with Sutherland-Hodgman, the clip coordinate set exactly
to the plane so that neighbouring sub-cells partition each facet without gaps.
"""


import taichi as ti

# A triangle clipped by the six faces of a box has at most 3 + 6 vertices.
MAX_VERTICES = 9
Polygon = ti.types.matrix(MAX_VERTICES, 3, ti.f64)


@ti.func
def clip_polygon(p: ti.template(), n: ti.i32, axis: ti.i32, bound: ti.f64, side: ti.f64):
    """Part of the planar polygon ``p[:n]`` where ``side * (x[axis] - bound) >= 0``."""
    q = Polygon(0.0)
    m = 0
    for e in range(n):
        f = (e + 1) % n
        ce = side * (p[e, axis] - bound)
        cf = side * (p[f, axis] - bound)
        if ce >= 0:
            for c in ti.static(range(3)):
                q[m, c] = p[e, c]
            m += 1
        if (ce >= 0 and cf < 0) or (ce < 0 and cf >= 0):
            t = ce / (ce - cf)
            for c in ti.static(range(3)):
                q[m, c] = p[e, c] + t * (p[f, c] - p[e, c])
            q[m, axis] = bound  # exactly on the plane: neighbours share the cut edge
            m += 1
    return q, m


@ti.func
def prism_moments(p: ti.template(), n: ti.i32):
    """Signed xy-projected area of polygon ``p[:n]`` and the signed integral of z over it."""
    area = 0.0
    first = 0.0
    for e in range(1, n - 1):
        a = 0.5 * ((p[e, 0] - p[0, 0]) * (p[e + 1, 1] - p[0, 1]) - (p[e + 1, 0] - p[0, 0]) * (p[e, 1] - p[0, 1]))
        area += a
        first += a * (p[0, 2] + p[e, 2] + p[e + 1, 2]) / 3.0
    return area, first


@ti.func
def slab_range(lo: ti.f64, hi: ti.f64, lower: ti.i32, upper: ti.i32):
    """Integer slabs [k, k+1) meeting [lo, hi], clamped to [lower, upper); a flat range gets one slab."""
    k0 = ti.cast(ti.floor(lo), ti.i32)
    k1 = ti.max(ti.cast(ti.ceil(hi), ti.i32), k0 + 1)
    return ti.max(k0, lower), ti.min(k1, upper)


@ti.kernel
def scan_triangles(
    tri: ti.types.ndarray(dtype=ti.f64, ndim=3),
    x0: ti.i32,
    volume: ti.types.ndarray(dtype=ti.f64, ndim=3),
    cover: ti.types.ndarray(dtype=ti.f64, ndim=3),
):
    """Accumulate triangles ``tri`` [N, 3, 3] into sub-cell columns ``x0 .. x0 + volume.shape[0]``.

    volume, cover: [nx_chunk, ny, nz] (sub-cell units), indexed relative to ``x0`` along x.
    """
    for t in range(tri.shape[0]):
        p = Polygon(0.0)
        for v, c in ti.static(ti.ndrange(3, 3)):
            p[v, c] = tri[t, v, c]
        lo = ti.min(p[0, 0], p[1, 0], p[2, 0])
        hi = ti.max(p[0, 0], p[1, 0], p[2, 0])
        i0, i1 = slab_range(lo, hi, x0, x0 + volume.shape[0])
        for i in range(i0, i1):
            a, na = clip_polygon(p, 3, 0, ti.f64(i), 1.0)
            a, na = clip_polygon(a, na, 0, ti.f64(i + 1), -1.0)
            if na >= 3:
                scan_column(a, na, i - x0, volume, cover)


@ti.func
def scan_column(a: ti.template(), na: ti.i32, ix: ti.i32, volume: ti.template(), cover: ti.template()):
    ylo, yhi = a[0, 1], a[0, 1]
    for e in range(1, na):
        ylo, yhi = ti.min(ylo, a[e, 1]), ti.max(yhi, a[e, 1])
    j0, j1 = slab_range(ylo, yhi, 0, volume.shape[1])
    for j in range(j0, j1):
        b, nb = clip_polygon(a, na, 1, ti.f64(j), 1.0)
        b, nb = clip_polygon(b, nb, 1, ti.f64(j + 1), -1.0)
        if nb >= 3:
            zlo, zhi = b[0, 2], b[0, 2]
            for e in range(1, nb):
                zlo, zhi = ti.min(zlo, b[e, 2]), ti.max(zhi, b[e, 2])
            k0, k1 = slab_range(zlo, zhi, 0, volume.shape[2])
            for k in range(k0, k1):
                c, nc = clip_polygon(b, nb, 2, ti.f64(k), 1.0)
                c, nc = clip_polygon(c, nc, 2, ti.f64(k + 1), -1.0)
                if nc >= 3:
                    area, first = prism_moments(c, nc)
                    volume[ix, j, k] += first - k * area
                    cover[ix, j, k] += area


@ti.kernel
def scan_segments(
    seg: ti.types.ndarray(dtype=ti.f64, ndim=3),
    x0: ti.i32,
    volume: ti.types.ndarray(dtype=ti.f64, ndim=2),
    cover: ti.types.ndarray(dtype=ti.f64, ndim=2),
):
    """2D analogue of :func:`scan_triangles`: segments ``seg`` [N, 2, 2], solid on their left.

    A segment running in -x has the solid below it (up-facing), hence the signed length x0 - x1.
    volume, cover: [nx_chunk, ny].
    """
    for s in range(seg.shape[0]):
        ax, ay, bx, by = seg[s, 0, 0], seg[s, 0, 1], seg[s, 1, 0], seg[s, 1, 1]
        if ax != bx:
            i0, i1 = slab_range(ti.min(ax, bx), ti.max(ax, bx), x0, x0 + volume.shape[0])
            for i in range(i0, i1):
                # parametrise by x so each column gets the sub-segment over [i, i+1] exactly
                xa = ti.max(ti.min(ax, bx), ti.f64(i))
                xb = ti.min(ti.max(ax, bx), ti.f64(i + 1))
                if xb > xa:
                    ya = ay + (xa - ax) / (bx - ax) * (by - ay)
                    yb = ay + (xb - ax) / (bx - ax) * (by - ay)
                    sign = 1.0 if bx < ax else -1.0
                    scan_segment_column(xa, ya, xb, yb, sign, i - x0, volume, cover)


@ti.func
def scan_segment_column(
    xa: ti.f64, ya: ti.f64, xb: ti.f64, yb: ti.f64, sign: ti.f64, ix: ti.i32, volume: ti.template(), cover: ti.template()
):
    k0, k1 = slab_range(ti.min(ya, yb), ti.max(ya, yb), 0, volume.shape[1])
    for k in range(k0, k1):
        # sub-segment with y in [k, k+1]; y is linear in x along the segment
        ta, tb = 0.0, 1.0
        if ya != yb:
            t_lo = (ti.f64(k) - ya) / (yb - ya)
            t_hi = (ti.f64(k + 1) - ya) / (yb - ya)
            ta = ti.max(0.0, ti.min(t_lo, t_hi))
            tb = ti.min(1.0, ti.max(t_lo, t_hi))
        if tb > ta:
            length = sign * (tb - ta) * (xb - xa)
            ymid = ya + 0.5 * (ta + tb) * (yb - ya)
            volume[ix, k] += length * (ymid - k)
            cover[ix, k] += length
