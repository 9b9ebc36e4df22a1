"""The DG method's output at cell centres, at probes (located in their elements) and on the
embedded surface, as a part of ``DGElasticity``.

Displacements are the element polynomials' (on the surface: the smooth embedding,
``embedding.py``). Strains everywhere are the patch fit of ``recovery.py`` (one degree above the
element's own strain) evaluated in the element holding the point; at the surface vertices the
stress then carries the applied tractions (:mod:`engine.surface_stress`, shared with the
staggered method). With stiffness warping every element's strain is its corotated one.

Mixed into ``elasticity.DGElasticity`` (it reads the method's elements, basis and material).
"""

from __future__ import annotations

import numpy as np

from ..material import STRESS_FIELDS, strain_fields
from ..method import State
from ..output import FieldData
from ..surface_stress import SurfaceStress
from .embedding import SurfaceEmbedding
from .lifting import lifted_jumps
from .location import locate, owners
from .recovery import PatchFit, strain_polynomials


class Fields(SurfaceStress):
    """Output fields of ``DGElasticity`` (see the module docstring)."""

    def evaluate(self, u: np.ndarray, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Displacement [N, 3] [m] of coefficients u [E, 3, n] at points [N, 3] of ``element`` [N]."""
        psi = self.basis.values(element, self._xi(element, points))
        return np.einsum("qpi,qi->qp", u[element], psi)

    def gradient(self, u: np.ndarray, element: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Displacement gradient [N, 3, 3] (du_p / dx_a at [:, p, a]) at points of ``element``."""
        grad = self.basis.gradients(element, self._xi(element, points))
        return np.einsum("qpi,qai->qpa", u[element], grad)

    def stress_at(self, u: np.ndarray, element: np.ndarray, points: np.ndarray,
                  rotations: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(strain, stress) Voigt [N, 6] (xx, yy, zz, yz, xz, xy; tensor strain) of the element's own
        polynomial at points of ``element`` (no recovery); with rotations [E, 3, 3] the corotated
        strain sym(R^T F) - I."""
        G = self.gradient(u, element, points)
        if rotations is not None:
            F = np.eye(3) + G
            G = np.einsum("qba,qbc->qac", rotations[element], F) - np.eye(3)
        eps = 0.5 * (G + G.transpose(0, 2, 1))
        voigt = np.stack([eps[:, 0, 0], eps[:, 1, 1], eps[:, 2, 2], eps[:, 1, 2], eps[:, 0, 2], eps[:, 0, 1]], axis=1)
        from ..material import stress as hooke

        return voigt, hooke(voigt, self.lam, self.mu, 3)

    def cell_elements(self) -> tuple[np.ndarray, np.ndarray]:
        """(cells [C, 3], element [C]): every cell holding material and the element of its largest piece."""
        cut, el = self.cut, self.elements
        order = np.lexsort((-cut.volume, self.elements.grid.linear_index(cut.piece_cell)))
        lin = self.elements.grid.linear_index(cut.piece_cell[order])
        first = np.concatenate([[True], lin[1:] != lin[:-1]])
        pick = order[first]
        return cut.piece_cell[pick], el.piece_element[pick]

    def locate(self, points: np.ndarray) -> np.ndarray:
        """Element [N] containing each point, -1 outside the material (surface points count as inside)."""
        return locate(self.elements, self.cut, self.surface, points)

    def owners(self, points: np.ndarray) -> np.ndarray:
        """Element [N] of points known to lie in the solid or on its surface (``location.owners``)."""
        return owners(self.elements, self.cut, points)

    def fields(self, state: State, names: list[str], probes: np.ndarray | None, surface: bool,
               time_value: float | None = None, velocity: np.ndarray | None = None) -> FieldData:
        grid = self.elements.grid
        u = state.u
        cells, element = self.cell_elements()
        centres = grid.sample_points(cells)
        data = FieldData(time=time_value)
        idx = tuple(cells.T)

        def dense(values: np.ndarray) -> np.ndarray:
            out = np.full(tuple(grid.shape) + values.shape[1:], np.nan)
            out[idx] = values
            return out

        strain = (self.recovered_strain(u, state.rotations, state.value_scale)
                  if any(n in names for n in STRESS_FIELDS) else None)
        fit = self.patch_fit() if strain is not None else None
        if "displacement" in names:
            data.cells["displacement"] = dense(self.evaluate(u, element, centres))
        if velocity is not None and "velocity" in names:
            data.cells["velocity"] = dense(self.evaluate(velocity, element, centres))
        if strain is not None:
            for name, val in self._strain_fields(fit.evaluate(strain, element, centres), names).items():
                data.cells[name] = dense(val)
        if probes is not None and len(probes):
            probes = np.asarray(probes, dtype=float)
            where = self.locate(probes)
            ok = where >= 0
            sel = where[ok]

            def probe(values: np.ndarray) -> np.ndarray:
                out = np.full((len(probes),) + values.shape[1:], np.nan)
                out[ok] = values
                return out

            if "displacement" in names:
                data.probes["displacement"] = probe(self.evaluate(u, sel, probes[ok]))
            if velocity is not None and "velocity" in names:
                data.probes["velocity"] = probe(self.evaluate(velocity, sel, probes[ok]))
            if strain is not None:
                for name, val in self._strain_fields(fit.evaluate(strain, sel, probes[ok]), names).items():
                    data.probes[name] = probe(val)
        if surface:
            embedding = self.embedding()
            data.surface["displacement"] = embedding.displacement(u)
            if strain is not None:
                raw = fit.evaluate(strain, embedding.vertex_element, self.surface.vertices)
                data.surface.update(self.surface_stress(raw, names, state.load_scale))
        return data

    def recovered_strain(self, u: np.ndarray, rotations: np.ndarray | None = None, value_scale: float = 1.0
                         ) -> np.ndarray:
        """The patch-fitted Voigt strain of coefficients u [E, 3, n] as monomial coefficients
        [E, 6, n'] in the element frames (``recovery``; corotated with rotations [E, 3, 3]). Its trace
        is the lifted divergence (``lifting``; ``value_scale``: the prescribed values'), which the
        volumetric energy holds, with IP fluxes where the model does not warp (Babuska-Zlamal's form has
        no consistency terms: its volumetric energy reads each element's div u)."""
        strain = strain_polynomials(u, self.basis, rotations)
        if rotations is None and self.flux == "ip":
            points = self.patch_points() if self.patches["count"] else None
            held = self.prescribed_at(points, value_scale) if points is not None else None
            r = lifted_jumps(self.elements, self.basis, u, self.patches, points, held)
            strain[:, :3] -= np.einsum("ei,eis->es", r, self.basis.T)[:, None, :] / 3.0
        return self.patch_fit().fit(strain)

    def patch_fit(self) -> PatchFit:
        """The strain recovery of this geometry (built once)."""
        if getattr(self, "_patch_fit", None) is None:
            self._patch_fit = PatchFit(self.elements, self.basis)
        return self._patch_fit

    def _strain_fields(self, strain: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
        return strain_fields(strain, names, self.lam, self.mu, 3)

    def embedding(self) -> SurfaceEmbedding:
        if getattr(self, "_embedding", None) is None:
            self._embedding = SurfaceEmbedding(self)
        return self._embedding
