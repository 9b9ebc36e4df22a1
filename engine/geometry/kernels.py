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


import gstaichi as ti

from .. import runtime  # noqa: F401 - first: its Taichi patches make the decorators below quick

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


@ti.kernel(fastcache=True)
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


@ti.kernel(fastcache=True)
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


# --- Open surfaces (winding_fill.py): winding number of cone caps, ray counts, certification ---
# Facet arrays are [N, d, d] in sub-cell units: rows are the corners of triangles (3D) / segments (2D).

# Returned instead of a bound where nothing can be certified (a cap facet meets the block).
NOT_CERTIFIED = 1e30


@ti.func
def corner(f: ti.template(), t: ti.i32, v: ti.i32, dim: ti.template()):
    return ti.Vector([f[t, v, c] for c in ti.static(range(dim))])


@ti.func
def facet_side(f: ti.template(), t: ti.i32, p: ti.template(), dim: ti.template()):
    """(corners - p) of facet t and det[a b c] (3D) / a x b (2D): the side of the facet's plane
    (line) p lies on. ``facet_winding`` and ``facet_above`` both take the side from here, so
    they agree about it even for points within round-off of the facet."""
    a, b = corner(f, t, 0, dim) - p, corner(f, t, 1, dim) - p
    c = a
    det = 0.0
    if ti.static(dim == 3):
        c = corner(f, t, 2, dim) - p
        det = a.dot(b.cross(c))
    else:
        det = a[0] * b[1] - a[1] * b[0]
    return a, b, c, det


@ti.func
def facet_winding(f: ti.template(), t: ti.i32, p: ti.template(), dim: ti.template()) -> ti.f64:
    """Winding-number share of facet t at p: signed solid angle / 4 pi (Van Oosterom & Strackee),
    2D signed angle / 2 pi. For p on the facet: 0 (the mean of the two sides), as ``facet_above``
    counts it half; on a facet parallel to the last axis, which ``facet_above`` never counts,
    the limit from the side of p + (eps, eps^2), where ``edge_function`` puts p."""
    a, b, c, det = facet_side(f, t, p, dim)
    den = a.dot(b)
    if ti.static(dim == 3):
        la, lb, lc = a.norm(), b.norm(), c.norm()
        den = la * lb * lc + den * lc + b.dot(c) * la + c.dot(a) * lb
    w = 0.0
    if det != 0.0 or den >= 0.0:
        w = ti.atan2(det, den) / (2.0 * ti.math.pi)
    else:
        # d det / dp = -normal (3D), (a_y - b_y, ..) (2D): the side p + (eps, eps^2) lies on
        side = 0.0
        if ti.static(dim == 3):
            n = (b - a).cross(c - a)
            if n[2] == 0.0:
                side = -ti.math.sign(n[0]) if n[0] != 0.0 else -ti.math.sign(n[1])
        else:
            if a[0] == b[0]:
                side = ti.math.sign(a[1] - b[1])
        w = 0.5 * side
    return w


@ti.func
def facet_meets_box(
    f: ti.template(), t: ti.i32, centre: ti.template(), half: ti.f64, dim: ti.template()
) -> ti.i32:
    """1 unless facet t surely misses the cube |x - centre|_inf <= half (bounding boxes, then the
    facet's plane / line against the cube; exact for segments, a superset for triangles)."""
    h = half * (1.0 + 1e-9) + 1e-9
    meets = 1
    for c in ti.static(range(dim)):
        lo, hi = f[t, 0, c], f[t, 0, c]
        for v in ti.static(range(1, dim)):
            lo, hi = ti.min(lo, f[t, v, c]), ti.max(hi, f[t, v, c])
        if lo > centre[c] + h or hi < centre[c] - h:
            meets = 0
    if meets == 1:
        a = corner(f, t, 0, dim)
        e = corner(f, t, 1, dim) - a
        if ti.static(dim == 3):
            n = e.cross(corner(f, t, 2, dim) - a)
            if ti.abs(n.dot(centre - a)) > h * (ti.abs(n[0]) + ti.abs(n[1]) + ti.abs(n[2])):
                meets = 0
        else:
            if ti.abs(e[0] * (centre[1] - a[1]) - e[1] * (centre[0] - a[0])) > h * (ti.abs(e[0]) + ti.abs(e[1])):
                meets = 0
    return meets


