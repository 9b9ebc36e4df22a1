"""The peer of the accuracy benchmark: what a user would pick instead of voxelastic.

scikit-fem P1 / P2 Lagrange elements (tetrahedra in 3D, triangles in 2D) on conforming gmsh
meshes of the true curved geometry (OpenCASCADE spheres / disks, boolean cut, uniform
characteristic length h), solved with CG preconditioned by a pyamg smoothed-aggregation V-cycle
that is given the rigid-body modes as near-null space ``B``, to ||b - A x|| < rtol ||b|| (the same
relative criterion, and default 1e-10, as voxelastic's runs). The problems, exact solutions and
probe points are those of :mod:`verification.problems`:

- ``lame``: shell 0.5 < r < 1 with the true radii (exact solution
  ``lame_problem(0.5, 1.0, p, E, nu, problem("lame").probes)``), traction -p n on the inner sphere
  (n the outward normal of the solid, which points to the centre there, so the shell inflates;
  checked: the mean radial displacement at the probes has the exact sign and size), nothing
  prescribed. K is then singular with the 6 rigid modes R, which P1 / P2 hold exactly. The
  pressure on the closed inner surface balances, and the right-hand side is projected onto
  range(K) = R^perp (Euclidean, in DOF space; this only removes round-off). CG runs on the singular
  system with the AMG V-cycle followed by the same projection, so every iterate stays in R^perp
  (pyamg solves the singular coarsest level by pseudo-inverse). Then the rigid part is removed in
  the L2 sense, integral of u and of x cross u over the mesh = 0: the continuous condition the
  exact radial solution meets, whereas the Euclidean DOF condition alone leaves a mesh-dependent
  rigid motion.
- ``annulus``: 2D plane strain, 0.325 < r < 0.8, body force, u = exact on the inner circle,
  traction sigma_exact(x) n on the outer circle with the normals of the mesh's boundary.
- ``ball``: unit ball, body force, u = exact on the facets whose centroid has z <= BALL_CAP, the
  traction sigma_exact(x) n on the others.

Dirichlet values interpolate the exact field at the boundary DOFs (vertices, and for P2 the edge
nodes). Body forces and tractions use Gauss order 2 * order + 2; the stiffness the order that is
exact on affine elements, 2 * (order - 1), which is also what isoparametric P2 needs
for its optimal rate (Ciarlet & Raviart 1972). Von Mises at the probes comes from
the FE stress of the element that contains the probe (2D: plane strain, sigma_zz = lambda tr eps,
as ``Problem.von_mises``).

Geometry: ``geometry="straight"`` (default) meshes with straight-sided simplices, so the boundary
is the inscribed polyhedron / polygon: its O(h^2) distance from the true boundary limits P2 to
O(h^2) on ``lame``, where the pressure acts on the facetted inner surface; the Dirichlet / traction
data of ``ball`` and ``annulus`` come from the exact field on the mesh's own boundary, so those keep
O(h^3). ``geometry="curved"`` (P2 only) asks gmsh for second-order elements (``setOrder(2)``:
boundary edge nodes on the true surface) and uses isoparametric P2 (scikit-fem MeshTet2 /
MeshTri2), which recovers O(h^3) on ``lame``. With straight sides, probes between a chord and the
curved boundary (coarse h: the 2% margin is then thinner than the chords' sagitta) raise
:class:`ProbeOutsideMesh`, unless ``outside="nearest"`` extrapolates from the closest element.

``geometry="stl"`` meshes what voxelastic is given instead of the CAD solid: the problem's STL
(icospheres of 81,920 triangles per sphere) tetrahedralised by fTetWild (``pytetwild``, ideal edge
length h, its default envelope of 1e-3 of the bounding box diagonal, all cores), straight-sided:
the input a user brings, meshed the way a robust mesher does it. gmsh meshing the STL directly
needs a watertight, well-shaped surface and reclassification, which fTetWild does not.

Commands (from the repository root)::

    .venv/bin/python -m benchmarks.peer --problem lame --order 2 --h 0.2 [--rtol 1e-10]
        [--geometry straight|curved|stl] [--outside error|nearest]
    .venv/bin/python -c "from benchmarks.peer import run_peer; print(run_peer('ball', 1, 0.2)['error_u'])"

Installs (Debian 12, Python 3.11, numpy 1.26.4, scipy 1.17.1): ``.venv/bin/pip install -e
'.[benchmarks]'`` (scikit-fem 12.0.2, pyamg 5.4.1, gmsh 4.15.2, pytetwild 0.4.2). The gmsh wheel's
libgmsh.so links libGLU, libGL, libXcursor, libXft, libXinerama, libXrender, libXfixes, libXext,
libX11, libfontconfig and libgomp, all on this image; on a bare Debian / Ubuntu image: ``apt-get
install -y libglu1-mesa libgl1 libxcursor1 libxft2 libxinerama1 libxrender1 libfontconfig1
libgomp1``. The DOLFINx peer beside this one: ``benchmarks.dolfinx_peer``.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass

import numpy as np

from verification.problems import BALL_CAP, Problem, lame_problem, problem, relative_l2, von_mises_of

LOAD_ORDER_EXTRA = 2  # body force / traction quadrature: 2 * order + this (smooth sin / cos data)
MAX_CG_ITERATIONS = 5000
INSIDE_TOLERANCE = 1e-10  # barycentric undershoot still counted as inside (round-off on shared faces)


class ProbeOutsideMesh(RuntimeError):
    """Some probes are in no element of the mesh."""


@dataclass
class _Discretisation:
    """The meshed problem: mesh, vector basis and which boundary facets carry what."""

    mesh: object  # skfem MeshTet1 / MeshTri1, or MeshTet2 / MeshTri2 (curved)
    basis: object  # skfem CellBasis with ElementVector(P1 / P2)
    vertex_mapping: object  # affine mapping of the straight simplices (probe search)
    dirichlet_facets: np.ndarray  # facet indices with u = exact
    load_facets: np.ndarray  # facet indices with a traction (lame: pressure, annulus: sigma n)


@dataclass
class _GmshMesh:
    """Vertices [n, d] [m], simplices [E, d + 1] (0-based) and, for second order, one node per edge:
    its vertex pair [m, 2] (sorted) and position [m, d] [m]."""

    points: np.ndarray
    cells: np.ndarray
    edge_pairs: np.ndarray | None = None
    edge_points: np.ndarray | None = None


# ----------------------------------------------------------------------------- meshing
def _gmsh_mesh(name: str, radii: tuple[float, ...], h: float, curved: bool) -> _GmshMesh:
    """Conforming simplex mesh of the true geometry with uniform size h [m]."""
    import gmsh

    gmsh.initialize(interruptible=False)  # no signal handlers: may run outside the main thread
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
        occ = gmsh.model.occ
        if name == "lame":
            a, b = radii
            occ.cut([(3, occ.addSphere(0, 0, 0, b))], [(3, occ.addSphere(0, 0, 0, a))])
            dim = 3
        elif name == "annulus":
            a, b = radii
            occ.cut([(2, occ.addDisk(0, 0, 0, b, b))], [(2, occ.addDisk(0, 0, 0, a, a))])
            dim = 2
        elif name == "ball":
            occ.addSphere(0, 0, 0, radii[0])
            dim = 3
        else:
            raise KeyError(f"problem: one of ['annulus', 'ball', 'lame'], got {name!r}")
        occ.synchronize()
        # one size everywhere, the characteristic length the benchmark sweeps: no refinement
        # from curvature or from the CAD points
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        return read_gmsh_mesh(dim, curved)
    finally:
        gmsh.finalize()


def ftetwild(vertices: np.ndarray, faces: np.ndarray, **options) -> tuple[np.ndarray, np.ndarray]:
    """(points [n, 3], tets [E, 4]) of ``pytetwild.tetrahedralize`` run in a scratch directory:
    fTetWild writes ``__tracked_surface.stl`` into the working directory (a copy had been
    committed at the repository root)."""
    import contextlib
    import tempfile

    import pytetwild

    with tempfile.TemporaryDirectory() as scratch, contextlib.chdir(scratch):
        points, tets = pytetwild.tetrahedralize(np.asarray(vertices, dtype=np.float64),
                                                np.asarray(faces, dtype=np.int32), **options)
    return np.asarray(points, dtype=np.float64), np.asarray(tets, dtype=np.int64)


def _stl_mesh(prob: Problem, h: float) -> _GmshMesh:
    """fTetWild (pytetwild) tetrahedra of the triangles voxelastic reads for the problem (its STL: the
    icospheres of ``verification.problems``), ideal edge length h [m], fTetWild's default envelope
    (1e-3 of the bounding box diagonal) and all cores: what a user meshing their STL would run. The
    tetrahedra are straight, so P2 on them is straight-sided."""
    if prob.dim != 3:
        raise ValueError(f"geometry 'stl': a 3D problem, got {prob.name!r}")
    mesh = prob.surface_mesh()
    return _GmshMesh(*ftetwild(mesh.vertices, mesh.faces, edge_length_abs=h))


def read_gmsh_mesh(dim: int, curved: bool) -> _GmshMesh:
    """Generate the current gmsh model's mesh (sizes already set) and read it back: simplices of
    dimension ``dim``, second order with edge nodes on the CAD boundary when ``curved``. Call between
    ``gmsh.initialize`` and ``gmsh.finalize``."""
    import gmsh

    gmsh.model.mesh.generate(dim)
    if curved:
        gmsh.model.mesh.setOrder(2)  # boundary edge nodes on the CAD surface, interior ones midway
    cell_type = {(3, False): 4, (3, True): 11, (2, False): 2, (2, True): 9}[dim, curved]
    local = gmsh.model.mesh.getElementProperties(cell_type)[4].reshape(-1, dim)  # reference nodes
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, nodes = gmsh.model.mesh.getElementsByType(cell_type)
    coords = coords.reshape(-1, 3)[:, :dim]
    lookup = np.full(int(tags.max()) + 1, -1, dtype=np.int64)  # tags: 1-based, with gaps
    lookup[tags.astype(np.int64)] = np.arange(len(tags))
    elem_nodes = lookup[nodes.reshape(-1, len(local)).astype(np.int64)]
    vertices = elem_nodes[:, : dim + 1]
    used = np.unique(vertices)
    renumber = np.full(len(tags), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    out = _GmshMesh(coords[used], renumber[vertices])
    if curved:
        # which vertex pair each higher-order node sits between, from gmsh's reference coordinates
        corners = local[: dim + 1]
        mid = 0.5 * (corners[:, None] + corners[None, :])  # [d + 1, d + 1, d]
        cols = np.arange(dim + 1, len(local))
        pairs = np.array([np.argwhere(np.all(np.isclose(mid, local[j]), axis=-1))[0] for j in cols])
        edge_pairs = np.sort(out.cells[:, pairs], axis=-1).reshape(-1, 2)  # [E * edges, 2]
        edge_points = coords[elem_nodes[:, cols]].reshape(-1, dim)
        edge_pairs, first = np.unique(edge_pairs, axis=0, return_index=True)
        out.edge_pairs, out.edge_points = edge_pairs, edge_points[first]
    return out


def skfem_mesh(gm: _GmshMesh, dim: int) -> tuple[object, object]:
    """scikit-fem meshes (mesh, its straight simplices): MeshTet1 / MeshTri1 twice, or
    MeshTet2 / MeshTri2 with gmsh's edge nodes and the MeshTet1 / MeshTri1 of its vertices."""
    import skfem
    from skfem.assembly import Dofs

    p, t = gm.points.T.copy(), gm.cells.T.astype(np.int32).copy()
    linear = skfem.MeshTet1(p, t) if dim == 3 else skfem.MeshTri1(p, t)
    if gm.edge_pairs is None:
        return linear, linear
    if dim == 3:
        quadratic_cls, p2 = skfem.MeshTet2, skfem.ElementTetP2()
    else:
        quadratic_cls, p2 = skfem.MeshTri2, skfem.ElementTriP2()
    mesh = quadratic_cls.from_mesh(linear)  # straight edge midpoints, then moved to gmsh's nodes
    dofs = Dofs(linear, p2)
    # the P2 DOF of an edge: an edge DOF in 3D, a facet DOF in 2D
    if dim == 3:
        edges, edge_dofs = linear.edges, dofs.edge_dofs[0]
    else:
        edges, edge_dofs = linear.facets, dofs.facet_dofs[0]
    doflocs = mesh.doflocs.copy()
    doflocs[:, edge_dofs] = gm.edge_points[edge_nodes(gm, edges.T)].T
    return quadratic_cls(doflocs, mesh.t), linear


