"""Views of a result for viewers: the solid as cells with corners, and a surface fine enough to bend.

Derived from a ``Result`` alone (no solver state), so any stored result can be shown:

* ``SolidMesh``: the cells holding material (volume fraction > 0) as hexahedra (quadrilaterals in
  2D) with their corner points, so a viewer shows the object without a Threshold filter; cell
  values are the result's own, and ``node_values`` gives corner values (displacement at nodes) as
  the volume-fraction-weighted mean of the material cells around each corner.
* ``RefinedSurface``: the output surface with every edge longer than the cell size bisected
  (trimesh's conforming bisection: shared midpoints, no cracks). A CAD bar whose STL has vertices
  only at its ends otherwise moves as a rigid body in a viewer while its cells bend. A new vertex
  takes the method's values at the original vertices, interpolated linearly over its original
  facet, plus what the cell field adds there beyond the same linear interpolation:
  ``u(x) = sum_i b_i u_i + (C(x) - sum_i b_i C(x_i))``, with ``b`` the barycentric coordinates of
  ``x`` in its facet, ``u_i`` the method's values at the facet's vertices and ``C`` the cell field
  interpolated to ``x``. Original vertices keep the method's values exactly; an affine cell field
  adds nothing; a bending one bends the facet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .blas import on_one_thread
from .grid import Grid

# VTK's corner order of a hexahedron / quadrilateral, as offsets of the cell's lower corner
_CORNERS = {
    3: np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]),
    2: np.array([[0, 0], [1, 0], [1, 1], [0, 1]]),
}
# The refined surface stops at this many facets (each bisection round at most quadruples them):
# past it the edges are left up to twice, four times ... the cell size instead.
MAX_REFINED_FACES = 400_000


@dataclass
class SolidMesh:
    """The material cells of a grid as an unstructured mesh.

    points: [P, d] corner coordinates [m]; cells: [N, 2^d] corner indices (VTK hexahedron /
    quadrilateral order); index: [N, d] grid index of each cell; node_of: [P, d] grid-node index of
    each point.
    """

    points: np.ndarray
    cells: np.ndarray
    index: np.ndarray
    node_of: np.ndarray

    def cell_values(self, dense: np.ndarray) -> np.ndarray:
        """Values [N, ...] of the material cells from a dense cell array [*grid.shape, ...]."""
        return np.asarray(dense)[tuple(self.index.T)]

    def node_values(self, dense: np.ndarray, volume_fraction: np.ndarray) -> np.ndarray:
        """Corner values [P, ...]: the mean of the finite values of the material cells sharing each
        corner, weighted by their volume fractions (NaN where none is finite)."""
        values = self.cell_values(dense)
        weight = self.cell_values(volume_fraction).astype(np.float64)
        finite = np.isfinite(values.reshape(len(values), -1)).all(axis=1)
        weight = np.where(finite, weight, 0.0)
        values = np.where(finite.reshape((-1,) + (1,) * (values.ndim - 1)), values, 0.0)
        total = np.zeros((len(self.points),) + values.shape[1:])
        norm = np.zeros(len(self.points))
        for corner in range(self.cells.shape[1]):
            ids = self.cells[:, corner]
            np.add.at(total, ids, values * weight.reshape((-1,) + (1,) * (values.ndim - 1)))
            np.add.at(norm, ids, weight)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = total / norm.reshape((-1,) + (1,) * (values.ndim - 1))
        out[norm == 0] = np.nan
        return out


def solid_mesh(grid: Grid, volume_fraction: np.ndarray) -> SolidMesh:
    """The cells with volume fraction > 0 and their corners (shared corners stored once)."""
    d = grid.dim
    index = np.argwhere(np.asarray(volume_fraction) > 0)
    corners = _CORNERS[d]
    node_shape = tuple(n + 1 for n in grid.shape)
    nodes = (index[:, None, :] + corners[None, :, :]).reshape(-1, d)
    keys = np.ravel_multi_index(tuple(nodes.T), node_shape)
    unique, inverse = np.unique(keys, return_inverse=True)
    node_of = np.stack(np.unravel_index(unique, node_shape), axis=1)
    points = np.asarray(grid.origin, dtype=np.float64) + grid.spacing * node_of
    return SolidMesh(points=points, cells=inverse.reshape(len(index), len(corners)).astype(np.int64),
                     index=index.astype(np.int64), node_of=node_of.astype(np.int64))


def interpolate_cells(grid: Grid, dense: np.ndarray, volume_fraction: np.ndarray, points: np.ndarray) -> np.ndarray:
    """A cell-centre field [*grid.shape, ...] at points [Q, d] -> [Q, ...].

    Multilinear between the 2^d cell centres around each point, each weight times the cell's volume
    fraction and renormalised over the cells with finite values, so cells outside the material
    (NaN) do not pull the value; NaN where none of the 2^d cells has a value.
    """
    d = grid.dim
    dense = np.asarray(dense, dtype=np.float64)
    tail = dense.shape[d:]
    s = (np.asarray(points, dtype=np.float64) - np.asarray(grid.origin)) / grid.spacing - 0.5
    base = np.floor(s).astype(np.int64)
    frac = s - base
    total = np.zeros((len(s),) + tail)
    norm = np.zeros(len(s))
    shape = np.asarray(grid.shape)
    for corner in np.ndindex(*(2,) * d):
        c = base + np.asarray(corner)
        inside = np.all((c >= 0) & (c < shape), axis=1)
        w = np.prod(np.where(np.asarray(corner) == 1, frac, 1.0 - frac), axis=1)
        cc = np.clip(c, 0, shape - 1)
        v = dense[tuple(cc.T)]
        ok = inside & np.isfinite(v.reshape(len(s), -1)).all(axis=1)
        w = np.where(ok, w * np.asarray(volume_fraction)[tuple(cc.T)], 0.0)
        total += np.where(ok.reshape((-1,) + (1,) * len(tail)), v, 0.0) * w.reshape((-1,) + (1,) * len(tail))
        norm += w
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / norm.reshape((-1,) + (1,) * len(tail))
    out[norm <= 0] = np.nan
    return out


@dataclass
class RefinedSurface:
    """A surface with no edge longer than ``max_edge`` (where the facet cap allowed it).

    vertices: [M, d] [m]; faces: [K, d]; parent: [M] the original facet each vertex lies on;
    weights: [M, d] its barycentric coordinates there; max_edge [m]: the edge bound reached.
    The first vertices are the original ones, in their order.
    """

    vertices: np.ndarray
    faces: np.ndarray
    parent: np.ndarray
    weights: np.ndarray
    max_edge: float


def _bisect(vertices: np.ndarray, faces: np.ndarray, max_edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, original facet of each face) with edges <= max_edge."""
    if vertices.shape[1] == 2:  # segments: each split into equal pieces
        a, b = vertices[faces[:, 0]], vertices[faces[:, 1]]
        pieces = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / max_edge).astype(np.int64))
        out_v, out_f, out_p = [vertices], [], []
        count = len(vertices)
        for k, (n, f) in enumerate(zip(pieces, faces)):
            inner = a[k] + (b[k] - a[k]) * (np.arange(1, n) / n)[:, None]
            ids = np.concatenate([[f[0]], count + np.arange(n - 1), [f[1]]])
            count += n - 1
            out_v.append(inner)
            out_f.append(np.stack([ids[:-1], ids[1:]], axis=1))
            out_p.append(np.full(n, k))
        return np.concatenate(out_v), np.concatenate(out_f), np.concatenate(out_p)
    from trimesh.remesh import subdivide_to_size

    v, f, parent = subdivide_to_size(vertices, faces, max_edge, max_iter=16, return_index=True)
    return np.asarray(v), np.asarray(f), np.asarray(parent)