@ti.func
def rim_field(edges: ti.template(), weight: ti.template(), p: ti.template(), rho: ti.f64, dim: ti.template()):
    """grad w(p) for the winding number w of a surface with boundary chain ``edges`` [E, 2, d]
    (3D: oriented edges a -> b, multiplicity ``weight`` [E] > 0; 2D: each boundary point twice,
    weight = segments ending there minus segments starting there), and a bound of |w(x) - w(p)|
    over the ball |x - p| <= rho, and one of |w(x) - w(p) - grad w(p) . (x - p)| (NOT_CERTIFIED
    if a boundary edge reaches into the ball).

    Biot-Savart: grad w(p) = (1/4 pi) sum_edges int (x - p) x dl / |x - p|^3, the segment
    integral in closed form; |grad w| <= (1/4 pi) sum int dl / r^2 and |grad grad w| <=
    (1/4 pi) sum int 2 dl / r^3, at most min(L / delta, pi) / delta and 2 min(L / delta, 2) / delta^2
    over a segment of length L at distance delta. 2D: w = sum weight phi_v / 2 pi, |grad phi_v| =
    1 / r, |grad grad phi_v| = 1 / r^2. The bound is the smaller of rho sup|grad w| and
    rho |grad w(p)| + rho^2 sup|grad grad w| / 2; the latter term bounds the linearisation."""
    g = ti.Vector.zero(ti.f64, dim)
    g_sup, h_sup = 0.0, 0.0
    inside = 0
    for e in range(edges.shape[0]):
        a = ti.Vector([edges[e, 0, c] for c in ti.static(range(dim))]) - p
        b = ti.Vector([edges[e, 1, c] for c in ti.static(range(dim))]) - p
        ab = b - a
        length2 = ab.dot(ab)
        s = 0.0
        if length2 > 0.0:
            s = ti.min(ti.max(-a.dot(ab) / length2, 0.0), 1.0)
        delta = (a + s * ab).norm() - rho
        m = ti.abs(weight[e])
        if delta <= 0.0:
            inside = 1
        elif ti.static(dim == 3):
            la, lb = a.norm(), b.norm()
            g += weight[e] * a.cross(b) * (la + lb) / (la * lb * (la * lb + a.dot(b))) / (4.0 * ti.math.pi)
            length = ti.sqrt(length2)
            g_sup += m * ti.min(length / delta, ti.math.pi) / (4.0 * ti.math.pi * delta)
            h_sup += m * ti.min(length / delta, 2.0) / (2.0 * ti.math.pi * delta * delta)
        else:
            g += weight[e] * ti.Vector([a[1], -a[0]]) / (2.0 * ti.math.pi * a.dot(a))
            g_sup += m / (2.0 * ti.math.pi * delta)
            h_sup += m / (2.0 * ti.math.pi * delta * delta)
    spread, curvature = NOT_CERTIFIED, NOT_CERTIFIED
    if inside == 0:
        curvature = 0.5 * rho * rho * h_sup
        spread = ti.min(rho * g_sup, rho * g.norm() + curvature)
    return g, spread, curvature


@ti.func
def cap_winding(cap: ti.template(), p: ti.template(), dim: ti.template()) -> ti.f64:
    w = 0.0
    for t in range(cap.shape[0]):
        w += facet_winding(cap, t, p, dim)
    return w