def edge_nodes(gm: _GmshMesh, ends: np.ndarray) -> np.ndarray:
    """Index into ``gm.edge_points`` of the node on each edge ends [M, 2] (vertex pairs, any order)."""
    n = len(gm.points)
    ours = np.sort(np.asarray(ends, dtype=np.int64), axis=1)
    key_ours, key_gmsh = ours[:, 0] * n + ours[:, 1], gm.edge_pairs[:, 0] * n + gm.edge_pairs[:, 1]
    order = np.argsort(key_gmsh)
    where = order[np.searchsorted(key_gmsh[order], key_ours).clip(max=len(order) - 1)]
    if not np.array_equal(key_gmsh[where], key_ours):
        raise RuntimeError("gmsh's second-order nodes do not match the mesh edges")
    # a node of the wrong edge would be half an edge off; the curving moves it O(h^2)
    a, b = gm.points[ours[:, 0]], gm.points[ours[:, 1]]
    if np.any(np.linalg.norm(gm.edge_points[where] - 0.5 * (a + b), axis=1) > 0.25 * np.linalg.norm(b - a, axis=1)):
        raise RuntimeError("gmsh's second-order nodes are far from their edges' midpoints")
    return where


def make_mesh(prob: Problem, h: float, geometry: str) -> _GmshMesh:
    """The peer's mesh of the problem (see :func:`run_peer`'s geometry)."""
    return _stl_mesh(prob, h) if geometry == "stl" else _gmsh_mesh(prob.name, prob.radii, h, geometry == "curved")


