"""Partial cell layers along flat faces: the normal strains' mu weights moved to their solid's first moments.

A cut cell weighs its normal strains, read at its centre, by its solid fraction; where a face of the
solid runs parallel to a grid plane the centre lies up to h/2 outside the solid in every cell of the
layer, and the bending strain there is read too far from the neutral axis: a beam W wide stiffens by
about 6 s (1 - s) (h / W)^2 per partial layer of fill s (2.7% over sub-cell offsets of the stress
suite's cantilever at W/8, 7% on the bundled example). Here each term mu eps_aa^2 of a cut cell
gives V |m_k| of its weight to its neighbour on its solid centroid's side along each axis k != a
(m: the centroid's offset in cells), so that term's weights have the solid's first moments across
a. Along a itself nothing moves: the plain fractions' differences along a are already the rows'
linear share of the surface. Only cells whose fill equals their neighbours' along a move (FLAT):
on curved surfaces the displacement samples beyond the surface already relax the cut cells, and
moving their weights as well over-corrected (a 0.15% bias on the thick spheres that did not shrink
with h; docs/design-notes.md, "Partial layers along flat faces"). And only where the run of
material along a ends on loaded or held faces at both ends (``ends_acted``): the lambda term keeps
the fractions (its weights moved per pair of strains lose definiteness on slivers), so at a free
end the two parts of sigma_aa = 0 would reach the end row through different weights.

The result is a sparse symmetric correction of the fine level's energy on the DOFs it touches,
added to the surface operator's mass (``nitsche.with_bulk``), so the matrix-free apply, the
smoothers and the factor see it. Loads reach the moved lines' end rows as the energy does: those
given at points through ``end_loads``, divergence-form ones through ``load``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .layers import fills_at, run_ends
from .operator import Level

FLAT = 0.02  # a cut cell moves its weight for eps_aa when its neighbours along a hold its fill to this
KEEP = 0.25  # least share of its own weight a cut cell keeps
CUT = 1e-12  # fills within this of 0 or 1 are not cut
NORMAL = 1 - 1e-6  # |n_a| of the load points that end a-lines on a face normal to a


def moved_weights(level: Level, acted: list[np.ndarray] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per axis a: (positions [M], weight changes [M]) of the term mu eps_aa^2 (dimensionless, summing
    to zero) at the cells they touch. ``acted[a]``: layout positions of the cells holding surface
    normal to a that a load or a hold acts on (``face_cells``); a cell moves eps_aa's weight only when
    the run of material along a through it ends in such cells at both ends (see ``ends_acted``).

    Centroids come from the slab model: along k, a cut cell's solid lies flush with its fuller
    neighbour, its extent s_k = V / (that neighbour's fill), so m_k = +-(1 - s_k) / 2 (0 when both
    neighbours hold the same fill): exact for cuts parallel to grid planes, which FLAT keeps."""
    d, lay, vc = level.dim, level.layout, level.vc_host
    eye = np.eye(d, dtype=np.int64)
    pos = np.nonzero((vc > CUT) & (vc < 1.0 - CUT))[0]
    pos = pos[pos < lay.count * lay.tile_size]
    index = lay.index_of(pos).astype(np.int64)
    v = vc[pos]
    low = [fills_at(level, index - eye[k]) for k in range(d)]
    high = [fills_at(level, index + eye[k]) for k in range(d)]
    offset = np.zeros((len(pos), d))
    for k in range(d):
        fuller = np.maximum(low[k], high[k])
        extent = np.minimum(v / np.maximum(fuller, CUT), 1.0)
        side = np.sign(high[k] - low[k])
        offset[:, k] = np.where(fuller > CUT, side * (1.0 - extent) / 2.0, 0.0)
    out = []
    for a in range(d):
        flat = np.ones(len(pos), dtype=bool)
        for nb in (low[a], high[a]):
            flat &= (nb <= 0.0) | (np.abs(nb - v) <= FLAT)
        flat[flat] = ends_acted(level, index[flat], a, None if acted is None else acted[a])
        give = np.zeros((len(pos), d))
        for k in range(d):
            if k == a:
                continue
            receiver = np.where(offset[:, k] > 0, high[k], low[k])
            give[:, k] = np.where(flat & (receiver > 0.0), v * np.abs(offset[:, k]), 0.0)
        total = give.sum(axis=1)
        cap = (1.0 - KEEP) * v
        give *= np.where(total > cap, cap / np.maximum(total, 1e-300), 1.0)[:, None]
        moving = give.sum(axis=1) > 0
        keys, values = [pos[moving]], [-give[moving].sum(axis=1)]
        for k in range(d):
            to = give[:, k] > 0
            step = np.where(offset[to, k] > 0, 1, -1)[:, None] * eye[k]
            keys.append(lay.positions(index[to] + step))
            values.append(give[to, k])
        keys_a, values_a = np.concatenate(keys), np.concatenate(values)
        unique, inverse = np.unique(keys_a, return_inverse=True)
        out.append((unique, np.bincount(inverse, weights=values_a, minlength=len(unique))))
    return out


