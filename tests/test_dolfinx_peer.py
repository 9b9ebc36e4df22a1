"""The DOLFINx peer (benchmarks/dolfinx_peer.py, benchmarks/dolfinx_job.py) against the scikit-fem peer
on the same gmsh mesh: both solve the same discrete problem (the same elements, quadrature and data),
so they agree to the solvers' tolerance, and both are compared with the exact solution.

Needs the benchmarks extra (gmsh, scikit-fem, pyamg) and, for the solves, DOLFINx in the system
Python (Debian / Ubuntu: ``apt-get install -y --no-install-recommends python3-dolfinx``); skipped
where either is missing (CI installs neither).
"""

import numpy as np
import pytest

pytest.importorskip("gmsh")
pytest.importorskip("skfem")
pytest.importorskip("pyamg")

from benchmarks.dolfinx_job import EDGES, facet_keys  # noqa: E402
from benchmarks.dolfinx_peer import Worker, available, boundary_faces, job_arrays, run_dolfinx  # noqa: E402
from benchmarks.peer import make_mesh, peer_problem, run_peer  # noqa: E402

needs_dolfinx = pytest.mark.skipif(available() is None, reason="the system Python has no DOLFINx "
                                   "(apt-get install -y --no-install-recommends python3-dolfinx)")


def test_boundary_faces_are_the_faces_of_one_tetrahedron():
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])  # sharing the face (1, 2, 3)
    faces = boundary_faces(cells, 5)
    assert len(faces) == 6
    assert facet_keys(np.array([[3, 2, 1]]), 5)[0] not in set(facet_keys(faces, 5))


def test_ten_node_cells_put_each_edge_node_on_its_edge_in_dolfinx_order():
    prob = peer_problem("ball")
    gm = make_mesh(prob, 0.5, "curved")
    job = job_arrays(prob, gm, 2, 1e-10, "error")
    x = job["points"][job["cells"]]  # [E, 10, 3]
    ends = np.array(EDGES)
    mid = 0.5 * (x[:, ends[:, 0]] + x[:, ends[:, 1]])
    length = np.linalg.norm(x[:, ends[:, 1]] - x[:, ends[:, 0]], axis=2)
    # the node of edge (i, j) is its midpoint moved onto the sphere: O(h^2), far below half an edge
    assert np.all(np.linalg.norm(x[:, 4:] - mid, axis=2) < 0.2 * length)
    # the cap's facets hold, the rest carry sigma_exact n: the whole boundary, the divergence form
    assert set(np.unique(job["roles"])) == {1, 2} and job["load"] == "exact"


@pytest.fixture(scope="module")
def worker():
    with Worker() as w:
        yield w


@needs_dolfinx
@pytest.mark.parametrize("name, order, h, geometry", [("lame", 2, 0.4, "curved"), ("ball", 2, 0.4, "curved"),
                                                      ("ball", 1, 0.28, "straight")])
def test_dolfinx_solves_the_scikit_fem_peers_discrete_problem(worker, record_property, name, order, h, geometry):
    ours = run_dolfinx(name, order, h, geometry=geometry, worker=worker)
    theirs = run_peer(name, order, h, geometry=geometry)
    assert (ours["elements"], ours["dofs"], ours["free_dofs"]) == (theirs["elements"], theirs["dofs"],
                                                                   theirs["free_dofs"])
    u, v = np.array(ours["displacement"]), np.array(theirs["displacement"])
    # CG to rtol 1e-10 in both; the loads' quadrature rules differ (Basix's, scikit-fem's) at degree 2p + 2
    assert np.abs(u - v).max() < 1e-5 * np.abs(v).max()
    vm, vm_theirs = np.array(ours["von_mises"]), np.array(theirs["von_mises"])
    assert np.abs(vm - vm_theirs).max() < 1e-4 * np.abs(vm_theirs).max()
    assert theirs["error_u"] / 1.5 < ours["error_u"] < 1.5 * theirs["error_u"]
    # GAMG with the rigid modes: tens of iterations here, to the same relative residual
    record_property("gamg_iterations", ours["iterations"])
    assert 0 < ours["iterations"] < 100 and ours["residual"] < 1e-10
    assert ours["versions"]["dolfinx"] and ours["stages"]["solve"] > 0