@ti.kernel(fastcache=True)
def bound_cap_winding(
    cap: ti.types.ndarray(dtype=ti.f64, ndim=3),
    edges: ti.types.ndarray(dtype=ti.f64, ndim=3),
    weight: ti.types.ndarray(dtype=ti.f64, ndim=1),
    centres: ti.types.ndarray(dtype=ti.f64, ndim=2),
    half: ti.f64,
    w: ti.types.ndarray(dtype=ti.f64, ndim=1),
    spread: ti.types.ndarray(dtype=ti.f64, ndim=1),
    dim: ti.template(),
):
    """Cap winding number w[i] at centres[i] [P, d] and a bound spread[i] of its variation over the
    cube of half-size ``half`` there (``rim_field`` of the rim ``edges``), NOT_CERTIFIED where a
    facet of ``cap`` [C, d, d] meets the cube (w jumps there). Where the spread alone reaches 1/2,
    nothing can be certified and w is left 0."""
    rho = half * ti.sqrt(ti.cast(dim, ti.f64))
    for i in range(centres.shape[0]):
        p = ti.Vector([centres[i, c] for c in ti.static(range(dim))])
        crossed = 0
        for t in range(cap.shape[0]):
            crossed = crossed | facet_meets_box(cap, t, p, half, dim)
        w[i], spread[i] = 0.0, NOT_CERTIFIED
        if crossed == 0:
            _, bound, _ = rim_field(edges, weight, p, rho, dim)
            spread[i] = bound
            if bound < 0.5:
                w[i] = cap_winding(cap, p, dim)


@ti.func
def edge_function(ax: ti.f64, ay: ti.f64, bx: ti.f64, by: ti.f64, px: ti.f64, py: ti.f64):
    """orient2d(a, b, p) and its sign under the symbolic perturbation p + (eps, eps^2).

    The endpoints are put in lexicographic order first, so two facets sharing an edge get
    bit-identical values; the perturbed sign is never 0 for a proper edge, so a point on an edge
    or a vertex lies in exactly one of the facets around it."""
    flip = 1.0
    x0, y0, x1, y1 = ax, ay, bx, by
    if bx < ax or (bx == ax and by < ay):
        x0, y0, x1, y1 = bx, by, ax, ay
        flip = -1.0
    e = (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)
    s = 0.0
    if e > 0.0:
        s = 1.0
    elif e < 0.0:
        s = -1.0
    elif y1 != y0:
        s = -1.0 if y1 > y0 else 1.0
    elif x1 != x0:
        s = 1.0
    return flip * e, flip * s


@ti.func
def facet_above(f: ti.template(), t: ti.i32, p: ti.template(), dim: ti.template()) -> ti.f64:
    """+1 / -1 if facet t lies above p along the last axis and faces up / down, half that if p
    is on the facet (the mean of the two sides, as in ``facet_winding``), else 0: the signed
    facet count of the scan conversion, at one point."""
    s = 0.0  # orientation of the facet's projection if it contains p's, else 0
    if ti.static(dim == 3):
        _, s0 = edge_function(f[t, 1, 0], f[t, 1, 1], f[t, 2, 0], f[t, 2, 1], p[0], p[1])
        _, s1 = edge_function(f[t, 2, 0], f[t, 2, 1], f[t, 0, 0], f[t, 0, 1], p[0], p[1])
        _, s2 = edge_function(f[t, 0, 0], f[t, 0, 1], f[t, 1, 0], f[t, 1, 1], p[0], p[1])
        if s0 == s1 and s1 == s2:
            s = s0
    else:
        # half-open in x: a shared end point belongs to exactly one of its segments
        if ti.min(f[t, 0, 0], f[t, 1, 0]) <= p[0] and p[0] < ti.max(f[t, 0, 0], f[t, 1, 0]):
            s = 1.0 if f[t, 1, 0] < f[t, 0, 0] else -1.0
    r = 0.0
    if s != 0.0:
        _, _, _, det = facet_side(f, t, p, dim)
        # d det / dp = -normal and s = sign of the normal's last component: det s > 0 below the facet
        if det * s > 0.0:
            r = s
        elif det == 0.0:
            r = 0.5 * s
    return r