def ends_acted(level: Level, index: np.ndarray, axis: int, acted: np.ndarray | None) -> np.ndarray:
    """bool [N]: the run of material along ``axis`` through each cell of ``index`` [N, d] ends at both
    ends in a cell of ``acted`` (layout positions). Where a run ends on a free face, sigma_aa = 0 there
    but its mu part 2 mu eps_aa = -lambda tr(eps) is not (a pulled bar's free sides): the moved mu
    weights and the plain lambda weights would leave that row the force 2 mu eps_aa dw. Where it ends
    on a curved or tilted face (a bolt hole's wall), the end cell is not flat and keeps its weight, so
    the change sits one row inside, where nothing reaches it: the L-bracket held on its bolt holes came
    out 6% further from its reference at 0.5 mm when such runs moved."""
    if acted is None or not len(index):
        return np.zeros(len(index), dtype=bool)
    _, _, (low, high) = run_ends(level, index, axis)
    lay = level.layout
    return np.isin(lay.positions(low), acted) & np.isin(lay.positions(high), acted)


def _strain_rows(level: Level, a: int, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """DOF keys a * size + position [M] of eps_aa's two samples at cells ``pos``: (low face, high face)."""
    lay = level.layout
    high = lay.positions(lay.index_of(pos).astype(np.int64) + np.eye(level.dim, dtype=np.int64)[a])
    if (high < 0).any():
        raise AssertionError("a weighted cell's high face lies outside the kept tiles")
    return a * level.size + pos, a * level.size + high


def correction(level: Level, weights: list[tuple[np.ndarray, np.ndarray]]
               ) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray] | None:
    """(DOF keys [n], the energy's correction [n, n] [N/m in 3D], its load [n] (zero)) for
    ``nitsche.combined`` from ``moved_weights``; None when no weight moves."""
    if not any(len(p) for p, _ in weights):
        return None
    h, d = level.spacing, level.dim
    rows, cols, vals = [], [], []
    for a, (pos, dw) in enumerate(weights):
        lo, hi = _strain_rows(level, a, pos)
        c = 2.0 * level.mu * dw * h ** (d - 2)  # 2 mu dw h^d / h^2
        rows += [lo, hi, lo, hi]
        cols += [lo, hi, hi, lo]
        vals += [c, c, -c, -c]
    r, cc, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keys, inverse = np.unique(np.concatenate([r, cc]), return_inverse=True)
    n = len(keys)
    matrix = sp.csr_matrix((v, (inverse[:len(r)], inverse[len(r):])), shape=(n, n))
    matrix.sum_duplicates()
    return keys, matrix, np.zeros(n)


