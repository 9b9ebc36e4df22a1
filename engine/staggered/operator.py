"""One grid level of the staggered elasticity operator: its tiles, fractions, masks and apply.

``Level`` owns the Taichi arrays of one level and sequences the kernels of ``kernels.py``:
A = K + shift M restricted to the free DOFs (``mask``), where K is the Hessian of the discrete
energy (strain energy weighted by control-volume fractions; README, "The staggered method") and
M the lumped mass from face fractions (only when a shift is set: static runs never build a mass). The finest level comes from exact volume fractions
(:func:`make_fine_level`), coarser ones from averaging cell fractions (:func:`make_coarse_level`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

from ..geometry.fractions import VolumeFractions
from ..grid import axis_pairs
from ..runtime import device_array, device_zeros, kernel_input, solve_float
from . import kernels
from .ghosts import float32_fraction, ghost_faces, ghost_inertia
from .layout import TILE, TileLayout, cell_bodies, dilate, make_layout, reorder


MIN_FRACTION = 1e-3
# The scan conversion sums prisms, so interior control volumes come out up to ~1e-14 below 1
# (8% of the shell's cells at 128^3). Read as cut, they would keep their tiles off the full-tile
# path and put them in the multigrid's boundary band; within this of 1 a fraction is 1.
ROUNDOFF = 1e-12


@dataclass(frozen=True)
class Part:
    """Positions an apply works on: ``update`` [m] int32 (sorted flat positions) get y = A x (or a
    smoothing step), ``stress`` [k] int32 (``update`` and their neighbours across a face) get the
    weighted stresses that it reads."""

    update: object
    stress: object
    m: int
    k: int


class Level:
    """The operator on one level. Fractions: vc [size] cells, ve [pairs, size] edges, vf [d, size]
    faces (control-volume fractions in [0, 1], f64 host arrays); spacing h [m]; lam, mu [Pa].
    ``dtype``: the float type of its device arrays (default the solve precision); ``active``
    [d, size] bool when already known (else computed from vc). ``ve`` is pruned in place.
    ``vf_host`` becomes None where no mass will be needed (a static method's levels)."""

    def __init__(self, layout: TileLayout, spacing: float, vc: np.ndarray, ve: np.ndarray, vf: np.ndarray,
                 lam: float, mu: float, dtype: type | None = None, active: np.ndarray | None = None) -> None:
        d = layout.dim
        self.layout, self.spacing, self.dim = layout, float(spacing), d
        self.lam, self.mu = float(lam), float(mu)
        self.dtype = np.dtype(dtype or solve_float()).type
        size, ts = layout.size, layout.tile_size
        vc = np.ascontiguousarray(vc, dtype=np.float64)
        ve = np.ascontiguousarray(ve, dtype=np.float64)
        coords = np.ascontiguousarray(layout.coords, dtype=np.int32)
        tmap = np.ascontiguousarray(layout.tile_map, dtype=np.int32)
        # setup kernels take the host arrays themselves (no device copies and transfers)
        if active is None:
            found = np.zeros((d, size), dtype=np.int32)
            kernels.active_faces(d, coords, tmap, vc, found)
            active = found.astype(bool)
        kernels.prune_edges(d, coords, tmap, active.astype(np.int32), ve)
        self.vc_host, self.ve_host, self.vf_host = vc, ve, np.asarray(vf, dtype=np.float64)
        self.active = np.asarray(active, dtype=bool)
        self.coords, self.tmap = device_array(coords), device_array(tmap)
        self.nbr = device_array(layout.neighbours())
        self._unlisted = device_array(np.zeros(1, dtype=np.int32))  # the position list of a whole-level pass
        # the kernels' fractions: on the CPU backend in f64 these are the host arrays themselves
        self.vc, self.ve = kernel_input(vc, self.dtype), kernel_input(ve, self.dtype)
        full = np.ones(layout.count, dtype=bool)
        for v in (vc[None], ve):
            full &= np.all(v.reshape(len(v), -1, ts)[:, : layout.count] == 1.0, axis=(0, 2))
        self.full_tiles = int(full.sum())
        self.full = device_array(full.astype(np.int32))
        self.sc = device_zeros((d, size), self.dtype)
        self.se = device_zeros((len(axis_pairs(d)), size), self.dtype)
        self.shift, self.density = 0.0, 0.0
        self.slivers = 0  # control volumes whose weight was raised to MIN_FRACTION
        self.origin: tuple[float, ...] | None = None  # [m] position of index 0's cell corner, when known
        self.mass = None  # [d, size] rho h^d Vf, built only when a shift (dynamics) is set
        self.ghost_inertia = None  # [d, size] the mass fractions of ghost samples (ghosts.ghost_inertia)
        self.ghosts_apart = None  # [k, d] positions (grid index units) of ghosts left out between bodies
        self.surface = None  # the Nitsche terms of displacement boundaries (nitsche.SurfaceOperator)
        self.hold = None  # their patches (nitsche.HoldPatches), for the coarser levels
        self.set_free(self.active)

    @property
    def size(self) -> int:
        return self.layout.size

    def zeros(self):
        """A zero [d, size] array in the level's float type."""
        return device_zeros((self.dim, self.size), self.dtype)

    def set_free(self, free: np.ndarray) -> None:
        """free [d, size] bool: the unknowns (active and not prescribed)."""
        self.free = np.asarray(free, dtype=bool) & self.active
        self.mask = device_array(self.free, np.int8)  # 0 / 1: 1 byte, not 8, per DOF
        self._dinv = None

    def set_shift(self, shift: float, density: float) -> None:
        """A = K + shift M with M = rho h^d (Vf + ghost inertia) (backward Euler: shift = 1 / dt^2)."""
        self.shift, self.density = float(shift), float(density)
        if self.mass is None and shift != 0.0:
            if self.vf_host is None:
                raise RuntimeError("this level was built for static analyses (its face fractions are gone): no mass")
            inertia = self.vf_host if self.ghost_inertia is None else self.vf_host + self.ghost_inertia
            self.mass = device_array(density * self.spacing**self.dim * inertia, self.dtype)
        self._dinv = None

    def set_surface(self, surface, hold) -> None:
        """Add the surface terms ``surface`` (a ``nitsche.SurfaceOperator`` of this level, from the
        patches ``hold``) to A: S x = mass xs - [flux, stress^T] [stress xs; flux^T xs] on its
        DOFs xs, two CSR passes over z = [xs; stress xs; flux^T xs]."""
        self.surface, self.hold = surface, hold
        self._dinv = None
        if surface is None:
            return
        n = len(surface.comp)
        lower = sp.vstack([surface.stress, surface.flux.T]).tocsr()
        upper = sp.hstack([surface.mass, -surface.flux, -surface.stress.T]).tocsr()
        self._ids = (device_array(surface.comp.astype(np.int32)), device_array(surface.pos.astype(np.int32)))
        # an operator of bulk terms alone (``flat_layers`` on a free body) has no stress rows: its empty
        # CSR arrays get one unread slot (a device array cannot be empty)
        self._csr = [(device_array(m.indptr.astype(np.int32)), device_array(_slot(m.indices.astype(np.int32))),
                      device_array(_slot(m.data), np.float64)) for m in (lower, upper)]
        self._z = device_zeros((n + lower.shape[0],), np.float64)
        self._sx = device_zeros((n,), np.float64)
        self._surface_count = n
        self._slots = {None: (None, device_array(np.arange(max(n, 1), dtype=np.int32)), n)}

    def _surface_apply(self, x) -> None:
        """_sx = S x at the surface DOFs (their compact order)."""
        comp, pos = self._ids
        (lp, lc, lv), (up, uc, uv) = self._csr
        kernels.gather(x, comp, pos, self._z)
        kernels.csr_apply(lp, lc, lv, self._z, self._z, self._surface_count)
        kernels.csr_apply(up, uc, uv, self._z, self._sx, 0)

    def _surface_slots(self, part: Part | None) -> tuple:
        """(device int32 list, count) of the surface DOFs at ``part``'s positions (all when None),
        found once per part."""
        key = None if part is None else id(part)
        if key not in self._slots:  # the part is kept beside its slots, so its id stays its own
            on = np.nonzero(np.isin(self.surface.pos, part.update.to_numpy()))[0].astype(np.int32)
            self._slots[key] = (part, device_array(on if len(on) else np.zeros(1, np.int32)), len(on))
        return self._slots[key][1:]

    def _mass_or_mask(self):
        return self.mass if self.mass is not None else self.mask

    @property
    def dinv(self):
        """[d, size] the inverse diagonal of A on the free DOFs, zero elsewhere (built on first use
        after the unknowns or the shift change: setup changes them more than once)."""
        if self._dinv is None:
            self._dinv = self.zeros()
            d = self.dim
            kernels.inverse_diagonal(d, self.coords, self.tmap, self.mask, self.vc, self.ve, self.lam, self.mu,
                                     self.spacing ** (d - 2), self._mass_or_mask(), self.shift, self._dinv)
            if self.surface is not None:
                sf = self.surface
                dinv = self._dinv.to_numpy()
                old = dinv[sf.comp, sf.pos].astype(np.float64)
                on = old > 0
                diag = 1.0 / np.where(on, old, 1.0) + sf.diagonal
                dinv[sf.comp, sf.pos] = np.where(on & (diag > 0), 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
                self._dinv.from_numpy(dinv)
        return self._dinv

    def part(self, update: np.ndarray) -> Part:
        """The ``Part`` of the flat positions ``update`` [m] (in kept tiles): the stresses it reads
        are at those positions and their neighbours one index down and up along each axis."""
        lay, d = self.layout, self.dim
        update = np.unique(np.asarray(update, dtype=np.int64))
        zero = lay.count * lay.tile_size
        # marked on a flag per position (the zero tile's too) rather than sorted and deduplicated:
        # 2d + 1 lists of the band's positions (950 k on the 256^3 shell's finest level)
        reads = np.zeros(lay.size, dtype=bool)
        reads[update] = True
        for a in range(d):
            for step in (-1, 1):
                reads[lay.shifted(update, a, step)] = True
        stress = np.flatnonzero(reads[:zero])
        return Part(device_array(update.astype(np.int32)), device_array(stress.astype(np.int32)), len(update), len(stress))

    def _stresses(self, x, part: Part | None) -> None:
        d = self.dim
        listed = part is not None
        kernels.weighted_stresses(d, listed, part.stress if listed else self._unlisted,
                                  part.k if listed else self.layout.count * self.layout.tile_size,
                                  self.nbr, self.full, x, self.vc, self.ve, self.lam, self.mu, 1.0 / self.spacing,
                                  self.sc, self.se)

    def _divergence(self, mode: int, part: Part | None, x, b, dinv, step, c1: float, c2: float, y) -> None:
        d = self.dim
        listed = part is not None
        surface = self.surface is not None
        c1, c2 = float(c1), float(c2)  # numpy scalars would defeat the kernel launcher's argument cache
        if surface:
            self._surface_apply(x)  # before the divergence: CHEBYSHEV updates x in place
        kernels.stress_divergence(d, mode, listed, part.update if listed else self._unlisted,
                                  part.m if listed else self.layout.count * self.layout.tile_size,
                                  self.nbr, self.mask, self.sc, self.se, self.spacing ** (d - 1), x,
                                  self._mass_or_mask(), self.shift, b, dinv, step, c1, c2, y)
        if surface:
            slots, n = self._surface_slots(part)
            if n:
                comp, pos = self._ids
                kernels.surface_add(mode, slots, n, comp, pos, self._sx, self.mask, dinv, c2, step, x, y)

    def apply(self, x, y, part: Part | None = None) -> None:
        """y = A x on the free DOFs (x must vanish off them); only at ``part``'s positions when given."""
        self._stresses(x, part)
        self._divergence(kernels.APPLY, part, x, y, y, y, 0.0, 0.0, y)

    def residual(self, x, b, r) -> None:
        """r = b - A x (b must vanish off the free DOFs)."""
        self._stresses(x, None)
        self._divergence(kernels.RESIDUAL, None, x, b, r, r, 0.0, 0.0, r)

    def chebyshev_step(self, x, b, step, dinv, c1: float, c2: float, part: Part | None = None) -> None:
        """step = c1 step + c2 dinv (b - A x), x += step, at ``part``'s positions (all when None);
        dinv must vanish off the free DOFs. c1 = 0 does not read step."""
        self._stresses(x, part)
        self._divergence(kernels.CHEBYSHEV, part, x, b, dinv, step, c1, c2, step)


# A run touching more kept shear edges than this is taken as held by its neighbours (see
# unheld_groups): the thin-wall mechanisms touch none (inside a wall) or one (beside a corner).
WEAK_EDGES = 2


@dataclass(frozen=True)
class Mechanisms:
    """Zero-energy motions of a level (see :func:`unheld_groups`): DOF k is component ``comp[k]``
    at flat position ``pos[k]``, moves by ``sign[k]`` (+1 or -1) in the motion ``group[k]``
    (0 .. count - 1); ``fill``: the largest cell fraction between the moving samples (how much of
    a cell the thin feature fills)."""

    comp: np.ndarray
    pos: np.ndarray
    group: np.ndarray
    sign: np.ndarray
    count: int
    fill: float


def unheld_groups(level: Level) -> Mechanisms:
    """Zero-energy motions of a level's free DOFs that thin features leave (not rigid motions).

    With mu > 0 a motion of zero energy has no normal strain in any material cell, so u_a is
    constant along each *run*: the a-face samples along axis a linked through material cells (the
    cells beyond a run's ends hold none). K's null space is therefore spanned by run translations
    t_r that make every kept shear term vanish: (a, b) at I reads t(a, I) - t(a, I - e_b) +
    t(b, I) - t(b, I - e_a). A wall or rod thinner than a cell that lies inside one cell layer has
    one sample across its thickness; the shear terms that would tie its transverse runs (two faces
    each) to its in-plane samples reach empty layers and are pruned, so those runs touch no kept
    shear term (or, beside a corner, one term shared with a run of the other wall).

    Found here: runs of free samples touching at most WEAK_EDGES kept shear terms in all; a term
    with exactly two such runs ties them (t_2 = +-t_1), one with one holds it, one with more holds
    them all (conservative), and every other run is taken as held. Each connected, consistently
    signed set of tied runs that nothing holds is an exact null vector of K (every term it touches
    vanishes), and the sets are disjoint: ``count`` is a lower bound of the null space's dimension
    beyond rigid motions, exact for the thin walls and rods described above. Cost: elementwise over
    the level's positions, graph work only on the weak runs (none in a part without thin features)."""
    empty = np.zeros(0, dtype=np.int64)
    comp, pos, run, total = _weak_runs(level)
    if not total:
        return Mechanisms(empty, empty, empty, empty, 0, 0.0)
    entries = _run_terms(level, comp, pos, run)
    group, run_sign, number, valid = _unheld_sets(entries, total)
    dof = valid[group[run]]
    return Mechanisms(comp[dof], pos[dof], number[group[run[dof]]], run_sign[run[dof]], int(valid.sum()),
                      _fill(level, comp[dof], pos[dof]))


def _shear_of(d: int) -> dict[int, list[tuple[int, int]]]:
    """Per component a, the shear pairs reading it: (pair number q, the other axis b)."""
    return {a: [(q, b if p0 == a else p0) for q, (p0, b) in enumerate(axis_pairs(d)) if a in (p0, b)] for a in range(d)}


def _weak_runs(level: Level) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The runs of free samples (see :func:`unheld_groups`) touching at most WEAK_EDGES kept shear
    terms and linked to no other sample: (comp [k], pos [k], run number [k] of each sample, runs)."""
    d, lay = level.dim, level.layout
    n = lay.count * lay.tile_size
    vc, ve, free = level.vc_host, level.ve_host, level.free
    shear_of = _shear_of(d)
    comps, poss, runs = [], [], []
    total = 0
    for a in range(d):
        # kept shear terms holding u_a(I): (a, b) at I and at I + e_b (whole-array shifts: a
        # per-position neighbour lookup cost 0.3 s on the 128^3 sphere, where nothing is weak)
        kept = np.zeros(n, dtype=np.int8)
        for q, b in shear_of[a]:
            on = ve[q] > 0
            kept += on[:n]
            kept += _shift_up(lay, on, b)[:n]
        cpos = np.nonzero(free[a, :n] & (kept <= WEAK_EDGES))[0]
        if not len(cpos):
            continue
        count = kept[cpos].astype(np.int64)
        # runs: faces p and p + e_a share cell p; a run linked to any other sample is held
        up, down = lay.shifted(cpos, a, 1), lay.shifted(cpos, a, -1)
        link_up, link_down = vc[cpos] > 0, vc[down] > 0
        k_up = np.minimum(np.searchsorted(cpos, up), len(cpos) - 1)
        k_down = np.minimum(np.searchsorted(cpos, down), len(cpos) - 1)
        inner = link_up & (cpos[k_up] == up)
        held = (link_up & ~inner) | (link_down & (cpos[k_down] != down))
        rows = np.nonzero(inner)[0]
        graph = sp.coo_matrix((np.ones(len(rows)), (rows, k_up[rows])), shape=(len(cpos),) * 2)
        m, label = csgraph.connected_components(graph, directed=False)
        good = np.bincount(label, weights=held, minlength=m) == 0
        good &= np.bincount(label, weights=count, minlength=m) <= WEAK_EDGES
        keep = good[label]
        if not keep.any():
            continue
        number = np.cumsum(good) - 1 + total
        total += int(good.sum())
        comps.append(np.full(int(keep.sum()), a))
        poss.append(cpos[keep])
        runs.append(number[label[keep]])
    if not total:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, 0
    return np.concatenate(comps), np.concatenate(poss), np.concatenate(runs), total


def _run_terms(level: Level, comp: np.ndarray, pos: np.ndarray, run: np.ndarray) -> np.ndarray:
    """The kept shear terms touching the weak runs, each once, as the run numbers [terms, 4] of the
    samples they read (u_a(E), u_a(E - e_b), u_b(E), u_b(E - e_a)), -1 for every other sample."""
    d, lay, ve, size = level.dim, level.layout, level.ve_host, level.size
    terms = []
    for a, pairs_of_a in _shear_of(d).items():
        on = comp == a
        for q, b in pairs_of_a:
            for e in (pos[on], lay.shifted(pos[on], b, 1)):
                terms.append(q * size + e[ve[q, e] > 0])
    terms = np.unique(np.concatenate(terms))
    q_of, e_of = terms // size, terms % size
    key = np.sort(comp * size + pos)
    run_by_key = run[np.argsort(comp * size + pos)]

    def run_at(c: int, p: np.ndarray) -> np.ndarray:
        """Weak run number of samples (c, p), -1 for every other sample."""
        k = np.minimum(np.searchsorted(key, c * size + p), len(key) - 1)
        return np.where(key[k] == c * size + p, run_by_key[k], -1)

    entries = []
    for q, (qa, qb) in enumerate(axis_pairs(d)):
        e = e_of[q_of == q]
        entries.append(np.stack([run_at(qa, e), run_at(qa, lay.shifted(e, qb, -1)),
                                 run_at(qb, e), run_at(qb, lay.shifted(e, qa, -1))], axis=1))
    return np.concatenate(entries)


def _unheld_sets(entries: np.ndarray, total: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """From the terms' run numbers ``entries`` [terms, 4] of ``total`` runs: each run's set
    (group [total]), its sign relative to the set's first run, each set's number among the valid
    ones, and which sets are valid (consistently signed and held by nothing) [sets]."""
    signs = np.array([1, -1, 1, -1])
    moving = entries >= 0
    c = moving.sum(axis=1)
    pinned = np.zeros(total, dtype=bool)
    pinned[entries[(c == 1)[:, None] & moving]] = True
    pinned[entries[(c >= 3)[:, None] & moving]] = True
    # terms tying two runs: s1 t1 + s2 t2 = 0, so t2 = -s1 s2 t1. Consistency of the signs around
    # cycles: on the double cover (run, +-1), run r's two copies fall apart iff its set is consistent
    tied = np.nonzero(c == 2)[0]
    col = np.argsort(~moving[tied], axis=1, kind="stable")[:, :2]  # the two moving entries
    r1, r2 = entries[tied, col[:, 0]], entries[tied, col[:, 1]]
    same = -signs[col[:, 0]] * signs[col[:, 1]] > 0
    base = sp.coo_matrix((np.ones(len(tied)), (r1, r2)), shape=(total, total))
    m, group = csgraph.connected_components(base, directed=False)
    twin = np.where(same, 0, total)
    ends = (np.concatenate([r1, r1 + total]), np.concatenate([r2 + twin, r2 + total - twin]))
    cover = sp.coo_matrix((np.ones(2 * len(tied)), ends), shape=(2 * total, 2 * total))
    _, copy = csgraph.connected_components(cover, directed=False)
    consistent = np.ones(m, dtype=bool)
    np.logical_and.at(consistent, group, copy[:total] != copy[total:])
    free_group = np.bincount(group, weights=pinned, minlength=m) == 0
    valid = consistent & free_group
    # the sign of each run relative to the first run of its set
    first = np.full(m, total)
    np.minimum.at(first, group, np.arange(total))
    run_sign = np.where(copy[:total] == copy[first[group]], 1, -1)
    return group, run_sign, np.cumsum(valid) - 1, valid


def _shift_up(lay: TileLayout, values: np.ndarray, axis: int) -> np.ndarray:
    """out[p] = values[p + e_axis] for a flat array [size] on ``lay`` (the zero tile's value where
    p + e_axis is in a tile that is not kept): a slice within each tile, the neighbour tile's first
    layer at its last."""
    d = lay.dim
    tiles = values.reshape((lay.count + 1,) + (TILE,) * d)
    out = np.empty_like(tiles)
    inner = [slice(None)] * (d + 1)
    src = list(inner)
    inner[axis + 1], src[axis + 1] = slice(0, TILE - 1), slice(1, TILE)
    out[tuple(inner)] = tiles[tuple(src)]
    # the last layer reads the first layer of the neighbour tile one step up along axis
    code = (3**d - 1) // 2 + 3 ** (d - 1 - axis)
    up = np.append(lay.neighbours()[:, code], lay.count)  # the zero tile's neighbour is itself
    last, first = list(inner), list(inner)
    last[axis + 1], first[axis + 1] = TILE - 1, 0
    out[tuple(last)] = tiles[tuple(first)][up]
    return out.reshape(-1)


def _fill(level: Level, comp: np.ndarray, pos: np.ndarray) -> float:
    """The largest fraction of the cells just above the samples (comp, pos) along their own axis
    that hold material (a run's cells; 0 when there are none)."""
    out = 0.0
    for a in range(level.dim):
        p = pos[comp == a]
        if len(p):
            out = max(out, float(level.vc_host[p].max()))
    return out


def describe_thin_features(level: Level, mech: Mechanisms) -> str:
    """The user's message for ``mech`` (count > 0) on ``level``: how many motions nothing holds,
    where (sample positions in m when the level knows its origin, else grid indices) and what to
    change. Starts with the setting to change (``grid.cell_size: ...``)."""
    d, h = level.dim, level.spacing
    index = level.layout.indices()[mech.pos].astype(np.float64)
    if level.origin is not None:
        where = np.asarray(level.origin) + h * (index + 0.5 - 0.5 * np.eye(d)[mech.comp])
        unit = " m"
    else:
        where, unit = index, " (grid indices)"
    fmt = lambda v: "(" + ", ".join(f"{x:.4g}" for x in v) + ")"  # noqa: E731
    along = ", ".join(f"{int(np.sum(mech.comp == a))} u_{'xyz'[a]}" for a in range(d) if np.any(mech.comp == a))
    thick = mech.fill * h
    return (
        f"grid.cell_size: {mech.count} independent motion(s) of displacement samples ({len(mech.pos)} DOFs: {along}) "
        f"cost no strain energy, so the stiffness matrix is singular: they lie in material thinner than a grid cell "
        f"(h = {h:.4g} m) that lies inside one cell layer (walls or rods filling at most {mech.fill:.0%} of their "
        f"cells, about {thick:.3g} m thick for a wall), where the staggered grid has one sample across the thickness "
        f"and nothing resists moving it across; the samples lie between {fmt(where.min(axis=0))} and "
        f"{fmt(where.max(axis=0))}{unit}. Refine the grid so that every wall crosses a grid plane (a grid.cell_size "
        f"smaller than the thinnest wall's thickness, here about {thick:.3g} m, does: a wall exactly one cell thick "
        f"can lie between two planes), thicken the walls, or use "
        f"method.kind 'dg'"
    )


def dof_bodies(level: Level, comp: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Body label [n] (1, 2, ...; 0 if none) of face DOFs (comp [n], flat position [n]): the
    connected component of material cells (edge connectivity: cells sharing only a vertex share
    no term) of a cell on either side of the face."""
    d, lay = level.dim, level.layout
    cell = lay.flat(cell_bodies(lay, level.vc_host))
    body = cell[pos].astype(np.int32)  # labels fit; 4 bytes per unknown saved at 20 M DOFs
    for a in range(d):
        on = (comp == a) & (body == 0)
        body[on] = cell[lay.shifted(pos[on], a, -1)]
    # a ghost sample (beside no material, tied by an edge) belongs to the body of a cell around it
    loose = np.nonzero(body == 0)[0]
    if len(loose):
        index = lay.indices()[pos[loose]]
        for o in itertools.product((-1, 0, 1), repeat=d):
            p = lay.positions(index + np.asarray(o))
            found = np.where(p >= 0, cell[np.maximum(p, 0)], 0)
            body[loose] = np.where(body[loose] == 0, found, body[loose])
    return body


def _snap(v: np.ndarray) -> np.ndarray:
    """:func:`weights` in place (the fine level's arrays are hundreds of MB)."""
    v[v > 1.0 - ROUNDOFF] = 1.0
    v[(v > 0) & (v < MIN_FRACTION)] = MIN_FRACTION
    return v


def weights(fractions: np.ndarray) -> np.ndarray:
    """Exact fractions as the operator weighs them: within ROUNDOFF of 1 they are 1, and a weight
    below MIN_FRACTION is raised to it. Tiny weights make local modes that are almost decoupled
    from the body; no coarse grid sees them, so CG spends an iteration on each (sphere, 128^3: 53
    iterations instead of 24). The added stiffness is at most MIN_FRACTION h^d of strain energy
    density per sliver control volume."""
    v = np.where(fractions > 1.0 - ROUNDOFF, 1.0, fractions)
    return np.where((v > 0) & (v < MIN_FRACTION), MIN_FRACTION, v)


def make_fine_level(fractions: VolumeFractions, lam: float, mu: float, dtype: type | None = None,
                    ghosts: list[np.ndarray] | None = None) -> Level:
    """The finest level: the kept tiles are those touching material, with exact fractions.
    ``dtype``: its device float type (default the solve precision). ``ghosts``: per component a
    [k, d] samples outside the material that boundaries' surface points interpolate from
    (``sampling.stencil_samples``); those an edge holding material ties to the body join the
    unknowns (``ghosts.ghost_faces``), with the inertia of ``ghosts.ghost_inertia``."""
    grid = fractions.grid
    d = grid.dim
    box = tuple(n + 1 for n in grid.shape)
    cell_offset = (0,) * d
    unit = [tuple(int(k == a) for k in range(d)) for a in range(d)]
    edge_offsets = [tuple(int(k in p) for k in range(d)) for p in axis_pairs(d)]
    data_tiles = np.concatenate([fractions.control[s].coords for s in fractions.control])
    layout = make_layout(box, dilate(data_tiles, d))
    vc = layout.load(fractions.control[cell_offset])
    # each kind loaded into its row of one array (np.stack of separate rows held every array twice)
    ve, vf = np.zeros((len(edge_offsets), layout.size)), np.zeros((d, layout.size))
    for rows, offsets in ((ve, edge_offsets), (vf, unit)):
        for row, s in zip(rows, offsets):
            layout.load(fractions.control[s], out=row)
    vf[vf > 1.0 - ROUNDOFF] = 1.0
    slivers = int(np.count_nonzero((vc > 0) & (vc < MIN_FRACTION)) + np.count_nonzero((ve > 0) & (ve < MIN_FRACTION)))
    # before the slivers are raised: a ghost tied only by edges of the mesh's round-off would take
    # MIN_FRACTION's stiffness in where a face lies through samples (ghosts.py)
    tie = min(MIN_FRACTION, float32_fraction(grid))
    active, apart = ghost_faces(layout, vc, ve, ghosts, tie) if ghosts is not None else (None, None)
    vc, ve = _snap(vc), _snap(ve)
    level = _pruned(layout, grid.spacing, vc, ve, vf, lam, mu, dtype, active)
    if ghosts is not None:
        level.ghost_inertia = ghost_inertia(level)
        level.ghosts_apart = apart
    level.slivers = slivers
    level.origin = tuple(float(o) for o in grid.origin)
    return level


def make_coarse_level(fine: Level) -> Level:
    """The level of spacing 2h, in the float type of ``fine``: every control volume is a union of
    2^d fine cells, so its fraction is the mean of theirs (exact given the fine cell fractions,
    which are read from the f64 host copy)."""
    d = fine.dim
    box = tuple((n - 1 + 1) // 2 + 3 for n in fine.layout.box)  # ceil(cells / 2) + 2 cells (+ 1 index)
    layout = make_layout(box, dilate(fine.layout.coords // 2, d))
    vc = np.zeros(layout.size)
    ve = np.zeros((len(axis_pairs(d)), layout.size))
    vf = np.zeros((d, layout.size))
    kernels.coarse_fractions(d, layout.coords, layout.tile_map, fine.layout.tile_map, fine.layout.count,
                             fine.vc_host, vc, ve, vf)
    coarse = _pruned(layout, 2 * fine.spacing, vc, ve, vf, fine.lam, fine.mu, fine.dtype)
    if fine.origin is not None:  # coarse cell J covers fine cells 2 J - 2 + {0, 1}^d
        coarse.origin = tuple(o - coarse.spacing for o in fine.origin)
    return coarse


def _vertex_tiles(layout: TileLayout, active: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """[count] bool: the tiles holding an edge E = I + o (o in {0, 1}^d, o_a = 0) whose curl reads an
    active a-face I of a kept tile, where the curl smoothing (``curls.py``) stores that curl's
    coefficient: the tiles above a kept tile's last layers (12 more of 451 on the 64^3 shell; they
    hold no material)."""
    d = layout.dim
    act = active.reshape((d, -1) + (TILE,) * d)[:, : layout.count] & keep.reshape((1, -1) + (1,) * d)
    out = np.zeros(layout.count, dtype=bool)
    shape = np.asarray(layout.tile_map.shape)
    for s in itertools.product((0, 1), repeat=d):
        # the curls reading an a-face are at I + o with o_a = 0: on the last layer along every axis of s
        # (not a), it reaches the tile T + s
        comps = [a for a in range(d) if not s[a]]
        if not any(s) or not comps:
            continue
        view = act[(comps, slice(None)) + tuple(TILE - 1 if sk else slice(None) for sk in s)]
        tiles = np.nonzero(view.reshape(len(comps), layout.count, -1).any(axis=(0, 2)))[0]
        up = layout.coords[tiles].astype(np.int64) + np.asarray(s)
        inside = np.all(up < shape, axis=1)
        t = layout.tile_map[tuple(up[inside].T)]
        out[t[t < layout.count]] = True
    return out


def _pruned(layout: TileLayout, spacing: float, vc, ve, vf, lam: float, mu: float, dtype: type | None,
            active: np.ndarray | None = None) -> Level:
    """Drop the tiles holding no active DOF and no material, then build the level (``active``
    [d, size]: the active faces when not just those beside material)."""
    d, ts = layout.dim, layout.tile_size
    if active is None:
        found = np.zeros((d, layout.size), dtype=np.int32)
        kernels.active_faces(d, layout.coords, layout.tile_map, np.ascontiguousarray(vc, dtype=np.float64), found)
        active = found.astype(bool)
    keep = active.reshape(d, -1, ts)[:, : layout.count].any(axis=(0, 2))
    keep |= (vc.reshape(-1, ts)[: layout.count] > 0).any(axis=1)
    keep |= _vertex_tiles(layout, active, keep)
    if not keep.all():
        layout, order = layout.select(keep)
        vc, ve, vf, active = (reorder(v, order, ts) for v in (vc, ve, vf, active))
    return Level(layout, spacing, vc, ve, vf, lam, mu, dtype, active)


def _slot(values: np.ndarray) -> np.ndarray:
    """``values``, or one zero where it is empty (a device array needs a slot)."""
    return values if len(values) else np.zeros(1, dtype=values.dtype)