def refine_surface(vertices: np.ndarray, faces: np.ndarray, max_edge: float) -> RefinedSurface:
    """Bisect the edges longer than ``max_edge`` [m] (doubling the bound until the result stays
    under MAX_REFINED_FACES facets); returns the refined surface with each vertex's facet."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    d = vertices.shape[1]
    bound = float(max_edge)
    while True:
        v, f, parent_face = _bisect(vertices, faces, bound)
        if len(f) <= max(MAX_REFINED_FACES, len(faces)):
            break
        bound *= 2.0
    if len(v) >= len(vertices):  # the bisection keeps the original vertices first
        assert np.array_equal(v[:len(vertices)], vertices)
    parent = np.zeros(len(v), dtype=np.int64)
    parent[f.reshape(-1)] = np.repeat(parent_face, d)
    corners = vertices[faces[parent]]  # [M, d, d]
    weights = _barycentric(v, corners)
    # the original vertices take their own value exactly (weight 1 on themselves)
    n0 = len(vertices)
    for k in range(d):
        own = faces[parent[:n0], k] == np.arange(n0)
        weights[:n0][own] = np.eye(d)[k]
    return RefinedSurface(vertices=v, faces=f, parent=parent, weights=weights, max_edge=bound)


@on_one_thread
def _barycentric(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Barycentric coordinates [M, d] of points [M, D] in simplices with corners [M, d, D]
    (triangles in 3D, segments in 2D), by least squares in the simplex's own plane."""
    a = corners[:, 0]
    edges = corners[:, 1:] - a[:, None, :]  # [M, d-1, D]
    rhs = points - a
    gram = np.einsum("mid,mjd->mij", edges, edges)
    proj = np.einsum("mid,md->mi", edges, rhs)
    # a degenerate facet (corners on one line, or all in one point; the loader keeps facets of zero
    # area whose corners differ) has a singular Gram matrix: least squares, by its pseudo-inverse,
    # puts the point on the line (or the first corner) and solve() raised "Singular matrix"
    size = np.einsum("mii->m", gram)
    regular = np.linalg.det(gram) > 1e-12 * size ** gram.shape[1]
    lam = np.empty_like(proj)
    lam[regular] = np.linalg.solve(gram[regular], proj[regular][..., None])[..., 0]
    lam[~regular] = np.einsum("mij,mj->mi", np.linalg.pinv(gram[~regular]), proj[~regular])
    return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)