def load(level: Level, weights: list[tuple[np.ndarray, np.ndarray]], stress_at, share) -> np.ndarray:
    """The divergence form's share of the correction [d, size] [N]: the correction's residual of the
    stress field (``stress_at(x [M, d]) -> [M, d, d]`` [Pa] at cell centres), each row scaled by
    ``share(a, positions) -> [M]`` (its share of the load's patch), so that a constant stress
    stays an exact solution."""
    d, h, lay = level.dim, level.spacing, level.layout
    lam, mu = level.lam, level.mu
    f = np.zeros((d, level.size))
    origin = np.asarray(level.origin, dtype=float)
    for a, (pos, dw) in enumerate(weights):
        if not len(pos):
            continue
        sigma = np.asarray(stress_at(origin + h * (lay.index_of(pos) + 0.5)), dtype=float)
        trace = np.trace(sigma, axis1=1, axis2=2)
        two_mu_eps = sigma[:, a, a] - lam / (d * lam + 2.0 * mu) * trace  # 2 mu eps_aa of C^-1 sigma
        force = dw * two_mu_eps * h ** (d - 1)  # its work on eps_aa = (u_hi - u_lo) / h
        lo, hi = _strain_rows(level, a, pos)
        for keys, sign in ((lo, -1.0), (hi, 1.0)):
            p = keys - a * level.size
            f[a] += np.bincount(p, weights=sign * force * share(a, p), minlength=level.size)
    return f


def face_cells(level: Level, points: np.ndarray, normals: np.ndarray, axis: int) -> np.ndarray:
    """Layout positions (unique) of the cells holding those of the surface points [Q, d] whose outward
    normal [Q, d] lies along ``axis`` (a face normal to it)."""
    along = np.abs(normals[:, axis]) > NORMAL
    cells = cells_of(level, points[along], normals[along])
    return np.unique(cells[cells >= 0])


def cells_of(level: Level, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Layout positions [Q] of the cells holding surface points [Q, d] [m] with outward normals
    [Q, d]: a point on a grid plane belongs to the cell on its solid side."""
    h = level.spacing
    inward = points - (1e-9 * h) * normals
    return level.layout.positions(np.floor((inward - np.asarray(level.origin)) / h).astype(np.int64))


def end_loads(level: Level, weights: list[tuple[np.ndarray, np.ndarray]],
              loads: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray:
    """What the surface loads given at points (``loads``: (points [Q, d] m, weights [Q] m^2,
    tractions [Q, d] Pa, normals [Q, d]) each) add [d, size] [N] where weights moved: the
    correction's residual of the stress, as :func:`load` gives it for a stress field, which the
    loads' spread (sampling.py) does not give. Each moved cell's dw h^(d-1) 2 mu eps_aa goes to its
    high face and minus that to its low face: along a line of equal dw only its ends keep any, and
    where dw changes (corner cells within FLAT of their line's fill) the row between keeps the
    difference. Every cell's pair is in balance, force and torque. 2 mu eps_aa = sigma_aa - c
    tr(sigma), c = lambda / (d lambda + 2 mu): sigma_aa from the normal tractions of the faces that
    end the cell's run along a (the mean of their points in the run's end cells; linear between the
    two ends, or the one end that has any), sigma_kk, k != a, from a face normal to k at an end of
    the run along k through the cell (:func:`_lateral`); a lateral stress no such face gives is taken
    as zero, a free face's (the uniaxial state of a bar's end). Toward an end without such a face
    (a hold) the row past the last moved cell takes nothing: the hold's reaction is its force."""
    d, h, lay = level.dim, level.spacing, level.layout
    c = level.lam / (d * level.lam + 2 * level.mu)
    f = np.zeros((d, level.size))
    if not loads:
        return f
    x, w, t, n = (np.concatenate(v) for v in zip(*loads))
    cell = cells_of(level, x, n)
    eye = np.eye(d, dtype=np.int64)
    # per cell and axis k: the area of the points on faces normal to k and their sum of w sigma_kk
    # (t_k n_k); only such faces end a-lines as the partition assumes (a tilted face's cells would
    # take a share of its load that the energy does not give them, and unbalance a free body)
    area, normal_stress = np.zeros((d, level.size)), np.zeros((d, level.size))
    for k in range(d):
        ok = (cell >= 0) & (np.abs(n[:, k]) > NORMAL)
        area[k] = np.bincount(cell[ok], weights=w[ok], minlength=level.size)
        normal_stress[k] = np.bincount(cell[ok], weights=w[ok] * t[ok, k] * np.sign(n[ok, k]),
                                       minlength=level.size)
    for a, (pos, dw) in enumerate(weights):
        pos, dw = pos[dw != 0], dw[dw != 0]
        if not len(pos):
            continue
        index = lay.index_of(pos).astype(np.int64)
        moved = np.zeros(level.size, dtype=bool)
        moved[pos] = True
        # the runs' ends and the lateral stresses are looked up at the ends of each group of moved
        # cells in a row along a and taken linear between (walking every moved cell's runs took 4.3 s
        # on a box at 128^3); a constant stress is the same everywhere, so this stays exact
        first, last, group = _groups(index, a)
        _, _, ends = run_ends(level, index[first], a)
        stress, loaded = [], []
        for end in ends:  # sigma_aa at the run's low and high end faces, where they are loaded
            at = lay.positions(end)
            here = (at >= 0) & (area[a, np.maximum(at, 0)] > 0)
            at = np.maximum(at, 0)
            stress.append(np.where(here, normal_stress[a, at] / np.where(here, area[a, at], 1.0), 0.0)[group])
            loaded.append(here[group])
        low, high = ends[0][group, a], ends[1][group, a]
        along = (index[:, a] + 0.5 - low) / (high + 1 - low)  # the cell centre's place between the end faces
        sigma = np.where(loaded[0] & loaded[1], (1 - along) * stress[0] + along * stress[1],
                         np.where(loaded[0], stress[0], stress[1]))
        lateral = [_lateral(level, index[i], a, area, normal_stress)[group] for i in (first, last)]
        span = index[last, a][group] - index[first, a][group]
        inside = (index[:, a] - index[first, a][group]) / np.maximum(span, 1)
        two_mu_eps = sigma - c * (sigma + (1 - inside) * lateral[0] + inside * lateral[1])
        force = np.where(loaded[0] | loaded[1], h ** (d - 1) * two_mu_eps * dw, 0.0)
        for sign, face, side in ((1, eye[a], 1), (-1, 0 * eye[a], 0)):
            rows = lay.positions(index + face)
            beyond = lay.positions(index + sign * eye[a])
            past = (beyond < 0) | ~moved[np.maximum(beyond, 0)]
            good = (rows >= 0) & ~(past & ~loaded[side])
            np.add.at(f[a], rows[good], sign * force[good])
    return f


