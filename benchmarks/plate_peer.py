"""The P2 reference of the holed plates (verification.plates): scikit-fem on graded gmsh meshes.

The plate and both loadings are symmetric about x = 0.5 and y = 0.5, so the reference solves the
quarter x >= 0.5, y >= 0.5 of the true geometry (OpenCASCADE box minus cylinder, meshed by gmsh
with second-order tetrahedra: edge nodes on the cylinder) with the mirror conditions u_x = 0 on x = 0.5 and u_y = 0 on
y = 0.5. ``tension``: traction LOAD e_x on x = 1 and u_z = 0 at one vertex (the quarter's one rigid
motion left; the loads have no z part, so it carries no force). ``bending``: x = 1 clamped, pressure
LOAD on z = 0.2. Isoparametric P2 Lagrange (scikit-fem ``ElementVector(ElementTetP2)`` on
``MeshTet2``; straight-sided P2 did not converge in tension, the hole's chords away from the point
setting the load path), stiffness quadrature of order 2, solved directly (pypardiso, MKL PARDISO; SciPy's SuperLU where it is missing).

Mesh: size ``min(h_max, h_min + GRADE * r)``, r [m] the distance from the line x = 0.5, y = 0.65
(the hole's edge on the symmetry plane, through both points), with h_max = H_MAX_OVER_MIN * h_min;
a level halves h_min (and so h_max). The stress at a point on it is the mean over the elements
that hold the point (P2 stress is discontinuous between elements; ``spread`` is their max - min
over |mean|). sigma_xx / LOAD at each case's probe point per level; the value of the finest level is
the reference, converged when it differs from the one before by less than 0.2% (``change``).

Commands (repository root; the benchmarks extra installed)::

    .venv/bin/python -m benchmarks.plate_peer                       # print the study, both cases
    .venv/bin/python -m benchmarks.plate_peer --write               # and store verification/plate_reference.json
    .venv/bin/python -m benchmarks.plate_peer --case bending --h-min 0.004
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from benchmarks.peer import read_gmsh_mesh, reference_coordinates, skfem_mesh
from verification.plates import CENTRE, E, LOAD, NU, PLATES, RADIUS, REFERENCE_FILE, SIZE

GRADE = 0.2  # growth of the element size with the distance from the hole's edge line [m / m]
H_MAX_OVER_MIN = 4.0  # the coarsest elements over the finest
LEVELS = (0.016, 0.008, 0.004)  # h_min [m] of the default study
CONVERGED = 2e-3  # relative change of the last level that counts as converged
TOLERANCE = 1e-9  # barycentric undershoot still counted as inside an element


def quarter_mesh(h_min: float) -> tuple[object, object]:
    """Isoparametric second-order tetrahedra (skfem.MeshTet2: gmsh's edge nodes on the cylinder)
    of the quarter x >= 0.5, y >= 0.5 of the plate, graded from h_min [m] at the line
    x = 0.5, y = CENTRE[1] + RADIUS; and the straight MeshTet1 of its vertices."""
    import gmsh

    L, W, T = SIZE
    cx, cy = CENTRE
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("quarter")
        occ = gmsh.model.occ
        box = occ.addBox(cx, cy, 0.0, L - cx, W - cy, T)
        drill = occ.addCylinder(cx, cy, -T, 0.0, 0.0, 3 * T, RADIUS)
        occ.cut([(3, box)], [(3, drill)])
        occ.synchronize()
        field = gmsh.model.mesh.field
        f = field.add("MathEval")
        r = f"Sqrt((x - {cx})^2 + (y - {cy + RADIUS})^2)"
        field.setString(f, "F", f"Min({H_MAX_OVER_MIN * h_min}, {h_min} + {GRADE} * {r})")
        field.setAsBackgroundMesh(f)
        for option in ("MeshSizeFromPoints", "MeshSizeFromCurvature", "MeshSizeExtendFromBoundary"):
            gmsh.option.setNumber(f"Mesh.{option}", 0)
        return skfem_mesh(read_gmsh_mesh(3, curved=True), 3)
    finally:
        gmsh.finalize()


def _facets_on(mesh, axis: int, at: float) -> np.ndarray:
    """Boundary facets [k] whose vertices all lie on the plane x_axis = at [m]."""
    b = mesh.boundary_facets()
    on = np.all(np.abs(mesh.p[axis, mesh.facets[:, b]] - at) < 1e-9, axis=0)
    return b[on]


def _solve(K, f: np.ndarray, held: np.ndarray) -> np.ndarray:
    """u [N] [m] of K u = f with u = 0 at the ``held`` DOFs (sparse direct)."""
    from scipy.sparse.linalg import spsolve

    try:
        from pypardiso import spsolve as pardiso
    except ImportError:  # no MKL wheel here: SuperLU
        pardiso = spsolve
    free = np.setdiff1d(np.arange(K.shape[0]), held)
    A = K.tocsr()[free][:, free].tocsr()
    u = np.zeros(K.shape[0])
    u[free] = pardiso(A, f[free])
    return u


def _stress_at(basis, linear, u: np.ndarray, point: np.ndarray) -> tuple[float, float, int]:
    """(mean, spread, count) of sigma_xx [Pa] at ``point`` [3] [m] over the (curved) elements that
    hold it; ``linear``: the straight MeshTet1 of the same vertices (the candidates)."""
    corners = linear.p[:, linear.t]  # [3, 4, E]
    A = corners[:, 1:, :] - corners[:, :1, :]  # [3, 3, E]
    rhs = point[:, None] - corners[:, 0, :]  # [3, E]
    near = np.nonzero(np.linalg.norm(rhs, axis=0) < 2 * np.max(np.linalg.norm(A, axis=0), axis=0))[0]
    X = np.linalg.solve(A[:, :, near].transpose(2, 0, 1), rhs[:, near].T[:, :, None])[:, :, 0].T  # [3, n]
    # curving moves a boundary element's barycentric coordinates by O(h / R): Newton where near
    close = np.concatenate([1 - X.sum(axis=0)[None], X]).min(axis=0) > -0.3
    near = near[close]
    X = reference_coordinates(basis.mapping, np.repeat(point[:, None], len(near), axis=1), near, X[:, close])
    inside = np.concatenate([1 - X.sum(axis=0)[None], X]).min(axis=0) > -TOLERANCE
    cells, X = near[inside], X[:, inside][:, :, None]
    if len(cells) == 0:
        raise RuntimeError(f"no element holds {point}")
    grad = np.zeros((3, 3, len(cells)))
    for k in range(basis.Nbfun):
        phi = basis.elem.gbasis(basis.mapping, X, k, tind=cells)[0]
        grad += u[basis.element_dofs[k, cells]] * phi.grad[..., 0]  # d u_i / d x_j
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    values = 2 * mu * grad[0, 0] + lam * np.trace(grad)  # sigma_xx [per element]
    mean = float(values.mean())
    return mean, float((values.max() - values.min()) / abs(mean)), len(values)


def solve_quarter(name: str, h_min: float):
    """The P2 solution of one case on the quarter mesh of level h_min [m]: (basis, the straight
    MeshTet1, u [N] [m])."""
    import skfem
    from skfem.helpers import dot
    from skfem.models.elasticity import linear_elasticity

    mesh, linear = quarter_mesh(h_min)
    # intorder 2: exact on affine elements, and enough for isoparametric P2's optimal rate
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP2()), intorder=2)
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    K = skfem.asm(linear_elasticity(lam, mu), basis)
    comp = np.arange(basis.N) % 3  # node-major vector DOFs (checked below)
    if not np.array_equal(basis.element_dofs[1::3], basis.element_dofs[::3] + 1):
        raise RuntimeError("unexpected scikit-fem vector DOF layout")

    def dofs_on(axis: int, at: float, component: int | None) -> np.ndarray:
        d = basis.get_dofs(facets=_facets_on(mesh, axis, at)).all()
        return d if component is None else d[comp[d] == component]

    held = [dofs_on(0, CENTRE[0], 0), dofs_on(1, CENTRE[1], 1)]  # mirror planes
    load_axis, load_at = (0, SIZE[0]) if name == "tension" else (2, SIZE[2])
    fb = skfem.FacetBasis(mesh, basis.elem, facets=_facets_on(mesh, load_axis, load_at), intorder=4)
    if name == "tension":
        f = skfem.asm(skfem.LinearForm(lambda v, w: LOAD * v[0]), fb)
        corner = int(np.argmin(np.linalg.norm(mesh.p.T - np.array([SIZE[0], SIZE[1], 0.0]), axis=1)))
        held.append(basis.nodal_dofs[2, corner:corner + 1])  # u_z at a vertex
    else:
        f = skfem.asm(skfem.LinearForm(lambda v, w: -LOAD * dot(w.n, v)), fb)
        held.append(dofs_on(0, SIZE[0], None))  # clamp
    return basis, linear, _solve(K, f, np.unique(np.concatenate(held)))


def solve_case(name: str, h_min: float) -> dict:
    """One level: sigma_xx / LOAD at the case's probe point, with the mesh and timing."""
    start = time.perf_counter()
    basis, linear, u = solve_quarter(name, h_min)
    sxx, spread, count = _stress_at(basis, linear, u, np.asarray(PLATES[name].point, dtype=float))
    return {"case": name, "h_min": h_min, "h_max": H_MAX_OVER_MIN * h_min, "elements": int(basis.mesh.t.shape[1]),
            "dofs": int(basis.N), "value": sxx / LOAD, "spread": spread, "elements_at_point": count,
            "seconds": round(time.perf_counter() - start, 1)}


def study(name: str, levels: tuple[float, ...]) -> dict:
    """Every level of one case (printed as JSON lines as they finish) and the converged value."""
    rows = []
    for h_min in levels:
        rows.append(solve_case(name, h_min))
        if len(rows) > 1:
            rows[-1]["change"] = abs(rows[-1]["value"] / rows[-2]["value"] - 1)
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    change = rows[-1].get("change", float("nan"))
    return {"value": rows[-1]["value"], "change": change, "converged": bool(change < CONVERGED), "levels": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.plate_peer", description=__doc__.splitlines()[0])
    ap.add_argument("--case", action="append", choices=list(PLATES), help="only these cases (repeatable)")
    ap.add_argument("--h-min", type=float, action="append", help="h_min levels [m] instead of the default study")
    ap.add_argument("--write", action="store_true", help=f"store the study in {REFERENCE_FILE.name}")
    a = ap.parse_args(argv)
    levels = tuple(a.h_min or LEVELS)
    table = {name: study(name, levels) for name in (a.case or list(PLATES))}
    print(json.dumps(table, indent=1))
    if a.write:
        table["command"] = "python -m benchmarks.plate_peer --write" + "".join(f" --h-min {h}" for h in (a.h_min or []))
        table["quantity"] = "sigma_xx / LOAD at verification.plates.PLATES[case].point (mean over the elements there)"
        REFERENCE_FILE.write_text(json.dumps(table, indent=1) + "\n")
    return 0 if all(t["converged"] for t in table.values() if isinstance(t, dict)) else 1


if __name__ == "__main__":
    raise SystemExit(main())
