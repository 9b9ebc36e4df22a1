"""One grid level of the staggered elasticity operator: its tiles, fractions, masks and apply.

``Level`` owns the Taichi arrays of one level and sequences the kernels of ``kernels.py``:
A = K + shift M restricted to the free DOFs (``mask``), where K is the Hessian of the discrete
energy (DESIGN.md) and M the lumped mass from face fractions (only when a shift is set: static
runs never build a mass). The finest level comes from exact volume fractions
(:func:`make_fine_level`), coarser ones from averaging cell fractions (:func:`make_coarse_level`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
import taichi as ti

from ..geometry.fractions import VolumeFractions
from . import kernels
from .layout import TileLayout, dilate, make_layout, reorder


MIN_FRACTION = 1e-3
# The scan conversion sums prisms, so interior control volumes come out up to ~1e-14 below 1
# (8% of the shell's cells at 128^3). Read as cut, they would keep their tiles off the full-tile
# path and put them in the multigrid's boundary band; within this of 1 a fraction is 1.
ROUNDOFF = 1e-12


def pairs(d: int) -> tuple[tuple[int, int], ...]:
    """Axis pairs (a, b), a < b, of the shear strains, in the order of the ``ve`` rows."""
    return kernels.PAIRS[d]


def float_type() -> type:
    from ..runtime import ensure_initialized

    return np.float64 if ensure_initialized().precision == "f64" else np.float32


def taichi_float():
    """The Taichi type of the solver's float arrays."""
    return ti.f64 if float_type() is np.float64 else ti.f32


def device_array(values: np.ndarray, dtype: type | None = None):
    """A Taichi ndarray holding ``values`` (float arrays in the solve precision)."""
    values = np.asarray(values)
    if dtype is None:
        dtype = float_type() if values.dtype.kind == "f" else values.dtype
    values = np.ascontiguousarray(values, dtype=dtype)
    out = ti.ndarray(dtype={np.float64: ti.f64, np.float32: ti.f32, np.int32: ti.i32}[np.dtype(dtype).type], shape=values.shape)
    out.from_numpy(values)
    return out


@dataclass(frozen=True)
class Part:
    """Tiles of a level an apply works on: ``tiles`` [m] int32 get y = A x, ``stress`` [k] int32
    (``tiles`` and their neighbours) get the weighted stresses that it reads."""

    tiles: object
    stress: object


