"""Realistic parts with no closed form (issue 23): voxelastic and the peer on one STL, against
references. A part's own module (``benchmarks.bracket``, ``benchmarks.scan``) describes it as a
:class:`Part` and picks the sizes; this one runs each method on it in a spawned process.

One meaning for every boundary: the surface patch inside its region, optionally only the facets whose
outward normal lies within ``max_angle_deg`` of ``direction`` (the spec's ``facing``). voxelastic
clips facets at the region's boundary; the peer takes its own boundary facets by their centroid, so
a part's regions should end on its own edges (or where ``facing`` already ends the patch), where
both rules take the same surface.

The peer: scikit-fem P1 / P2 on fTetWild's tetrahedra of the STL ("stl", pyamg CG with the rigid
modes), on gmsh's tetrahedra inside the STL's own facets ("facets": the exact solid every
voxelastic method reads, a reference) or on gmsh's isoparametric mesh of the CAD solid where the part
has one ("curved", a reference); references are solved by PARDISO.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .geometry import run_isolated


@dataclass(frozen=True)
class Part:
    """A loaded part. Regions are the job spec's (``box``, ``sphere`` or ``halfspace``); ``cad``
    builds the CAD solid in the current gmsh model with its mesh size h [m] set (None: a scan)."""

    young: float  # [Pa]
    poisson: float
    clamps: tuple[dict, ...]  # regions whose surface patch is held at u = 0
    load: dict | None = None  # the region of the traction's patch
    traction: tuple[float, float, float] = (0.0, 0.0, 0.0)  # [Pa]
    clamp_facing: dict | None = None
    load_facing: dict | None = None
    density: float = 1000.0  # [kg/m^3]
    gravity: tuple[float, float, float] | None = None  # [m/s^2]
    cad: Callable[[float], None] | None = None
    rtol: float = 1e-8  # every iterative solve, voxelastic's and the peer's


def inside(region: dict, x: np.ndarray) -> np.ndarray:
    """Points x [n, 3] [m] in a spec region."""
    if "box" in region:
        lo, hi = region["box"]
        return np.all((x >= lo) & (x <= hi), axis=1)
    if "sphere" in region:
        return np.linalg.norm(x - region["sphere"]["center"], axis=1) <= region["sphere"]["radius"]
    plane = region["halfspace"]
    return (x - plane["point"]) @ np.asarray(plane["normal"], dtype=float) <= 0.0


def facing(rule: dict | None, normals: np.ndarray) -> np.ndarray:
    """Which unit normals [n, 3] lie within the rule's angle of its direction (all without a rule)."""
    if rule is None:
        return np.ones(len(normals), dtype=bool)
    d = np.asarray(rule["direction"], dtype=float)
    return normals @ (d / np.linalg.norm(d)) >= np.cos(np.radians(rule["max_angle_deg"]))


def probes(stl: str, count: int, depth: float, seed: int = 1) -> np.ndarray:
    """``count`` points [m] inside the STL's solid, ``depth`` or more from its surface (a fixed seed)."""
    import trimesh

    mesh = trimesh.load(stl, force="mesh")
    rng = np.random.default_rng(seed)
    found = []
    while sum(len(f) for f in found) < count:
        x = rng.uniform(mesh.bounds[0], mesh.bounds[1], (4000, 3))
        found.append(x[trimesh.proximity.signed_distance(mesh, x) > depth])
    return np.concatenate(found)[:count]


def _facets_as_boundary(stl: str, h: float) -> None:
    """A gmsh volume bounded by the STL's own triangles, meshed inside up to ``h``: the exact solid
    every voxelastic method reads, which fTetWild only approximates (within its envelope). Finer
    facets would refine it at the surface, but with each one split in 4 the bracket's P2 system
    outgrew this machine's 24 GB in PARDISO."""
    import gmsh

    gmsh.merge(stl)
    loop = gmsh.model.geo.addSurfaceLoop([tag for _, tag in gmsh.model.getEntities(2)])
    gmsh.model.geo.addVolume([loop])
    gmsh.model.geo.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", h)