def refined_values(surface: RefinedSurface, faces: np.ndarray, vertex_values: np.ndarray | None,
                   grid: Grid, cell_field: np.ndarray | None, volume_fraction: np.ndarray,
                   original: np.ndarray) -> np.ndarray | None:
    """Values [M, ...] on the refined surface (module docstring): the method's ``vertex_values``
    [m, ...] at the original vertices ``original`` [m, d], corrected by the cell field
    ``cell_field`` [*grid.shape, ...] between them. Either input may be None (then the other alone
    is used); None if both are."""
    corner_ids = np.asarray(faces)[surface.parent]  # [M, d]
    w = surface.weights
    if vertex_values is None and cell_field is None:
        return None
    if cell_field is None:
        vals = np.asarray(vertex_values, dtype=np.float64)
        return np.einsum("mk,mk...->m...", w, vals[corner_ids])
    at_new = interpolate_cells(grid, cell_field, volume_fraction, surface.vertices)
    if vertex_values is None:
        return at_new
    at_old = interpolate_cells(grid, cell_field, volume_fraction, original)
    vals = np.asarray(vertex_values, dtype=np.float64)
    linear = np.einsum("mk,mk...->m...", w, vals[corner_ids])
    correction = at_new - np.einsum("mk,mk...->m...", w, at_old[corner_ids])
    correction = np.where(np.isfinite(correction), correction, 0.0)
    out = linear + correction
    out[:len(original)] = vals  # exactly the method's values where it gave them
    return out
