"""The DOLFINx side of the accuracy benchmark's DOLFINx peer (``benchmarks.dolfinx_peer``).

Run by the interpreter that has DOLFINx (Debian's ``/usr/bin/python3`` with ``python3-dolfinx``
0.5.2, PETSc / petsc4py 3.18), never by the project's virtual environment, which only starts it::

    /usr/bin/python3 benchmarks/dolfinx_job.py

It imports DOLFINx, petsc4py, UFL and Basix, writes one line ``{"ready": {versions}}`` on its stdout
and then solves one job per line ``{"job": "in.npz", "out": "out.npz"}`` read from stdin, answering
each with ``{"done": {...}}`` or ``{"error": "..."}``, until stdin closes: a second job in the same
process is the *warm* one (forms already compiled by FFCx). Anything the libraries print goes to
stderr. The job file holds the meshed problem as arrays (written by ``dolfinx_peer.job_arrays``):

- ``points`` [n, 3] [m] and ``cells`` [E, 4 | 10] in DOLFINx's node order (10 nodes: a degree-2
  coordinate element, the curved tetrahedra);
- ``order`` (P1 / P2 displacement), ``facets`` [F, 3] (vertex indices into ``points``) with
  ``roles`` [F] (``DIRICHLET``: u = exact; ``LOAD``: the traction), ``probes`` [P, 3] [m], ``lame``
  (lambda, mu) [Pa], ``rtol``, ``outside`` ("error" | "nearest"), ``problem`` (its name);
- ``load``: ``"pressure"`` (a pressure ``pressure`` [Pa] on the LOAD facets, -p n with n the mesh's
  outward normal; ``floating``: nothing held, so the 6 rigid modes are the null space) or
  ``"exact"`` (body force and traction sigma_exact n of an exact solution: see :func:`_load`).

The job: ``dolfinx.mesh.create_mesh`` from the arrays, the boundary facets tagged from ``roles``,
vector Lagrange P``order``, stiffness with quadrature degree 2 (order - 1) and loads with
2 order + 2 (what ``benchmarks.peer`` integrates with), PETSc CG preconditioned by GAMG with the
rigid-body modes as near-null space (``Mat.setNearNullSpace``; the smoother options of DOLFINx's
elasticity demo), stopped at ||b - A x||_2 < rtol ||b||_2 (the unpreconditioned norm, pyamg's
criterion in the scikit-fem peer; b here keeps the Dirichlet rows, which DOLFINx sets to identity
rows), then displacement and its gradient at the probes in the element holding each.
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from pathlib import Path

import numpy as np

DIRICHLET, LOAD = 1, 2
# the edges of basix's reference tetrahedron: the order of a 10-node cell's edge nodes
EDGES = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))
MAX_ITERATIONS = 5000  # as benchmarks.peer
INSIDE_TOLERANCE = 1e-10  # as benchmarks.peer: barycentric undershoot still counted as inside
GAMG_OPTIONS = {  # DOLFINx's elasticity demo (0.5): Chebyshev / Jacobi smoothing, CG eigenvalue estimates
    "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi",
    "mg_levels_esteig_ksp_type": "cg", "mg_levels_ksp_chebyshev_esteig_steps": 20,
}


def versions() -> dict:
    """Import the libraries (the cold part of a first job) and say which they are."""
    import basix
    import dolfinx
    import dolfinx.fem.petsc  # noqa: F401
    import ufl
    from petsc4py import PETSc

    return {"dolfinx": dolfinx.__version__, "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
            "ufl": ufl.__version__, "basix": basix.__version__, "numpy": np.__version__,
            "python": sys.version.split()[0]}


# ----------------------------------------------------------------------------- mesh
def _mesh(points: np.ndarray, cells: np.ndarray, facets: np.ndarray, roles: np.ndarray):
    """The DOLFINx mesh and its boundary facets tagged DIRICHLET / LOAD (matched by their input
    vertices: create_mesh reorders cells and nodes)."""
    import dolfinx
    import ufl
    from mpi4py import MPI

    degree = 2 if cells.shape[1] == 10 else 1
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, degree))
    mesh = dolfinx.mesh.create_mesh(MPI.COMM_SELF, cells, points, domain)
    topology = mesh.topology
    topology.create_connectivity(2, 3)
    topology.create_connectivity(2, 0)
    boundary = dolfinx.mesh.exterior_facet_indices(topology)
    vertices = topology.connectivity(2, 0).array.reshape(-1, 3)[boundary]  # local vertex numbers
    n_vertices = topology.index_map(0).size_local
    node = dolfinx.cpp.mesh.entities_to_geometry(mesh._mesh, 0, np.arange(n_vertices, dtype=np.int32), False)[:, 0]
    ours = facet_keys(np.asarray(mesh.geometry.input_global_indices)[node][vertices], len(points))
    theirs = facet_keys(facets, len(points))
    order = np.argsort(theirs)
    where = order[np.searchsorted(theirs[order], ours).clip(0, len(order) - 1)]
    if len(theirs) != len(ours) or not np.array_equal(theirs[where], ours):
        raise RuntimeError("the job's boundary facets are not the mesh's")
    at = np.argsort(boundary)
    tags = dolfinx.mesh.meshtags(mesh, 2, boundary[at].astype(np.int32), roles[where][at].astype(np.int32))
    return mesh, tags


def facet_keys(triples: np.ndarray, n: int) -> np.ndarray:
    """One int64 per facet from its three vertex indices (< n), whatever their order."""
    if n >= 2**21:
        raise ValueError(f"{n} points: facet keys would overflow int64")
    t = np.sort(np.asarray(triples, dtype=np.int64), axis=1)
    return (t[:, 0] * n + t[:, 1]) * n + t[:, 2]


# ----------------------------------------------------------------------------- assembly
def _cell_points(mesh, reference: np.ndarray) -> np.ndarray:
    """Physical points [cells, Q, 3] of reference points [Q, 3] in every cell."""
    import basix

    degree = mesh.geometry.cmap.degree
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.tetrahedron, degree,
                                   basix.LagrangeVariant.gll_warped)
    shape = element.tabulate(0, reference)[0, :, :, 0]  # [Q, nodes]
    nodes = mesh.geometry.x[mesh.geometry.dofmap.array.reshape(-1, shape.shape[1])]  # [cells, nodes, 3]
    return np.einsum("qk,ckj->cqj", shape, nodes)


def _load(mesh, tags, job: dict, v, degree: int):
    """The right-hand side form.

    ``pressure``: -p n on the LOAD facets. ``exact``: the problem's body force f = -div sigma_exact
    plus sigma_exact n on the LOAD facets, where the LOAD and DIRICHLET facets are the whole
    boundary (``dolfinx_peer`` checks it). Every test function of a free DOF vanishes on the
    DIRICHLET facets, so by the divergence theorem on each (curved) element the two are exactly
    int sigma_exact : grad v dx: sigma_exact at the cells' quadrature points (a Quadrature element)
    is all it needs, where DOLFINx 0.5 has no quadrature-point data on facets. The Dirichlet rows
    are set by the boundary condition, so their entries do not matter.
    """
    import basix
    import dolfinx
    import ufl

    if job["load"] == "pressure":
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags, metadata={"quadrature_degree": degree})
        return -float(job["pressure"]) * ufl.inner(ufl.FacetNormal(mesh), v) * ds(LOAD)
    from verification.problems import problem

    element = ufl.VectorElement("Quadrature", mesh.ufl_cell(), degree, dim=9, quad_scheme="default")
    space = dolfinx.fem.FunctionSpace(mesh, element)
    reference, _ = basix.make_quadrature(basix.QuadratureType.Default, basix.CellType.tetrahedron, degree)
    x = _cell_points(mesh, reference)  # [cells, Q, 3]
    sigma = dolfinx.fem.Function(space)
    dofs = space.dofmap.list.array.reshape(x.shape[0], x.shape[1])  # the points of a cell in rule order
    sigma.x.array.reshape(-1, 9)[dofs] = problem(job["problem"]).stress(x.reshape(-1, 3)).reshape(x.shape[:2] + (9,))
    dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": degree})
    return ufl.inner(ufl.as_matrix([[sigma[3 * i + j] for j in range(3)] for i in range(3)]), ufl.grad(v)) * dx


def _rigid_modes(V) -> np.ndarray:
    """Rigid modes [N, 6] at the DOFs (block size 3, DOF = 3 node + component): translations, then
    rotations about the centroid of the nodes."""
    x = V.tabulate_dof_coordinates()
    x = x - x.mean(axis=0)
    modes = np.zeros((3 * len(x), 6))
    for k in range(3):
        modes[k::3, k] = 1.0
        rotation = np.cross(np.eye(3)[k], x)  # e_k cross x
        for c in range(3):
            modes[c::3, 3 + k] = rotation[:, c]
    return modes


def _petsc_vectors(A, columns: np.ndarray) -> list:
    vectors = []
    for column in columns.T:
        vec = A.createVecRight()
        vec.array[:] = column
        vectors.append(vec)
    return vectors


# ----------------------------------------------------------------------------- solve
def _solve(A, b, modes: np.ndarray, rtol: float, floating: bool) -> tuple[np.ndarray, int, float]:
    """x [N], CG iterations and the final ||b - A x|| / ||b||."""
    from petsc4py import PETSc

    q, _ = np.linalg.qr(modes)  # orthonormal (Euclidean): a null space wants it, GAMG does not mind
    space = PETSc.NullSpace().create(vectors=_petsc_vectors(A, q))
    A.setNearNullSpace(space)
    options = PETSc.Options()
    prefix = "voxelastic_peer_"
    for key, value in {**GAMG_OPTIONS, **({"mg_coarse_pc_type": "svd"} if floating else {})}.items():
        options[prefix + key] = value  # floating: the coarsest level is singular, pseudo-inverse as pyamg's
    if floating:
        A.setNullSpace(space)  # CG keeps every iterate orthogonal to the rigid modes
        space.remove(b)  # range(A): the pressure balances, so this only removes round-off
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setType("cg")
    ksp.getPC().setType("gamg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=rtol, atol=0.0, max_it=MAX_ITERATIONS)
    ksp.setFromOptions()
    x = A.createVecRight()
    ksp.solve(b, x)
    if ksp.getConvergedReason() <= 0:
        raise RuntimeError(f"CG did not reach rtol {rtol:g} (PETSc reason {ksp.getConvergedReason()}, "
                           f"{ksp.getIterationNumber()} iterations)")
    if floating:
        space.remove(x)
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    for key in list(options.getAll()):
        if key.startswith(prefix):
            options.delValue(key)
    return x.array.copy(), ksp.getIterationNumber(), r.norm() / b.norm()


def _remove_rigid_l2(V, modes: np.ndarray, u: np.ndarray, degree: int) -> np.ndarray:
    """u [N] minus its L2(mesh)-orthogonal projection on the rigid modes [N, 6] (as benchmarks.peer)."""
    import dolfinx
    import dolfinx.fem.petsc
    import ufl

    w, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    mass = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(
        ufl.inner(w, v) * ufl.dx(metadata={"quadrature_degree": degree})))
    mass.assemble()
    MR = np.empty_like(modes)
    for k, vec in enumerate(_petsc_vectors(mass, modes)):
        out = mass.createVecLeft()
        mass.mult(vec, out)
        MR[:, k] = out.array
    return u - modes @ np.linalg.solve(modes.T @ MR, MR.T @ u)


# ----------------------------------------------------------------------------- probes
def _locate(mesh, probes: np.ndarray, outside: str) -> tuple[np.ndarray, np.ndarray, int]:
    """Cell [P] and reference coordinates [P, 3] of each probe: of the cells whose bounding box holds
    it, the one it undershoots least (barycentric); and how many are in no cell (an error unless
    ``outside`` is "nearest"). Curved cells: Newton (``pull_back``) from the straight cell's answer,
    only where that is near (as ``benchmarks.peer``)."""
    import dolfinx.geometry

    dofmap = mesh.geometry.dofmap.array.reshape(len(mesh.geometry.dofmap), -1)
    padding = 0.0
    if dofmap.shape[1] == 10:  # the boxes hold the vertices: pad by what the edge nodes bulge, times
        # max sum of the P2 edge functions (1.5), which is the most the cell leaves its straight one
        x = mesh.geometry.x[dofmap]
        bulge = x[:, 4:] - 0.5 * (x[:, [e[0] for e in EDGES]] + x[:, [e[1] for e in EDGES]])
        padding = 1.5 * float(np.linalg.norm(bulge, axis=2).max())
    tree = dolfinx.geometry.BoundingBoxTree(mesh, 3, padding=padding)
    candidates = dolfinx.geometry.compute_collisions(tree, probes)
    probe = np.repeat(np.arange(len(probes)), np.diff(candidates.offsets))
    cell = candidates.array
    nodes = mesh.geometry.x[dofmap[cell]]  # [pairs, nodes, 3]
    edges = nodes[:, 1:4] - nodes[:, :1]  # the straight cell's vertices
    X = np.linalg.solve(edges.transpose(0, 2, 1), (probes[probe] - nodes[:, 0])[..., None])[..., 0]
    if mesh.geometry.cmap.degree > 1:
        for k in np.flatnonzero(_depth(X) > -0.5):
            try:
                X[k] = mesh.geometry.cmap.pull_back(probes[probe[k]][None, :], nodes[k])[0]
            except RuntimeError:  # Newton failed: the point is not in this cell
                X[k] = -1.0
    depth = _depth(X)
    best = np.full(len(probes), -1)
    for k in np.argsort(depth):  # the deepest pair of each probe last
        best[probe[k]] = k
    if np.any(best < 0):
        raise RuntimeError(f"{int(np.sum(best < 0))} probes are in no cell's bounding box")
    missing = int(np.sum(depth[best] < -INSIDE_TOLERANCE))
    if missing and outside != "nearest":
        raise RuntimeError(f"{missing} of {len(probes)} probes lie in no element of the mesh")
    return cell[best], X[best], missing


def _depth(X: np.ndarray) -> np.ndarray:
    """Smallest barycentric coordinate [M] of reference points X [M, 3]."""
    return np.minimum(1.0 - X.sum(axis=1), X.min(axis=1))


def _at_probes(mesh, V, u: np.ndarray, cells: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displacement [P, 3] and its gradient [P, 3, 3] (du_i / dx_j) at the probes."""
    import basix

    def element(degree):
        return basix.create_element(basix.ElementFamily.P, basix.CellType.tetrahedron, degree,
                                    basix.LagrangeVariant.gll_warped)

    phi = element(V.ufl_element().degree()).tabulate(1, reference)[..., 0]  # [4, P, dofs]
    shape = element(mesh.geometry.cmap.degree).tabulate(1, reference)[1:, ..., 0]  # [3, P, nodes]
    nodes = mesh.geometry.x[mesh.geometry.dofmap.array.reshape(-1, shape.shape[2])][cells]  # [P, nodes, 3]
    jacobian = np.einsum("apk,pkj->pja", shape, nodes)  # dx_j / dX_a
    dofs = V.dofmap.list.array.reshape(-1, phi.shape[2])[cells]  # [P, dofs] blocks of 3
    coef = u.reshape(-1, 3)[dofs]  # [P, dofs, 3]
    value = np.einsum("pk,pki->pi", phi[0], coef)
    grad_ref = np.einsum("apk,pki->pia", phi[1:], coef)  # du_i / dX_a
    return value, np.einsum("pia,paj->pij", grad_ref, np.linalg.inv(jacobian))