class Level:
    """The operator on one level. Fractions: vc [size] cells, ve [pairs, size] edges, vf [d, size]
    faces (control-volume fractions in [0, 1]); spacing h [m]; lam, mu [Pa]."""

    def __init__(self, layout: TileLayout, spacing: float, vc: np.ndarray, ve: np.ndarray, vf: np.ndarray,
                 lam: float, mu: float) -> None:
        d = layout.dim
        self.layout, self.spacing, self.dim = layout, float(spacing), d
        self.lam, self.mu = float(lam), float(mu)
        self.vc_host, self.ve_host, self.vf_host = vc, ve, vf
        size, ts = layout.size, layout.tile_size
        self.coords = device_array(layout.coords.astype(np.int32))
        self.tmap = device_array(layout.tile_map.astype(np.int32))
        self.nbr = device_array(layout.neighbours())
        every = device_array(np.arange(layout.count, dtype=np.int32))
        self.everywhere = Part(every, every)
        self.vc, self.ve = device_array(vc), device_array(ve)
        active = device_array(np.zeros((d, size), dtype=np.int32))
        kernels.active_faces(d, self.coords, self.tmap, self.vc, active)
        kernels.prune_edges(d, self.coords, self.tmap, active, self.ve)
        self.active = active.to_numpy().astype(bool)
        self.ve_host = ve = self.ve.to_numpy().astype(np.float64)
        full = np.ones(layout.count, dtype=bool)
        for v in (vc[None], ve):
            full &= np.all(v.reshape(len(v), -1, ts)[:, : layout.count] == 1.0, axis=(0, 2))
        self.full_tiles = int(full.sum())
        self.full = device_array(full.astype(np.int32))
        self.sc = device_array(np.zeros((d, size)))
        self.se = device_array(np.zeros((len(pairs(d)), size)))
        self.shift, self.density = 0.0, 0.0
        self.slivers = 0  # control volumes whose weight was raised to MIN_FRACTION
        self.mass = None  # [d, size] rho h^d Vf, built only when a shift (dynamics) is set
        self.set_free(self.active)

    @property
    def size(self) -> int:
        return self.layout.size

    def zeros(self):
        return ti.ndarray(dtype=taichi_float(), shape=(self.dim, self.size))

    def set_free(self, free: np.ndarray) -> None:
        """free [d, size] bool: the unknowns (active and not prescribed)."""
        self.free = np.asarray(free, dtype=bool) & self.active
        self.mask = device_array(self.free.astype(float))
        self._update_diagonal()

    def set_shift(self, shift: float, density: float) -> None:
        """A = K + shift M with M = rho h^d Vf (backward Euler: shift = 1 / dt^2)."""
        self.shift, self.density = float(shift), float(density)
        if self.mass is None and shift != 0.0:
            self.mass = device_array(density * self.spacing**self.dim * self.vf_host)
        self._update_diagonal()

    def _mass_or_mask(self):
        return self.mass if self.mass is not None else self.mask

    def _update_diagonal(self) -> None:
        self.dinv = self.zeros()
        d = self.dim
        kernels.inverse_diagonal(d, self.coords, self.tmap, self.mask, self.vc, self.ve, self.lam, self.mu,
                                 self.spacing ** (d - 2), self._mass_or_mask(), self.shift, self.dinv)

    def part(self, tiles: np.ndarray) -> Part:
        """The ``Part`` of the kept tiles ``tiles`` [m] (tile numbers)."""
        tiles = np.unique(np.asarray(tiles, dtype=np.int32))
        halo = np.unique(self.layout.neighbours()[tiles])
        halo = halo[halo < self.layout.count]
        return Part(device_array(tiles), device_array(halo.astype(np.int32)))

    def apply(self, x, y, part: Part | None = None) -> None:
        """y = A x on the free DOFs (x must vanish off them); only in ``part``'s tiles when given."""
        d = self.dim
        part = part or self.everywhere
        kernels.weighted_stresses(d, part.stress, self.nbr, self.full, x, self.vc, self.ve,
                                  self.lam, self.mu, 1.0 / self.spacing, self.sc, self.se)
        kernels.stress_divergence(d, part.tiles, self.nbr, self.mask, self.sc, self.se,
                                  self.spacing ** (d - 1), x, self._mass_or_mask(), self.shift, y)

    def apply_unmasked(self, x, y) -> None:
        """y = K x at every active DOF (for loads from prescribed values and reactions)."""
        saved = self.mask
        self.mask = device_array(self.active.astype(float))
        try:
            self.apply(x, y)
        finally:
            self.mask = saved


def dof_bodies(level: Level, index: np.ndarray, comp: np.ndarray) -> np.ndarray:
    """Body label [n] (1, 2, ...; 0 if none) of face DOFs (comp [n], global index [n, d]): the
    connected component of material cells (edge connectivity: cells sharing only a vertex share
    no term) of a cell on either side of the face."""
    d = level.dim
    cell = level.layout.dense(level.vc_host)
    labels, _ = ndi.label(cell > 0, structure=ndi.generate_binary_structure(d, 2))
    body = np.zeros(len(index), dtype=np.int64)
    for J in (index, index - np.eye(d, dtype=np.int64)[comp]):
        ok = np.all((J >= 0) & (J < np.asarray(cell.shape)), axis=1)
        lab = np.zeros(len(J), dtype=np.int64)
        lab[ok] = labels[tuple(J[ok].T)]
        body = np.where(body == 0, lab, body)
    return body