def facet_roles(prob: Problem, centroids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks [F] of the boundary facets (centroids [F, d] [m]) holding u = exact / carrying the load."""
    radius = np.linalg.norm(centroids, axis=1)
    inner = radius < 0.5 * sum(prob.radii[:2])
    if prob.name == "lame":
        return np.zeros_like(inner), inner
    if prob.name == "annulus":
        return inner, ~inner
    cap = centroids[:, -1] <= BALL_CAP  # facets straddling the plane go by their centroid
    return cap, ~cap


def _discretise(prob: Problem, order: int, h: float, geometry: str) -> _Discretisation:
    import skfem
    from skfem.mapping import MappingAffine

    mesh, linear = skfem_mesh(make_mesh(prob, h, geometry), prob.dim)
    if prob.dim == 3:
        scalar = skfem.ElementTetP1() if order == 1 else skfem.ElementTetP2()
    else:
        scalar = skfem.ElementTriP1() if order == 1 else skfem.ElementTriP2()
    # order 2 (p - 1): exact on affine elements, and what isoparametric P2 needs for its optimal rate
    # (Ciarlet & Raviart 1972: exact for degree 2p - 2 on the reference element)
    basis = skfem.Basis(mesh, skfem.ElementVector(scalar), intorder=2 * (order - 1))
    boundary = mesh.boundary_facets()
    held, loaded = facet_roles(prob, mesh.p[:, mesh.facets[:, boundary]].mean(axis=1).T)
    return _Discretisation(mesh, basis, MappingAffine(linear), boundary[held], boundary[loaded])


# ----------------------------------------------------------------------------- assembly
def _components(basis) -> np.ndarray:
    """Component [N] of each global DOF of an ElementVector basis."""
    d = basis.mesh.dim()
    # scikit-fem numbers vector DOFs node-major, DOF = d * (scalar DOF) + component: checked, not assumed
    first = basis.element_dofs[::d]
    expected = np.repeat(first, d, axis=0) + np.tile(np.arange(d), len(first))[:, None]
    if not np.array_equal(basis.element_dofs, expected):
        raise RuntimeError("unexpected scikit-fem vector DOF layout")
    return np.arange(basis.N) % d


def _rigid_modes(basis, comp: np.ndarray) -> np.ndarray:
    """Rigid modes [N, 6 | 3] at the DOFs: translations, then rotations about the centroid."""
    x = basis.doflocs.T - basis.mesh.p.mean(axis=1)  # [N, d] [m]; centred: better conditioned
    d = x.shape[1]
    rows = np.arange(len(comp))
    cols = [(comp == k).astype(float) for k in range(d)]
    if d == 2:
        cols.append(np.where(comp == 0, -x[:, 1], x[:, 0]))
    else:
        for k in range(3):  # rotation about axis k: e_k cross x
            cols.append(np.cross(np.eye(3)[k], x)[rows, comp])
    return np.stack(cols, axis=1)


def _vector_function(f, x: np.ndarray) -> np.ndarray:
    """f (points [M, d] -> values [M, d]) at quadrature points x [d, E, Q] -> [d, E, Q]."""
    d = x.shape[0]
    return f(x.reshape(d, -1).T).T.reshape(x.shape)


def _assemble(prob: Problem, disc: _Discretisation, order: int):
    """Stiffness K [N, N], loads f [N] [N], prescribed values u_D [N] [m] and the prescribed DOFs D."""
    import skfem
    from skfem.helpers import dot
    from skfem.models.elasticity import linear_elasticity

    lam, mu = prob.lame
    basis, mesh = disc.basis, disc.mesh
    K = skfem.asm(linear_elasticity(lam, mu), basis)
    f = np.zeros(basis.N)
    load_order = 2 * order + LOAD_ORDER_EXTRA
    if prob.body_force is not None:
        @skfem.LinearForm
        def body(v, w):
            return dot(_vector_function(prob.body_force, w.x), v)

        f += skfem.asm(body, skfem.Basis(mesh, basis.elem, mapping=basis.mapping, intorder=load_order))
    if len(disc.load_facets):
        fb = skfem.FacetBasis(mesh, basis.elem, facets=disc.load_facets, intorder=load_order)
        if prob.name == "lame":
            p = prob.pressure

            @skfem.LinearForm
            def pressure(v, w):
                return -p * dot(w.n, v)  # w.n: outward normal of the solid, towards the centre here

            f += skfem.asm(pressure, fb)
        else:
            @skfem.LinearForm
            def traction(v, w):
                x, n = w.x, w.n
                d = x.shape[0]
                sigma = prob.stress(x.reshape(d, -1).T)  # [M, d, d]
                t = np.einsum("mij,jm->im", sigma, n.reshape(d, -1)).reshape(x.shape)
                return dot(t, v)

            f += skfem.asm(traction, fb)
    u_D = np.zeros(basis.N)
    D = np.zeros(0, dtype=np.int64)
    if len(disc.dirichlet_facets):
        D = basis.get_dofs(facets=disc.dirichlet_facets).all()  # vertex and (P2) edge DOFs
        comp = _components(basis)
        u_D[D] = prob.exact(basis.doflocs[:, D].T)[np.arange(len(D)), comp[D]]
    return K, f, u_D, D


# ----------------------------------------------------------------------------- solve
def _solve(K, f: np.ndarray, u_D: np.ndarray, D: np.ndarray, modes: np.ndarray, d: int, rtol: float,
           floating: bool) -> tuple[np.ndarray, int, float]:
    """u [N] [m], CG iterations, and the true final ||b - A x|| / ||b|| of the condensed system."""
    import pyamg
    from scipy.sparse.linalg import LinearOperator

    free = np.setdiff1d(np.arange(K.shape[0]), D)
    K = K.tocsr()
    A = K[free][:, free].tocsr()
    b = f[free] - K[free][:, D] @ u_D[D]
    B = modes[free]
    # Dirichlet takes every component of a node and DOFs are node-major, so d x d blocks survive
    A_amg = A.tobsr(blocksize=(d, d)) if len(free) % d == 0 else A
    ml = pyamg.smoothed_aggregation_solver(A_amg, B=B)
    amg = ml.aspreconditioner(cycle="V")
    if floating:
        q, _ = np.linalg.qr(B)  # orthonormal basis of the rigid modes (Euclidean, DOF space)

        def project(v: np.ndarray) -> np.ndarray:
            return v - q @ (q.T @ v)

        b = project(b)  # range(K) = null(K)^perp; the pressure balances, so this only drops round-off
        M = LinearOperator(A.shape, matvec=lambda r: project(amg @ r), dtype=float)
    else:
        M = amg
    residuals: list[float] = []
    x, info = pyamg.krylov.cg(A, b, x0=np.zeros_like(b), tol=rtol, M=M, maxiter=MAX_CG_ITERATIONS,
                              residuals=residuals)
    if info != 0:
        raise RuntimeError(f"CG did not reach rtol {rtol:g} within {MAX_CG_ITERATIONS} iterations (info {info})")
    if floating:
        x = project(x)
    residual = float(np.linalg.norm(b - A @ x) / np.linalg.norm(b))
    u = u_D.copy()
    u[free] = x
    return u, len(residuals) - 1, residual


def _remove_rigid_l2(basis, order: int, modes: np.ndarray, u: np.ndarray) -> np.ndarray:
    """u [N] minus its L2(mesh)-orthogonal projection on the rigid modes [N, m]."""
    import skfem
    from skfem.helpers import dot

    exact = skfem.Basis(basis.mesh, basis.elem, mapping=basis.mapping, intorder=2 * order)  # degree 2p
    MR = skfem.asm(skfem.BilinearForm(lambda a, v, w: dot(a, v)), exact) @ modes  # [N, m]
    return u - modes @ np.linalg.solve(modes.T @ MR, MR.T @ u)


# ----------------------------------------------------------------------------- probes
def reference_coordinates(mapping, x: np.ndarray, cells: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Reference coordinates [d, M] of points x [d, M] in elements ``cells`` [M] of a curved mesh.

    Newton from ``start`` [d, M] (the straight element's answer) without scikit-fem's clipping to
    the reference box, so a point outside its candidate lands outside and is rejected, not clamped.
    """
    X = start[:, :, None].copy()
    for _ in range(20):
        dX = np.einsum("ijkl,jkl->ikl", mapping.invDF(X, cells), x[:, :, None] - mapping.F(X, cells))
        X += dX
        if np.abs(dX).max() < 1e-13:
            break
    return X[:, :, 0]


def _locate(disc: _Discretisation, x: np.ndarray, outside: str, candidates: int = 16
            ) -> tuple[np.ndarray, np.ndarray, int]:
    """Containing element [N] of points x [d, N] [m], their reference coordinates [d, N], and how
    many are in no element (only with outside="nearest"; they take the element they undershoot
    least, i.e. the FE polynomial is extrapolated a little)."""
    from scipy.spatial import cKDTree

    mesh, vm = disc.mesh, disc.vertex_mapping
    curved = not disc.mesh.affine
    d, n = x.shape
    nel = mesh.t.shape[1]
    tree = cKDTree(mesh.p[:, mesh.t].mean(axis=1).T)
    found = np.full(n, -1, dtype=np.int64)
    ref = np.zeros((d, n))
    depth = np.full(n, -np.inf)  # smallest barycentric coordinate in the chosen element
    todo = np.arange(n)
    for k in (candidates, 128):  # the wide pass only for the points the first did not place
        k = min(k, nel)
        _, ix = tree.query(x[:, todo].T, k)
        ix = ix.reshape(len(todo), k)  # [n, k]
        xs = np.repeat(x[:, todo], k, axis=1)  # [d, n * k]
        X = np.einsum("ijm,jm->im", vm.invA[:, :, ix.ravel()], xs - vm.b[:, ix.ravel()])
        lam = np.concatenate([1 - X.sum(axis=0)[None], X], axis=0).min(axis=0)
        if curved:
            # Newton only where the straight element is near: curving moves a boundary element's
            # barycentric coordinates by O(h / R), well below 0.5 at the sizes meshed here
            near = lam > -0.5
            X[:, near] = reference_coordinates(disc.basis.mapping, xs[:, near], ix.ravel()[near], X[:, near])
            lam = np.concatenate([1 - X.sum(axis=0)[None], X], axis=0).min(axis=0)
            lam[~near] = -np.inf
        lam = np.nan_to_num(lam, nan=-np.inf).reshape(len(todo), k)
        best = lam.argmax(axis=1)
        rows = np.arange(len(todo))
        better = lam[rows, best] > depth[todo]
        pick = todo[better]
        found[pick] = ix[rows, best][better]
        depth[pick] = lam[rows, best][better]
        ref[:, pick] = X.reshape(d, len(todo), k)[:, rows, best][:, better]
        todo = todo[depth[todo] < -INSIDE_TOLERANCE]
        if not len(todo):
            break
    if len(todo) and outside != "nearest":
        radii = np.linalg.norm(x[:, todo], axis=0)
        raise ProbeOutsideMesh(
            f"{len(todo)} of {n} probes lie in no element of the mesh: between a chord and the curved "
            f"boundary (at radii {radii.min():.4g} to {radii.max():.4g} m; deepest barycentric undershoot "
            f"{-depth[todo].min():.3g}). Use a finer h, geometry='curved', or outside='nearest'.")
    return found, ref, len(todo)


def _at_probes(disc: _Discretisation, u: np.ndarray, x: np.ndarray, outside: str
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """Displacement [N, d] [m], displacement gradient [N, d, d] (du_i / dx_j) at points x [d, N],
    and the number of points extrapolated (see :func:`_locate`)."""
    basis = disc.basis
    cells, X, extrapolated = _locate(disc, x, outside)
    X = X[:, :, None]  # one point per element
    d, n = x.shape
    val = np.zeros((d, n))
    grad = np.zeros((d, d, n))
    for k in range(basis.Nbfun):
        phi = basis.elem.gbasis(basis.mapping, X, k, tind=cells)[0]
        coef = u[basis.element_dofs[k, cells]]
        val += coef * phi.value[..., 0]
        grad += coef * phi.grad[..., 0]
    return val.T, grad.transpose(2, 0, 1), extrapolated


# ----------------------------------------------------------------------------- driver
def peer_problem(name: str) -> Problem:
    """The problem as the peer solves it (lame: the true radii)."""
    base = problem(name)
    if name == "lame":
        # the peer meshes the true spheres, so its exact solution has the true radii
        return lame_problem(0.5, 1.0, base.pressure, base.youngs_modulus, base.poisson_ratio, base.probes)
    return base


def _import_libraries() -> None:
    """Import before the clock starts: a job in a fresh process would otherwise time its imports."""
    import gmsh  # noqa: F401
    import pyamg  # noqa: F401
    import scipy.spatial  # noqa: F401
    import skfem  # noqa: F401
    import skfem.models.elasticity  # noqa: F401


def run_peer(problem_name: str, order: int, h: float, rtol: float = 1e-10, geometry: str = "straight",
             outside: str = "error") -> dict:
    """Solve one benchmark problem with scikit-fem P``order`` on a gmsh mesh of size h [m].

    Returns the benchmark record: dofs (all vector DOFs, prescribed included; free_dofs without),
    elements, seconds (meshing + assembly + solve + probe evaluation, wall, imports excluded),
    stages {mesh, assembly, solve, probe} [s] (solve includes the AMG setup), CG iterations, final
    relative residual, displacement [1200][d] [m] and von Mises [1200] [Pa] at the probes, their
    relative l2 errors against the exact solution, and "extrapolated" (probes in no element).

    geometry: "straight" simplices, or "curved" (order 2 only): gmsh second-order nodes and
    isoparametric P2, both of the true geometry; or "stl": fTetWild's tetrahedra of the STL voxelastic
    reads (3D; meshing time counted like gmsh's). outside: "error" raises :class:`ProbeOutsideMesh` if a
    probe is in no element, "nearest" extrapolates from the closest one.
    """
    check_arguments(order, geometry, outside)
    prob = peer_problem(problem_name)  # the exact solution and probes are not the peer's work: untimed
    _import_libraries()
    stages: dict[str, float] = {}
    start = t = time.perf_counter()

    disc = _discretise(prob, order, h, geometry)
    stages["mesh"] = time.perf_counter() - t
    t = time.perf_counter()

    K, f, u_D, D = _assemble(prob, disc, order)
    modes = _rigid_modes(disc.basis, _components(disc.basis))
    stages["assembly"] = time.perf_counter() - t
    t = time.perf_counter()

    floating = prob.name == "lame"
    u, iterations, residual = _solve(K, f, u_D, D, modes, prob.dim, rtol, floating)
    if floating:
        u = _remove_rigid_l2(disc.basis, order, modes, u)
    stages["solve"] = time.perf_counter() - t
    t = time.perf_counter()

    disp, grad, extrapolated = _at_probes(disc, u, prob.probes.T.copy(), outside)
    vm = von_mises_at(prob, grad)
    stages["probe"] = time.perf_counter() - t
    seconds = time.perf_counter() - start

    return record(f"scikit-fem P{order}", geometry, prob, problem_name, h, disp, vm, dofs=int(disc.basis.N),
                  free_dofs=int(disc.basis.N - len(D)), elements=int(disc.mesh.t.shape[1]), seconds=seconds,
                  stages=stages, iterations=int(iterations), residual=residual, extrapolated=extrapolated)


def check_arguments(order: int, geometry: str, outside: str) -> None:
    """ValueError unless the peer's order, geometry and outside (see :func:`run_peer`) go together."""
    if order not in (1, 2):
        raise ValueError(f"order: 1 or 2, got {order!r}")
    if geometry not in ("straight", "curved", "stl") or (geometry == "curved" and order != 2):
        raise ValueError(f"geometry: 'straight', 'stl', or 'curved' with order 2; got {geometry!r} with order {order}")
    if outside not in ("error", "nearest"):
        raise ValueError(f"outside: 'error' or 'nearest', got {outside!r}")


def von_mises_at(prob: Problem, grad: np.ndarray) -> np.ndarray:
    """Von Mises stress [N] [Pa] of displacement gradients [N, d, d] (2D: plane strain)."""
    lam, mu = prob.lame
    eps = 0.5 * (grad + grad.transpose(0, 2, 1))
    sigma = 2 * mu * eps + lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(prob.dim)
    return von_mises_of(sigma, lam / (2 * (lam + mu)))


def record(name: str, geometry: str, prob: Problem, problem_name: str, h: float, disp: np.ndarray, vm: np.ndarray,
           **fields) -> dict:
    """A peer's record (see :func:`run_peer`): ``fields``, the probe values and their errors."""
    return {"method": name + {"straight": "", "curved": " isoparametric", "stl": " on the STL"}[geometry],
            "problem": problem_name, "h": h, **fields, "displacement": disp.tolist(), "von_mises": vm.tolist(),
            "error_u": relative_l2(disp, prob.exact(prob.probes)),
            "error_vm": relative_l2(vm, prob.von_mises(prob.probes))}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problem", required=True, choices=["lame", "annulus", "ball"])
    parser.add_argument("--order", type=int, default=1, choices=[1, 2])
    parser.add_argument("--h", type=float, required=True, help="gmsh characteristic length [m]")
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--geometry", default="straight", choices=["straight", "curved", "stl"],
                        help="curved: gmsh second-order nodes, isoparametric P2 (order 2 only)")
    parser.add_argument("--outside", default="error", choices=["error", "nearest"],
                        help="probes in no element: fail, or extrapolate from the nearest element")
    args = parser.parse_args(argv)
    out = run_peer(args.problem, args.order, args.h, args.rtol, args.geometry, args.outside)
    print(json.dumps({k: v for k, v in out.items() if k not in ("displacement", "von_mises")}, indent=1))


if __name__ == "__main__":
    main()