# ----------------------------------------------------------------------------- the job
def solve(job: dict) -> dict:
    """Solve one job (the arrays of the module docstring); the timed stages [s] of what a DOLFINx
    user would run: mesh (create_mesh, facet tags), assembly (forms compiled by FFCx on a first
    job, Dirichlet values, matrix, right-hand side), solve (GAMG setup, CG, rigid modes removed),
    probe (locating the probes, displacement and gradient)."""
    import dolfinx
    import dolfinx.fem.petsc
    import ufl
    from petsc4py import PETSc

    order = int(job["order"])
    lam, mu = (float(c) for c in job["lame"])
    floating = bool(job["floating"])
    stages = {}
    t = time.perf_counter()

    mesh, tags = _mesh(job["points"], job["cells"], job["facets"], job["roles"])
    stages["mesh"] = time.perf_counter() - t
    t = time.perf_counter()

    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", order))
    w, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = ufl.sym(ufl.grad(w))
    stiffness = dolfinx.fem.form(
        ufl.inner(2 * mu * eps + lam * ufl.tr(eps) * ufl.Identity(3), ufl.sym(ufl.grad(v)))
        * ufl.dx(metadata={"quadrature_degree": 2 * (order - 1)}))
    rhs = dolfinx.fem.form(_load(mesh, tags, job, v, 2 * order + 2))
    bcs = []
    held = tags.indices[tags.values == DIRICHLET]
    if len(held):
        from verification.problems import problem

        exact = problem(job["problem"]).exact
        u_D = dolfinx.fem.Function(V)
        u_D.interpolate(lambda x: exact(x.T).T)  # at the DOFs' points, as the scikit-fem peer
        bcs = [dolfinx.fem.dirichletbc(u_D, dolfinx.fem.locate_dofs_topological(V, 2, held))]
    A = dolfinx.fem.petsc.assemble_matrix(stiffness, bcs=bcs)
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(rhs)
    dolfinx.fem.petsc.apply_lifting(b, [stiffness], [bcs])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, bcs)
    modes = _rigid_modes(V)
    stages["assembly"] = time.perf_counter() - t
    t = time.perf_counter()

    u, iterations, residual = _solve(A, b, modes, float(job["rtol"]), floating)
    if floating:
        u = _remove_rigid_l2(V, modes, u, 2 * order)
    stages["solve"] = time.perf_counter() - t
    t = time.perf_counter()

    cells, reference, extrapolated = _locate(mesh, np.asarray(job["probes"], dtype=np.float64), str(job["outside"]))
    displacement, gradient = _at_probes(mesh, V, u, cells, reference)
    stages["probe"] = time.perf_counter() - t

    from benchmarks.memory import peak_rss_bytes

    dofs = 3 * V.dofmap.index_map.size_local
    return {"stages": stages, "worker_peak_rss_gib": peak_rss_bytes() / 2**30, "dofs": dofs, "free_dofs": dofs - sum(len(bc.dof_indices()[0]) for bc in bcs),
            "elements": int(mesh.topology.index_map(3).size_local), "iterations": int(iterations),
            "residual": float(residual), "extrapolated": extrapolated,
            "displacement": displacement, "gradient": gradient}