def weights(fractions: np.ndarray) -> np.ndarray:
    """Exact fractions as the operator weighs them: within ROUNDOFF of 1 they are 1, and a weight
    below MIN_FRACTION is raised to it. Tiny weights make local modes that are almost decoupled
    from the body; no coarse grid sees them, so CG spends an iteration on each (sphere, 128^3: 53
    iterations instead of 24). The added stiffness is at most MIN_FRACTION h^d of strain energy
    density per sliver control volume."""
    v = np.where(fractions > 1.0 - ROUNDOFF, 1.0, fractions)
    return np.where((v > 0) & (v < MIN_FRACTION), MIN_FRACTION, v)


def make_fine_level(fractions: VolumeFractions, lam: float, mu: float) -> Level:
    """The finest level: the kept tiles are those touching material, with exact fractions."""
    grid = fractions.grid
    d = grid.dim
    box = tuple(n + 1 for n in grid.shape)
    cell_offset = (0,) * d
    unit = [tuple(int(k == a) for k in range(d)) for a in range(d)]
    edge_offsets = [tuple(int(k in p) for k in range(d)) for p in pairs(d)]
    data_tiles = np.concatenate([fractions.control[s].coords for s in fractions.control])
    layout = make_layout(box, dilate(data_tiles, d))
    vc = layout.load(fractions.control[cell_offset])
    ve = np.stack([layout.load(fractions.control[s]) for s in edge_offsets])
    vf = np.stack([layout.load(fractions.control[s]) for s in unit])
    vf = np.where(vf > 1.0 - ROUNDOFF, 1.0, vf)
    slivers = int(np.count_nonzero((vc > 0) & (vc < MIN_FRACTION)) + np.count_nonzero((ve > 0) & (ve < MIN_FRACTION)))
    vc, ve = weights(vc), weights(ve)
    level = _pruned(layout, grid.spacing, vc, ve, vf, lam, mu)
    level.slivers = slivers
    return level


def make_coarse_level(fine: Level) -> Level:
    """The level of spacing 2h: every control volume is a union of 2^d fine cells, so its fraction
    is the mean of theirs (exact given the fine cell fractions)."""
    d = fine.dim
    box = tuple((n - 1 + 1) // 2 + 3 for n in fine.layout.box)  # ceil(cells / 2) + 2 cells (+ 1 index)
    layout = make_layout(box, dilate(np.unique(fine.layout.coords // 2, axis=0), d))
    vc_dev = device_array(np.zeros(layout.size))
    ve_dev = device_array(np.zeros((len(pairs(d)), layout.size)))
    vf_dev = device_array(np.zeros((d, layout.size)))
    kernels.coarse_fractions(d, device_array(layout.coords.astype(np.int32)), device_array(layout.tile_map.astype(np.int32)),
                             fine.tmap, fine.layout.count, fine.vc, vc_dev, ve_dev, vf_dev)
    return _pruned(layout, 2 * fine.spacing, vc_dev.to_numpy(), ve_dev.to_numpy(), vf_dev.to_numpy(), fine.lam, fine.mu)


def _pruned(layout: TileLayout, spacing: float, vc, ve, vf, lam: float, mu: float) -> Level:
    """Drop the tiles holding no active DOF and no material, then build the level."""
    d, ts = layout.dim, layout.tile_size
    active = device_array(np.zeros((d, layout.size), dtype=np.int32))
    kernels.active_faces(d, device_array(layout.coords.astype(np.int32)), device_array(layout.tile_map.astype(np.int32)),
                         device_array(vc), active)
    keep = active.to_numpy().reshape(d, -1, ts)[:, : layout.count].any(axis=(0, 2))
    keep |= (vc.reshape(-1, ts)[: layout.count] > 0).any(axis=1)
    if not keep.all():
        layout, order = layout.select(keep)
        vc, ve, vf = reorder(vc, order, ts), reorder(ve, order, ts), reorder(vf, order, ts)
    return Level(layout, spacing, vc, ve, vf, lam, mu)