@ti.func
def ray_count(
    closed: ti.template(), start: ti.template(), ids: ti.template(), col: ti.i32, p: ti.template(), dim: ti.template()
) -> ti.f64:
    """Indicator of the closed surface ``closed`` at p (an integer off its facets): the signed count
    of its facets above p, searched among ids[start[col]:start[col + 1]] (the facets over p's column)."""
    count = 0.0
    for m in range(start[col], start[col + 1]):
        count += facet_above(closed, ids[m], p, dim)
    return count


@ti.kernel(fastcache=True)
def sample_open_winding(
    closed: ti.types.ndarray(dtype=ti.f64, ndim=3),
    start: ti.types.ndarray(dtype=ti.i32, ndim=1),
    ids: ti.types.ndarray(dtype=ti.i32, ndim=1),
    cap: ti.types.ndarray(dtype=ti.f64, ndim=3),
    points: ti.types.ndarray(dtype=ti.f64, ndim=2),
    column: ti.types.ndarray(dtype=ti.i32, ndim=1),
    out: ti.types.ndarray(dtype=ti.f64, ndim=1),
    dim: ti.template(),
):
    """Winding number of an open surface S at points [P, d]: w_S = chi - w_cap, chi the integer
    indicator of S closed by its cap (``closed`` [N, d, d], by columns ``column`` [P]) and w_cap
    the cap's winding number (``cap`` [C, d, d])."""
    for i in range(points.shape[0]):
        p = ti.Vector([points[i, c] for c in ti.static(range(dim))])
        out[i] = ray_count(closed, start, ids, column[i], p, dim) - cap_winding(cap, p, dim)


@ti.kernel(fastcache=True)
def probe_open_winding(
    closed: ti.types.ndarray(dtype=ti.f64, ndim=3),
    surface_facets: ti.i32,
    start: ti.types.ndarray(dtype=ti.i32, ndim=1),
    ids: ti.types.ndarray(dtype=ti.i32, ndim=1),
    cap: ti.types.ndarray(dtype=ti.f64, ndim=3),
    edges: ti.types.ndarray(dtype=ti.f64, ndim=3),
    weight: ti.types.ndarray(dtype=ti.f64, ndim=1),
    centres: ti.types.ndarray(dtype=ti.f64, ndim=2),
    column: ti.types.ndarray(dtype=ti.i32, ndim=1),
    w: ti.types.ndarray(dtype=ti.f64, ndim=1),
    grad: ti.types.ndarray(dtype=ti.f64, ndim=2),
    spread: ti.types.ndarray(dtype=ti.f64, ndim=1),
    curvature: ti.types.ndarray(dtype=ti.f64, ndim=1),
    dim: ti.template(),
):
    """Winding number w[i] and its gradient grad[i] [P, d] of the open surface at the centres
    [P, d] of unit cubes, and bounds of its variation and of its linearisation error over the
    cube (``rim_field``). Where one of the surface's own facets (the first ``surface_facets`` of
    ``closed``) meets the cube w jumps: both bounds are NOT_CERTIFIED, w and grad are left 0."""
    rho = 0.5 * ti.sqrt(ti.cast(dim, ti.f64))
    for i in range(centres.shape[0]):
        p = ti.Vector([centres[i, c] for c in ti.static(range(dim))])
        col = column[i]
        crossed = 0
        for m in range(start[col], start[col + 1]):
            if ids[m] < surface_facets:
                crossed = crossed | facet_meets_box(closed, ids[m], p, 0.5, dim)
        w[i], spread[i], curvature[i] = 0.0, NOT_CERTIFIED, NOT_CERTIFIED
        for c in ti.static(range(dim)):
            grad[i, c] = 0.0
        if crossed == 0:
            w[i] = ray_count(closed, start, ids, col, p, dim) - cap_winding(cap, p, dim)
            g, bound, curved = rim_field(edges, weight, p, rho, dim)
            for c in ti.static(range(dim)):
                grad[i, c] = g[c]
            spread[i], curvature[i] = bound, curved
