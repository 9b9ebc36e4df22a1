"""Vertex-patch smoothing (engine/staggered/patches.py, patch_kernels.py) against dense numpy.

On a small clamped body (holds by Nitsche's method, so the level has surface terms) with a mass
shift and a few masked DOFs: every patch block is the principal submatrix of the assembled
operator A = K + S + shift M on the free DOFs, and the Taichi gather z = M^-1 r equals
sum_V R_V^T (R_V A R_V^T)^-1 R_V r computed with dense blocks.
"""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from engine.boundary import Prescribed
from engine.geometry.fractions import volume_fractions
from engine.grid import axis_pairs, make_grid
from engine.material import Material
from engine.regions import Halfspaces
from engine.runtime import device_array
from engine.staggered import assembly, patch_kernels
from engine.staggered.elasticity import StaggeredElasticity
from engine.staggered.multigrid import _on_free
from engine.staggered.patches import VertexPatches, patch_matrices
from tests.conftest import polygon_surface_2d, surface_of


def clamped_body(d: int) -> StaggeredElasticity:
    """A disc (2D) or ball (3D) of radius 1 held on its surface below x_d = -0.6, nu = 0.4999."""
    if d == 2:
        t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
        surface = polygon_surface_2d(np.stack([np.cos(t), np.sin(t)], axis=1))
        grid = make_grid(*surface.bounds, resolution=14)
    else:
        import trimesh

        surface = surface_of(trimesh.creation.icosphere(3, radius=1.0))
        grid = make_grid(*surface.bounds, resolution=8)
    eye = np.eye(d)
    below = Halfspaces(eye[[d - 1]], np.array([-0.6]))
    hold = Prescribed(below, (0.0,) * d, "base")
    return StaggeredElasticity(fractions=volume_fractions(surface, grid), surface=surface,
                               material=Material(1.0, 0.4999, 1.0), prescribed=[hold])


def assembled(level) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """(A on the free DOFs, their comp, their pos) with A = K + S + shift M."""
    lay, d = level.layout, level.dim
    comp, pos = np.nonzero(level.free)
    cells = tuple(n - 1 for n in lay.box)
    gid = assembly.dof_index(comp, lay.indices()[pos], cells)
    edges = {p: lay.dense(level.ve_host[q]) for q, p in enumerate(axis_pairs(d))}
    K = assembly.stiffness(lay.dense(level.vc_host), edges, level.spacing, level.lam, level.mu).tocsr()
    A = K[gid][:, gid] + sp.diags(level.shift * level.mass.to_numpy()[comp, pos])
    A = A + _on_free(level.surface, level.surface.matrix(), comp, pos, level.size)
    return A.tocsr(), comp, pos


@pytest.mark.parametrize("d", [2, 3])
def test_patch_smoother_is_the_sum_of_exact_patch_solves(d, rng):
    method = clamped_body(d)
    level = method.level
    level.set_shift(3.0, 1.0)
    # mask a few DOFs (as a coarse level's prescribed ones would be)
    free = level.free.copy()
    on = np.argwhere(free)
    free[tuple(on[rng.choice(len(on), 5, replace=False)].T)] = False
    level.set_free(free)
    A, comp, pos = assembled(level)
    lay, size = level.layout, level.size
    number = -np.ones((d, size), dtype=np.int64)
    number[comp, pos] = np.arange(len(comp))
    # every vertex whose patch holds a free DOF, its patch as free-DOF numbers (-1: not free)
    dofs = patch_kernels._patch_dofs(d)
    index = lay.indices()
    verts = []
    for a, p in zip(comp, pos):
        for o in itertools.product((0, 1), repeat=d):
            if o[a] == 0:
                verts.append(index[p] + np.asarray(o))
    verts = np.unique(np.asarray(verts), axis=0)
    vpos = lay.positions(verts)
    assert np.all(vpos >= 0)
    members = np.stack([np.where((q := lay.positions(verts - np.asarray(o))) >= 0, number[a, np.maximum(q, 0)], -1)
                        for a, o, _ in dofs], axis=1)
    # the host blocks are A's principal submatrices (without the surface terms, which VertexPatches adds)
    A_vol = A - _on_free(level.surface, level.surface.matrix(), comp, pos, size)
    blocks = patch_matrices(level, vpos)
    dense_vol = A_vol.toarray()
    for i in rng.choice(len(verts), 40, replace=False):
        mem = members[i]
        want = np.eye(len(mem))
        on_i = mem >= 0
        want[np.ix_(on_i, on_i)] = dense_vol[np.ix_(mem[on_i], mem[on_i])]
        np.testing.assert_allclose(blocks[i], want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    # z = M^-1 r from the kernel against the dense sum of patch solves
    patches = VertexPatches(level)
    assert 0 < patches.custom < len(verts)
    dense = A.toarray()
    r = rng.standard_normal(len(comp))
    want = np.zeros(len(comp))
    for mem in members:
        on_i = mem >= 0
        if on_i.any():
            sub = dense[np.ix_(mem[on_i], mem[on_i])]
            want[mem[on_i]] += np.linalg.solve(sub, r[mem[on_i]])
    full = np.zeros((d, size))
    full[comp, pos] = r
    z = level.zeros()
    patches.apply(patch_kernels.APPLY, device_array(full), z, z, 0.0, 1.0)
    got = z.to_numpy()
    np.testing.assert_allclose(got[comp, pos], want, rtol=1e-9, atol=1e-9 * np.abs(want).max())
    assert not np.any(got[~level.free])
