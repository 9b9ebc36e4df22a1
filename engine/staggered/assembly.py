"""Reference assembly of the staggered volume-fraction elasticity operator with scipy.sparse.

This is the slow, obviously-correct counterpart of the matrix-free operator: every quantity is
built from the discrete energy (dolny-2025 ch. 4, generalised to 3D)

    E(u) = h^d sum_cells Vc(I) [mu sum_a eps_aa(I)^2 + lambda/2 (sum_a eps_aa(I))^2]
         + h^d sum_{a<b} sum_I Ve_ab(I) 2 mu eps_ab(I)^2

    eps_aa(I) = (u_a(I + e_a) - u_a(I)) / h                                     (cell centre I)
    eps_ab(I) = ((u_a(I) - u_a(I - e_b)) + (u_b(I) - u_b(I - e_a))) / (2 h)     (edge/node (a, b), I)

so K = Hessian(E) = h^d (B_c^T (Vc (x) C) B_c + sum_{a<b} B_ab^T diag(4 mu Ve_ab) B_ab) with
C = 2 mu Id + lambda 1 1^T acting on (eps_11, ..., eps_dd) of one cell.

Layout. Every staggered kind lives on the "index box" of shape n + 1 (n = cells per axis, see
``engine.grid``); all fraction arrays given here have that shape. Displacement component a is
sampled on the a-faces: DOF (a, I) sits at origin + h (I + 1/2 - e_a / 2) and has the global id
a * prod(n + 1) + ravel_multi_index(I, n + 1). Samples of the box that fall outside the grid
(e.g. cell n_k) simply carry zero weight.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..solvers.rigid import rigid_modes  # noqa: F401  (re-exported: the reference's rigid motions)

from ..errors import GridError
from ..grid import Grid, axis_pairs

if TYPE_CHECKING:
    from ..geometry.fractions import VolumeFractions


def box_shape(shape: tuple[int, ...]) -> tuple[int, ...]:
    """Index box (n_k + 1 per axis) of a grid of ``shape`` cells."""
    return tuple(int(n) + 1 for n in shape)


def dof_count(shape: tuple[int, ...]) -> int:
    """Number of displacement DOFs, d * prod(n + 1), of a grid of ``shape`` cells (inactive ones included)."""
    return len(shape) * math.prod(box_shape(shape))


def dof_index(a: int | np.ndarray, index: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Global ids [...] of DOFs (a, I): a * prod(n + 1) + ravel_multi_index(I, n + 1).

    a: component (int, or int array broadcasting against index[..., 0]); index: [..., d] integer
    indices inside the box [0, n + 1) (outside raises ValueError); shape: cells per axis n.
    """
    box = box_shape(shape)
    index = np.asarray(index, dtype=np.int64)
    flat = np.ravel_multi_index(tuple(np.moveaxis(index, -1, 0)), box)
    return np.asarray(a, dtype=np.int64) * math.prod(box) + flat


def dof_components(shape: tuple[int, ...]) -> np.ndarray:
    """Component a [N] (int64) of every DOF, in global id order."""
    return np.repeat(np.arange(len(shape), dtype=np.int64), math.prod(box_shape(shape)))


def dof_positions(grid: Grid) -> np.ndarray:
    """Sample positions [N, d] [m] of all DOFs in global id order: (a, I) at origin + h (I + 1/2 - e_a / 2)."""
    index = _box_indices(box_shape(grid.shape))
    eye = np.eye(grid.dim, dtype=np.int64)
    return np.concatenate([grid.sample_points(index, eye[a]) for a in range(grid.dim)])


def index_box(values: np.ndarray, shape: tuple[int, ...], name: str = "fractions") -> np.ndarray:
    """Zero-pad ``values`` of a native extent (n + s, e.g. ``BlockSparse.dense()``) to the index box n + 1.

    Every axis of ``values`` must have n_k or n_k + 1 entries; the padding is on the high side,
    where the box samples lie outside the grid and carry no material.
    """
    values = np.asarray(values, dtype=float)
    box = box_shape(shape)
    if values.ndim != len(box) or any(m not in (n - 1, n) for m, n in zip(values.shape, box)):
        raise ValueError(
            f"{name}: shape {values.shape} fits neither the cells {tuple(shape)} nor the index box {box}"
        )
    return np.pad(values, [(0, n - m) for m, n in zip(values.shape, box)])