def _groups(index: np.ndarray, a: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cells [N, d] grouped into rows of consecutive cells along axis a: each group's first and last
    cell (numbers into ``index`` [G] each) and each cell's group [N]."""
    other = [k for k in range(index.shape[1]) if k != a]
    order = np.lexsort([index[:, a]] + [index[:, k] for k in reversed(other)])
    ranked = index[order]
    new = np.ones(len(order), dtype=bool)
    new[1:] = (np.diff(ranked[:, a]) != 1) | np.any(np.diff(ranked[:, other], axis=0) != 0, axis=1)
    number = np.cumsum(new) - 1
    group = np.empty(len(order), dtype=np.int64)
    group[order] = number
    starts = np.nonzero(new)[0]
    ends = np.append(starts[1:], len(order)) - 1
    return order[starts], order[ends], group


def _lateral(level: Level, index: np.ndarray, a: int, area: np.ndarray, normal_stress: np.ndarray) -> np.ndarray:
    """sum over k != a of sigma_kk [Pa] at cells ``index`` [N, d]: along k, the normal traction of
    the nearer end of the run of material through each cell that holds points of a face normal to k
    (``area`` [d, size] of such points per cell, ``normal_stress`` [d, size] their sum of w sigma_kk),
    else of the farther; zero where neither end has any (a free or held face)."""
    lay = level.layout
    out = np.zeros(len(index))
    for k in (k for k in range(level.dim) if k != a):
        _, _, (low, high) = run_ends(level, index, k)
        low_first = (index[:, k] - low[:, k] <= high[:, k] - index[:, k])[:, None]
        found = np.zeros(len(index), dtype=bool)
        for end in (np.where(low_first, low, high), np.where(low_first, high, low)):
            p = lay.positions(end)
            here = ~found & (p >= 0)
            here[here] = area[k, p[here]] > 0
            out[here] += normal_stress[k, p[here]] / area[k, p[here]]
            found |= here
    return out