def serve(requests, reply) -> None:
    """The worker loop of the module docstring: one JSON line in, one out, per job."""
    reply.write(json.dumps({"ready": versions()}) + "\n")
    reply.flush()
    for line in requests:
        if not line.strip():
            continue
        request = json.loads(line)
        try:
            with np.load(request["job"], allow_pickle=False) as data:
                job = {k: (data[k].item() if data[k].ndim == 0 else data[k]) for k in data.files}
            out = solve(job)
            arrays = {k: out.pop(k) for k in ("displacement", "gradient")}
            np.savez(request["out"], **arrays)
            answer = {"done": out}
        except Exception as exc:  # a failed job is an answer; the worker stays up for the next
            traceback.print_exc(file=sys.stderr)
            answer = {"error": f"{type(exc).__name__}: {exc}"}
        reply.write(json.dumps(answer) + "\n")
        reply.flush()


def main() -> None:
    import logging

    logging.disable(logging.INFO)  # FFCx's compiler lines on a first job
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # verification.problems (numpy only)
    reply = os.fdopen(os.dup(1), "w")  # the protocol keeps the real stdout ...
    os.dup2(2, 1)  # ... and whatever the libraries print goes to stderr
    sys.stdout = sys.stderr
    serve(sys.stdin, reply)


if __name__ == "__main__":
    main()