def box_fractions(
    fractions: VolumeFractions,
) -> tuple[np.ndarray, dict[int, np.ndarray], dict[tuple[int, int], np.ndarray]]:
    """(cell, faces, edges) of an ``engine.geometry.fractions.VolumeFractions`` as dense index-box arrays.

    cell: [*(n+1)] Vc; faces: a -> [*(n+1)] Vf_a; edges: (a, b), a < b -> [*(n+1)] Ve_ab. Dimensionless.
    """
    grid = fractions.grid
    d = grid.dim
    eye = np.eye(d, dtype=int)

    def dense(offset: np.ndarray, name: str) -> np.ndarray:
        return index_box(fractions.control[tuple(int(s) for s in offset)].dense(), grid.shape, name)

    cell = dense(np.zeros(d, dtype=int), "cell fractions")
    faces = {a: dense(eye[a], f"face fractions {a}") for a in range(d)}
    edges = {(a, b): dense(eye[a] + eye[b], f"edge fractions {a}{b}") for a, b in list(axis_pairs(d))}
    return cell, faces, edges


def strain_operators(
    shape: tuple[int, ...], spacing: float
) -> tuple[sp.csr_matrix, dict[tuple[int, int], sp.csr_matrix]]:
    """Discrete strains as sparse maps from u [N] (m) to eps (dimensionless).

    B_cell [d * P, N] (P = prod(n + 1)): row a * P + ravel(I) is eps_aa at cell I, for every I of
    the index box. B_edge[(a, b)] [P, N], a < b: row ravel(I) is eps_ab at edge (a, b) index I.
    Neighbours outside the box (u_a(I + e_a) for I_a = n_a, u_a(I - e_b) for I_b = 0, ...) are
    dropped, i.e. treated as zero displacement: those rows are only meaningful where they carry no
    weight, which ``stiffness`` enforces.
    """
    box = box_shape(shape)
    d, P = len(box), math.prod(box)
    index = _box_indices(box)
    rows = np.arange(P, dtype=np.int64)
    eye = np.eye(d, dtype=np.int64)
    h = float(spacing)

    parts = []
    for a in range(d):
        parts.append((a * P + rows, a * P + rows, np.full(P, -1.0 / h)))
        ok, far = _shifted(index, box, eye[a])
        parts.append((a * P + rows[ok], a * P + far, np.full(far.size, 1.0 / h)))
    b_cell = _coo(parts, (d * P, d * P))

    b_edge = {}
    for a, b in list(axis_pairs(d)):
        parts = []
        for comp, other in ((a, b), (b, a)):
            parts.append((rows, comp * P + rows, np.full(P, 0.5 / h)))
            ok, near = _shifted(index, box, -eye[other])
            parts.append((rows[ok], comp * P + near, np.full(near.size, -0.5 / h)))
        b_edge[(a, b)] = _coo(parts, (P, d * P))
    return b_cell, b_edge


def stiffness(
    cell: np.ndarray,
    edges: dict[tuple[int, int], np.ndarray],
    spacing: float,
    lam: float,
    mu: float,
) -> sp.csr_matrix:
    """Stiffness K [N, N] [Pa m^(d-2); N/m in 3D] of the discrete energy E(u) = u^T K u / 2.

    cell: [*(n+1)] cell fractions Vc; edges: (a, b), a < b -> [*(n+1)] Ve_ab (dimensionless, in
    [0, 1]; see ``index_box`` for native-extent arrays); spacing: h [m]; lam, mu: Lame
    parameters [Pa]. N = dof_count(n) with n = cell.shape - 1.
    Raises ValueError for cell weight on the box's high layer (cells outside the grid) and
    GridError for edge weight on the grid's low faces (its stencil leaves the grid).
    """
    cell, edges, shape = _check_weights(cell, edges)
    d, h = cell.ndim, float(spacing)
    b_cell, b_edge = strain_operators(shape, h)
    moduli = 2.0 * mu * np.eye(d) + lam * np.ones((d, d))
    k = b_cell.T @ sp.kron(sp.csr_matrix(moduli), sp.diags(cell.ravel())) @ b_cell
    for pair, b in b_edge.items():
        k = k + b.T @ sp.diags(4.0 * mu * edges[pair].ravel()) @ b
    k = (h**d * k).tocsr()
    k.eliminate_zeros()
    return k


def active_dofs(cell: np.ndarray, edges: dict[tuple[int, int], np.ndarray] | None = None) -> np.ndarray:
    """bool [N]: DOF (a, I) is an unknown iff a cell on either side of its face holds material
    (Vc(I) > 0 or Vc(I - e_a) > 0). ``edges`` is accepted for symmetry and ignored.

    A face held only by edge weights (beside a convex corner of the solid) would be a zero-energy
    mechanism: minimising over it cancels those shear terms. Such faces are not unknowns and the
    edge terms that reach them are dropped (:func:`supported_edges`), which leaves the energy of
    the remaining DOFs unchanged and K regular up to the rigid motions.
    """
    cell = np.asarray(cell, dtype=float)
    return np.concatenate([((cell > 0) | (_shift_up(cell, a) > 0)).ravel() for a in range(cell.ndim)])


