"""The boundary of the solid: an oriented simplicial surface in d dimensions.

3D: a triangle mesh, outward normals by the right-hand rule. 2D: oriented segments, the solid on
the left of each segment (outer loops counter-clockwise, holes clockwise). The exact cut-cell
geometry relies only on this orientation, which makes one code path serve both dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Surface:
    """vertices: [m, d] float64 [m]; faces: [k, d] int64 vertex indices (triangles / segments).

    closed: every edge (3D) / vertex (2D) is shared by exactly two faces with opposite orientation
    (after any repair). An open surface is still usable through the winding-number fallback.
    warnings: what loading and repair did (merged vertices, filled holes, flipped winding...).
    """

    vertices: np.ndarray
    faces: np.ndarray
    closed: bool = True
    warnings: list[str] = field(default_factory=list)

    @property
    def dim(self) -> int:
        return int(self.vertices.shape[1])

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower [d], upper [d]) of the vertices that faces use [m]."""
        used = self.vertices[np.unique(self.faces)]
        return used.min(axis=0), used.max(axis=0)

    def enclosed_volume(self) -> float:
        """Signed volume (3D, [m^3]) or area (2D, [m^2]) by the divergence theorem."""
        p = self.vertices[self.faces]
        if self.dim == 3:
            return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)
        return float((p[:, 0, 0] * p[:, 1, 1] - p[:, 1, 0] * p[:, 0, 1]).sum() / 2.0)
