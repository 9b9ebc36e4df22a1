"""Fields of a staggered solution: at cell centres, at probes and on the surface.

Cell values: displacement the mean of each cell's two face samples per component, strain the
cell's own (normal strains from its faces, shear the fraction-weighted mean of its edges). Probes
and surface vertices take the strain of :func:`recovery.fit_strain` (a linear fit of the cell
strains around the point, second order inside the body) and displacement by interpolating the
samples; surface stresses then carry the applied tractions (:mod:`engine.surface_stress`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..grid import axis_pairs
from ..material import STRESS_FIELDS, strain_fields
from ..output import FieldData
from ..method import State
from ..surface_stress import SurfaceStress
from . import sampling
from .recovery import fit_strain


class StaggeredFields(SurfaceStress):
    """Mixin of ``StaggeredElasticity``: needs ``level``, ``grid``, ``dim``, ``material``,
    ``surface``, ``surface_loads``, ``prescribed`` and ``surface_terms``."""

    def fields(self, state: State, names: list[str], probes: np.ndarray | None, surface: bool,
               time_value: float | None = None, velocity: np.ndarray | None = None) -> FieldData:
        lam, mu = self.material.lame
        d = self.dim
        strain = self.cell_strain(state.u, state.value_scale) if any(n in names for n in STRESS_FIELDS) else None
        cells = self.cell_fields(state.u, names, strain)
        data = FieldData(cells=cells, time=time_value)
        if velocity is not None and "velocity" in names:
            data.cells["velocity"] = self.cell_fields(velocity, ["displacement"])["displacement"]
        if probes is not None and len(probes):
            probes = np.asarray(probes, dtype=float)
            if "displacement" in names:
                data.probes["displacement"] = self.point_displacement(state.u, probes)
            if velocity is not None and "velocity" in names:
                data.probes["velocity"] = self.point_displacement(velocity, probes)
            if strain is not None:
                data.probes.update(strain_fields(self.point_strain(strain, probes), names, lam, mu, d))
        if surface:
            vertices = self.surface.vertices
            data.surface["displacement"] = self.surface_displacement(state.u, vertices)
            if strain is not None:
                data.surface.update(self.surface_stress(self.point_strain(strain, vertices), names, state.load_scale))
        return data

    def point_strain(self, strain: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Voigt strain [P, 6 | 3] at points [P, d] [m] from the cell strains [*shape, 6 | 3]."""
        return fit_strain(self.grid, strain, self._trust(), points)

    def _trust(self) -> np.ndarray:
        """Per-cell weight [*shape] of a cell's strain in fits: its solid fraction."""
        return self.level.layout.dense(self.level.vc_host)[tuple(slice(0, n) for n in self.grid.shape)]

    def point_displacement(self, u: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Displacement [N, d] at points by interpolation of the active samples (NaN outside)."""
        level = self.level

        def lookup(a: int, index: np.ndarray):
            pos = level.layout.positions(index)
            ok = (pos >= 0) & level.active[a, np.maximum(pos, 0)]
            return u[a, np.maximum(pos, 0)] * ok, ok

        return sampling.interpolate(self.grid, np.asarray(points, dtype=float), lookup)

    def surface_displacement(self, u: np.ndarray, vertices: np.ndarray) -> np.ndarray:
        """:meth:`point_displacement` [V, d] at surface vertices [V, d], where a vertex's stencil holds
        no active sample of a component (a self-intersecting shell's fold, a feature thinner than the
        grid resolves) that component's nearest active sample: a vertex is on the solid, never
        outside it, and one NaN vertex spread NaN over the viewers' refined surface."""
        out = self.point_displacement(u, vertices)
        missing = ~np.isfinite(out)
        for a in np.nonzero(missing.any(axis=0))[0]:
            lay = self.level.layout
            pos = np.nonzero(self.level.active[a, : lay.count * lay.tile_size])[0]
            samples = lay.index_of(pos) + 0.5 - 0.5 * np.eye(self.dim)[a]
            at = (np.asarray(vertices)[missing[:, a]] - np.asarray(self.grid.origin)) / self.grid.spacing
            out[missing[:, a], a] = u[a, pos[cKDTree(samples).query(at)[1]]]
        return out

    def cell_fields(self, u: np.ndarray, names: list[str], strain: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Fields at cell centres [*grid.shape, c], NaN where a cell holds no material; ``strain``:
        the cell strains when already computed."""
        d, shape = self.dim, self.grid.shape
        full = self.level.layout.dense(u)  # [d, *box]
        out: dict[str, np.ndarray] = {}
        if "displacement" in names:
            cut = tuple(slice(0, n) for n in shape)
            eye = np.eye(d, dtype=int)
            disp = np.stack([0.5 * (full[a][cut] + _shifted(full[a], eye[a], shape)) for a in range(d)], axis=-1)
            out["displacement"] = np.where(self._solid()[..., None], disp, np.nan)
        if any(n in names for n in STRESS_FIELDS):
            strain = self.cell_strain(u) if strain is None else strain
            lam, mu = self.material.lame
            out.update(strain_fields(strain, names, lam, mu, d))
        return out

    def _solid(self) -> np.ndarray:
        return self._trust() > 0

    def cell_strain(self, u: np.ndarray, value_scale: float = 1.0) -> np.ndarray:
        """Voigt strain [*shape, 6 | 3], NaN where a cell holds no material: normal strains from the
        cell's own faces, shear strains as the edge-fraction-weighted mean of the edges around the
        cell (edges outside the material carry no energy, so their strain is meaningless); in held cut
        cells the trace is their finite-volume divergence (``value_scale``: the prescribed values')."""
        lay, d, h = self.level.layout, self.dim, self.grid.spacing
        shape = self.grid.shape
        full = lay.dense(u)
        cut = tuple(slice(0, n) for n in shape)
        eye = np.eye(d, dtype=int)
        normal = [(_shifted(full[a], eye[a], shape) - full[a][cut]) / h for a in range(d)]
        shear = {}
        unheld = np.zeros(tuple(shape), dtype=bool)  # cells with a shear no edge's energy determines
        for q, (a, b) in enumerate(axis_pairs(d)):
            ua, ub = full[a], full[b]
            inner = tuple(slice(1, None) if k in (a, b) else slice(None) for k in range(d))
            edge = np.zeros_like(ua)
            edge[inner] = 0.5 * ((ua - np.roll(ua, 1, axis=b)) + (ub - np.roll(ub, 1, axis=a)))[inner] / h
            w = lay.dense(self.level.ve_host[q])
            corners = _corners(d, a, b)
            num = sum(_shifted(edge * w, o, shape) for o in corners)
            den = sum(_shifted(w, o, shape) for o in corners)
            plain = sum(_shifted(edge, o, shape) for o in corners) / 4
            shear[(a, b)] = np.where(den > 0, num / np.where(den > 0, den, 1.0), plain)
            unheld |= den == 0
        order = [(1, 2), (0, 2), (0, 1)] if d == 3 else [(0, 1)]
        strain = np.where(self._solid()[..., None], np.stack(normal + [shear[p] for p in order], axis=-1), np.nan)
        self._held_trace(strain, u, value_scale)  # before the cut cells' fit, which reads these cells too
        # a cut cell's own strain reads samples outside the solid that only its sliver of energy
        # determines: its value is the fit of its neighbourhood, weighted to the material. A sliver
        # none of whose edges of a pair holds material has that shear from faces that are no
        # unknowns (zero): it is no data for the fit (a body held at a constant c had strains of
        # c / h there, and 2.6e-3 E |c| / m on its surface through the fit)
        trust = self._trust()
        cut_cells = np.argwhere((trust > 0) & (trust < 1))
        if len(cut_cells):
            centres = np.asarray(self.grid.origin) + (cut_cells + 0.5) * h
            data = np.where(unheld[..., None], np.nan, strain)
            fitted = fit_strain(self.grid, data, trust, centres)
            found = np.isfinite(fitted).all(axis=1)  # else (nothing fit within reach) the cell's own
            strain[tuple(cut_cells[found].T)] = fitted[found]
            self._held_trace(strain, u, value_scale)  # the held ones among them keep their own
        return strain

    def _held_trace(self, strain: np.ndarray, u: np.ndarray, value_scale: float) -> None:
        """Set the trace of the held cut cells' strains [*shape, 6 | 3] (in place) to their finite-volume
        divergence, keeping their deviatoric parts. Near nu = 1/2 their energy reads that divergence,
        the wall's flux prescribed, not their faces' tr(eps), whose wall sample only mu holds: lambda
        times that slack was pressure noise (a bonded block at nu 0.4999, h = 1/8: 2.2 Pa in a rim cell
        beside cells of 0.06 Pa; the clamped sphere's cells up to 57% off, 0.07% now), and the cut
        cells' fits around them read it (a sliver at a clamp's rim 1,400 Pa where the field is 0.2)."""
        held = self.surface_terms.divergence if self.surface_terms is not None else None
        if held is None:
            return
        d = self.dim
        inside = np.all((held.members >= 0) & (held.members < np.asarray(self.grid.shape)), axis=1)
        cells = tuple(held.members[inside].T)
        shift = (held.trace(u, value_scale)[inside] - strain[cells][:, :d].sum(axis=1)) / d
        strain[cells + (slice(0, d),)] += shift[:, None]


def _shifted(a: np.ndarray, offset, shape) -> np.ndarray:
    """a[I + offset] over the cells I of ``shape``."""
    return a[tuple(slice(o, o + n) for o, n in zip(offset, shape))]


def _corners(d: int, a: int, b: int) -> list[tuple[int, ...]]:
    """Offsets of the four (a, b) edges around a cell."""
    return [tuple((k == a) * i + (k == b) * j for k in range(d)) for i in (0, 1) for j in (0, 1)]