def supported_edges(cell: np.ndarray, edges: dict[tuple[int, int], np.ndarray]) -> dict[tuple[int, int], np.ndarray]:
    """Edge weights with every term zeroed whose four shear DOFs are not all active."""
    cell = np.asarray(cell, dtype=float)
    d = cell.ndim
    act = active_dofs(cell).reshape((d,) + cell.shape)
    out = {}
    for (a, b), v in edges.items():
        ok = act[a] & _shift_up(act[a].astype(float), b).astype(bool) & act[b] & _shift_up(act[b].astype(float), a).astype(bool)
        out[(a, b)] = np.where(ok, v, 0.0)
    return out


def mass(face: dict[int, np.ndarray], spacing: float, density: float) -> np.ndarray:
    """Lumped mass diagonal [N] (kg): rho h^d Vf_a(I) at DOF (a, I).

    face: a -> [*(n+1)] face fractions Vf_a (dimensionless); spacing: h [m]; density: rho [kg/m^d].
    """
    d = len(face)
    if sorted(face) != list(range(d)) or d not in (2, 3):
        raise ValueError(f"face fractions: need one array per axis 0..d-1 (d = 2 or 3), got keys {sorted(face)}")
    shapes = {np.shape(face[a]) for a in range(d)}
    if len(shapes) != 1 or len(next(iter(shapes))) != d:
        raise ValueError(f"face fractions: all {d} arrays must share one {d}D index-box shape, got {sorted(shapes)}")
    return density * float(spacing) ** d * np.concatenate([np.asarray(face[a], dtype=float).ravel() for a in range(d)])


def _box_indices(box: tuple[int, ...]) -> np.ndarray:
    """All indices [prod(box), d] of the box in C order."""
    return np.indices(box).reshape(len(box), -1).T.astype(np.int64)


def _shifted(index: np.ndarray, box: tuple[int, ...], shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mask [P] of indices whose shifted neighbour is in the box, linear ids of those neighbours)."""
    moved = index + shift
    ok = np.all((moved >= 0) & (moved < np.asarray(box)), axis=1)
    return ok, np.ravel_multi_index(tuple(moved[ok].T), box)


def _coo(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], shape: tuple[int, int]) -> sp.csr_matrix:
    rows, cols, vals = (np.concatenate(p) for p in zip(*parts))
    return sp.coo_matrix((vals, (rows, cols)), shape=shape).tocsr()


def _shift_up(values: np.ndarray, axis: int) -> np.ndarray:
    """out[I] = values[I - e_axis] (zero where I_axis = 0)."""
    out = np.zeros_like(values)
    src = [slice(None)] * values.ndim
    dst = [slice(None)] * values.ndim
    src[axis], dst[axis] = slice(0, -1), slice(1, None)
    out[tuple(dst)] = values[tuple(src)]
    return out


def _shift_down(values: np.ndarray, axis: int) -> np.ndarray:
    """out[I] = values[I + e_axis] (zero where I_axis = n_axis)."""
    out = np.zeros_like(values)
    src = [slice(None)] * values.ndim
    dst = [slice(None)] * values.ndim
    src[axis], dst[axis] = slice(1, None), slice(0, -1)
    out[tuple(dst)] = values[tuple(src)]
    return out


def _check_weights(
    cell: np.ndarray, edges: dict[tuple[int, int], np.ndarray], check_support: bool = True
) -> tuple[np.ndarray, dict[tuple[int, int], np.ndarray], tuple[int, ...]]:
    """Validate the index-box weights; returns (cell, edges, cells per axis n)."""
    cell = np.asarray(cell, dtype=float)
    d = cell.ndim
    if d not in (2, 3) or min(cell.shape) < 2:
        raise ValueError(f"cell fractions: need a 2D or 3D index box (n + 1 >= 2 per axis), got shape {cell.shape}")
    if sorted(edges) != list(axis_pairs(d)):
        raise ValueError(f"edge fractions: need exactly the pairs {list(axis_pairs(d))} (a < b), got {sorted(edges)}")
    edges = {pair: np.asarray(v, dtype=float) for pair, v in edges.items()}
    for pair, v in edges.items():
        if v.shape != cell.shape:
            raise ValueError(f"edge fractions {pair}: shape {v.shape} differs from the cell index box {cell.shape}")
    if not all(np.all(np.isfinite(v)) for v in (cell, *edges.values())):
        raise ValueError("fractions: must be finite")
    if check_support:
        for k in range(d):
            if np.any(np.take(cell, -1, axis=k) != 0):
                raise ValueError(
                    f"cell fractions: non-zero on the layer {cell.shape[k] - 1} of axis {k}, which lies outside the grid"
                )
        for (a, b), v in edges.items():
            if np.any(np.take(v, 0, axis=a) != 0) or np.any(np.take(v, 0, axis=b) != 0):
                raise GridError(
                    f"edge fractions {(a, b)}: material on the grid's low boundary, where the strain stencil "
                    "leaves the grid; use grid.padding >= 1"
                )
    return cell, edges, tuple(n - 1 for n in cell.shape)