def _boundary_facets(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tetrahedral mesh's boundary facets, their centroids [n, 3] and outward unit normals [n, 3]."""
    facets = mesh.boundary_facets()
    corners = mesh.p[:, mesh.facets[:, facets]].transpose(2, 1, 0)  # [n, 3 corners, 3]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    tet = mesh.t[:, mesh.f2t[0, facets]]  # the one tetrahedron on each boundary facet
    opposite = mesh.p[:, tet].mean(axis=1).T - corners[:, 0]  # towards the solid
    normal *= -np.sign(np.einsum("ij,ij->i", normal, opposite))[:, None]
    return facets, corners.mean(axis=1), normal / np.linalg.norm(normal, axis=1, keepdims=True)


def peer(stl: str, points: list, order: int, h: float, geometry: str, part: Part, queue) -> None:
    """scikit-fem P``order`` on the part meshed by ``geometry`` ("stl", "facets", "curved"; see the
    module); queue: u at the points, seconds (meshing, assembly, solve, probes), DOFs, iterations."""
    import gmsh
    import skfem
    import trimesh
    from skfem.helpers import dot
    from skfem.mapping import MappingAffine
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from .peer import (
        _at_probes,
        _components,
        _Discretisation,
        _GmshMesh,
        _rigid_modes,
        _solve,
        ftetwild,
        read_gmsh_mesh,
        skfem_mesh,
    )

    surface = trimesh.load(stl, force="mesh")
    start = time.perf_counter()
    if geometry == "stl":
        made = _GmshMesh(*ftetwild(surface.vertices, surface.faces, edge_length_abs=h))
    else:
        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            if geometry == "facets":
                _facets_as_boundary(stl, h)
                made = read_gmsh_mesh(3, False)
            else:
                part.cad(h)
                made = read_gmsh_mesh(3, order == 2)
        finally:
            gmsh.finalize()
    mesh, linear = skfem_mesh(made, 3)
    element = skfem.ElementVector(skfem.ElementTetP1() if order == 1 else skfem.ElementTetP2())
    basis = skfem.Basis(mesh, element, intorder=2 * (order - 1))
    facets, centre, normal = _boundary_facets(linear)

    def patch(regions: tuple, rule: dict | None) -> np.ndarray:
        chosen = np.any([inside(r, centre) for r in regions], axis=0) & facing(rule, normal)
        return facets[chosen]

    loaded = patch((part.load,), part.load_facing) if part.load is not None else facets[:0]
    disc = _Discretisation(mesh, basis, MappingAffine(linear), patch(part.clamps, part.clamp_facing), loaded)
    K = skfem.asm(linear_elasticity(*lame_parameters(part.young, part.poisson)), basis)
    f = np.zeros(basis.N)
    if len(loaded):
        t = np.asarray(part.traction)[:, None, None]
        fb = skfem.FacetBasis(mesh, element, facets=loaded, intorder=2 * order)
        f += skfem.asm(skfem.LinearForm(lambda v, w: dot(np.broadcast_to(t, w.x.shape), v)), fb)
    if part.gravity is not None:
        g = part.density * np.asarray(part.gravity)[:, None, None]
        body = skfem.Basis(mesh, element, intorder=order)
        f += skfem.asm(skfem.LinearForm(lambda v, w: dot(np.broadcast_to(g, w.x.shape), v)), body)
    D = basis.get_dofs(facets=disc.dirichlet_facets).all()
    if geometry != "stl":  # the references: a direct solve (pyamg's CG stalled short of 1e-10 on the bracket)
        from pypardiso import spsolve

        free = np.setdiff1d(np.arange(basis.N), D)
        u, iterations = np.zeros(basis.N), 0
        u[free] = spsolve(K.tocsr()[free][:, free].tocsr(), f[free])
    else:
        u, iterations, _ = _solve(K, f, np.zeros(basis.N), D, _rigid_modes(basis, _components(basis)), 3,
                                  part.rtol, False)
    values = _at_probes(disc, u, np.asarray(points).T.copy(), "nearest")[0]
    queue.put({"u": values.tolist(), "seconds": time.perf_counter() - start, "dofs": int(basis.N),
               "iterations": iterations})


def spec(part: Part, stl: str, points: list, method: dict, h: float) -> dict:
    """The voxelastic job of the part: ``method`` at cell size h [m], u at the points."""
    boundaries = [{"kind": "displacement", "name": f"clamp{k}", "region": region, "value": [0, 0, 0]}
                  | ({"facing": part.clamp_facing} if part.clamp_facing else {})
                  for k, region in enumerate(part.clamps)]
    if part.load is not None:
        boundaries.append({"kind": "traction", "name": "load", "region": part.load, "value": list(part.traction)}
                          | ({"facing": part.load_facing} if part.load_facing else {}))
    out = {
        "geometry": {"mesh": stl},
        "grid": {"cell_size": h},
        "method": method,
        "material": {"youngs_modulus": part.young, "poisson_ratio": part.poisson, "density": part.density},
        "boundaries": boundaries,
        "solver": {"rtol": part.rtol},
        "output": {"fields": ["displacement"], "probes": points, "surface": False},
    }
    if part.gravity is not None:
        out["loads"] = {"gravity": list(part.gravity)}
    return out


def voxelastic(stl: str, points: list, method: dict, h: float, part: Part, queue) -> None:
    """One job run twice in a fresh process: the first is cold (Taichi compiles or loads its kernels,
    as in one CLI run; ``seconds_cold``), the second warm (``seconds``, its displacements)."""
    from engine import simulate
    from engine.geometry.cache import GeometryCache

    job = spec(part, stl, points, method, h)
    start = time.perf_counter()
    simulate(job, cache=GeometryCache(None))
    cold = time.perf_counter() - start
    start = time.perf_counter()
    result = simulate(job, cache=GeometryCache(None))
    queue.put({"u": np.asarray(result.fields.probes["displacement"]).tolist(), "seconds_cold": cold,
               "seconds": time.perf_counter() - start, "iterations": result.solver.iterations,
               "warnings": list(result.solver.warnings)})


def error(u: list, reference: list) -> float:
    """Relative l2 difference of displacements at the probes [n, 3]."""
    u, ref = np.asarray(u), np.asarray(reference)
    return float(np.linalg.norm(u - ref) / np.linalg.norm(ref))


def reference(points: list, part: Part, geometry: str, meshes: list[tuple[str, float]], label: str
              ) -> tuple[list, dict]:
    """P2 by PARDISO on the part meshed by ``geometry`` ("facets" or "curved") for each (STL, size [m]),
    coarsest first: u at the points of the last, and its DOFs, seconds and (with two or more) how far
    the one before is from it."""
    refs = [run_isolated(peer, stl, points, 2, h, geometry, part) for stl, h in meshes]
    summary = {"dofs": refs[-1]["dofs"], "seconds": refs[-1]["seconds"]}
    line = f"{label} ({refs[-1]['dofs']} DOFs, {refs[-1]['seconds']:.0f} s)"
    if len(refs) > 1:
        summary["coarser_vs_finer"] = error(refs[-2]["u"], refs[-1]["u"])
        line += f"; the coarser one differs by {summary['coarser_vs_finer']:.2e}"
    print(line, flush=True)
    return refs[-1]["u"], summary


def run_methods(runs: dict[str, list], stl: str, points: list, part: Part, references: dict[str, list]) -> list[dict]:
    """Each method's runs (name -> [("vox", method spec, h) or ("peer", order, h)], the peer on
    fTetWild's mesh of the STL), each in its own process; a row per run with its error against every
    reference (column name -> u at the points), seconds warm and cold, iterations and DOFs."""
    rows = []
    for name, cases in runs.items():
        for kind, what, h in cases:
            if kind == "vox":
                r = run_isolated(voxelastic, stl, points, what, h, part)
            else:
                r = run_isolated(peer, stl, points, what, h, "stl", part)
            row = {"method": name, "h": h, "seconds": r["seconds"], "seconds_cold": r.get("seconds_cold", r["seconds"]),
                   **{column: error(r["u"], u) for column, u in references.items()},
                   "iterations": r.get("iterations"), "dofs": r.get("dofs"), "warnings": r.get("warnings", [])}
            rows.append(row)
            errors = "  ".join(f"{column} {row[column]:.2e}" for column in references)
            print(f"{name:14s} h = {h:<7g} {errors}  {row['seconds']:7.1f} s (cold {row['seconds_cold']:.1f} s)",
                  flush=True)
    return rows


def parser(doc: str) -> argparse.ArgumentParser:
    """The command line every part's benchmark takes (its module docstring as the help)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="the two coarsest sizes per method only (a few minutes)")
    ap.add_argument("--method", action="append", help="run only this method (repeatable), e.g. 'DG k = 2'")
    ap.add_argument("--h", type=float, nargs="*", help="with --method: these sizes [m] instead of its own")
    ap.add_argument("--json")
    return ap


def selected(runs: dict[str, list], args: argparse.Namespace) -> dict[str, list]:
    """The runs that ``--quick`` / ``--method`` / ``--h`` keep."""
    if args.quick:
        runs = {k: v[:2] for k, v in runs.items()}
    if args.method:
        runs = {k: [(kind, what, h) for h in args.h] if args.h else v
                for k, v in runs.items() for kind, what, _ in v[:1] if k in args.method}
    return runs
