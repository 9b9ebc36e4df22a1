"""Which inputs each peer can mesh at all (issue 23): the surfaces users bring that are not clean
closed manifolds, given to fTetWild (``pytetwild``), to gmsh meshing the STL as it is, and to
voxelastic, which embeds the surface in its grid.

Usage:
    .venv/bin/python -m benchmarks.wild_inputs [--json out.json] [--timeout 300]

Inputs (built here from trimesh icospheres of radius 1 m, 1,280 facets each, written as binary STL):

- ``closed``: the sphere itself (the control);
- ``open``: the sphere without its facets above z = 0.9 (a hole 0.87 m across);
- ``overlapping``: two closed spheres whose centres are 1 m apart, in one file, not united (the
  surfaces cross each other: self-intersecting);
- ``flipped``: the sphere with every third facet's orientation reversed;
- ``cracked``: the sphere's facets as a soup whose corners are each moved by up to 1e-4 m, so
  that no exact weld closes it (what a careless export leaves);
- ``internal fin``: the sphere with a stray square sheet through its centre (a non-manifold fin).

For each: did the mesher produce a volume mesh (or an error, or nothing within ``--timeout``), its
cells and volume against the solid's (the sphere's; for the overlapping pair, the union of the two
meshes by manifold3d), and its seconds. voxelastic runs the whole job (loads its repairs report,
exact fractions, a clamped static solve at resolution 24) and reports its solid volume and warnings.
Each attempt runs in its own process (a crash or hang takes only that attempt).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from .geometry import run_isolated

RADIUS = 1.0


def _sphere(center=(0.0, 0.0, 0.0)):
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=RADIUS)
    mesh.apply_translation(center)
    return mesh


def make_inputs(folder: Path) -> dict[str, tuple[Path, float]]:
    """name -> (STL path, the volume [m^3] of the solid it means)."""
    import manifold3d
    import trimesh

    sphere = _sphere()
    out = {}

    def write(name: str, vertices, faces, volume: float) -> None:
        path = folder / f"{name.replace(' ', '_')}.stl"
        trimesh.Trimesh(vertices, faces, process=False).export(path)
        out[name] = (path, volume)

    write("closed", sphere.vertices, sphere.faces, sphere.volume)
    keep = sphere.triangles_center[:, 2] < 0.9
    write("open", sphere.vertices, sphere.faces[keep], sphere.volume)
    a, b = _sphere((-0.5, 0, 0)), _sphere((0.5, 0, 0))
    union = manifold3d.Manifold(manifold3d.Mesh(a.vertices.astype(np.float32), a.faces.astype(np.uint32))) + \
        manifold3d.Manifold(manifold3d.Mesh(b.vertices.astype(np.float32), b.faces.astype(np.uint32)))
    both = trimesh.util.concatenate([a, b])
    write("overlapping", both.vertices, both.faces, float(union.volume()))
    faces = sphere.faces.copy()
    faces[::3] = faces[::3, ::-1]
    write("flipped", sphere.vertices, faces, sphere.volume)
    soup = sphere.vertices[sphere.faces].reshape(-1, 3)
    soup = soup + np.random.default_rng(0).uniform(-1e-4, 1e-4, soup.shape)
    write("cracked", soup, np.arange(len(soup)).reshape(-1, 3), sphere.volume)
    fin_v = np.array([[-0.6, -0.6, 0.0], [0.6, -0.6, 0.0], [0.6, 0.6, 0.0], [-0.6, 0.6, 0.0]])
    write("internal fin", np.concatenate([sphere.vertices, fin_v]),
          np.concatenate([sphere.faces, len(sphere.vertices) + np.array([[0, 1, 2], [0, 2, 3]])]), sphere.volume)
    return out


def _tet_volume(points: np.ndarray, tets: np.ndarray) -> float:
    p = points[tets]
    e = p[:, 1:] - p[:, :1]
    return float(np.abs(np.einsum("ij,ij->i", e[:, 0], np.cross(e[:, 1], e[:, 2]))).sum() / 6)


def _ftetwild(path: str, queue) -> None:
    import trimesh

    from .peer import ftetwild

    mesh = trimesh.load(path, process=False)
    t = time.perf_counter()
    points, tets = ftetwild(mesh.vertices, mesh.faces, edge_length_fac=0.1)
    seconds = time.perf_counter() - t
    volume = _tet_volume(points, tets)
    queue.put({"cells": int(len(tets)), "volume": volume, "seconds": seconds})


def _gmsh(path: str, queue) -> None:
    """gmsh with the STL's own triangles as the boundary (no surface remeshing): the merged facets
    are one discrete surface, a volume is bounded by it, then 3D meshing. (Classifying the facets
    into patches and re-parametrising them, as its tutorial t13 does to remesh, failed already on
    the closed sphere: "Invalid exterior boundary mesh for parametrization".)"""
    import gmsh

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        t = time.perf_counter()
        gmsh.merge(path)
        surfaces = [tag for _, tag in gmsh.model.getEntities(2)]
        loop = gmsh.model.geo.addSurfaceLoop(surfaces)
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()
        gmsh.model.mesh.generate(3)
        seconds = time.perf_counter() - t
        tags, coords, _ = gmsh.model.mesh.getNodes()
        points = np.zeros((int(tags.max()) + 1, 3))
        points[tags.astype(np.int64)] = coords.reshape(-1, 3)
        _, nodes = gmsh.model.mesh.getElementsByType(4)
        tets = nodes.astype(np.int64).reshape(-1, 4)
        if not len(tets):
            raise RuntimeError("gmsh made no tetrahedra (and raised no error)")
        queue.put({"cells": int(len(tets)), "volume": _tet_volume(points, tets), "seconds": seconds})
    finally:
        gmsh.finalize()


def _voxelastic(path: str, queue) -> None:
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import run

    spec = {
        "geometry": {"mesh": path},
        "grid": {"resolution": 24},
        "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000},
        "loads": {"gravity": [0, 0, -9.81]},
        "boundaries": [{"kind": "displacement", "name": "base", "region": {"box": [[-3, -3, -3], [3, 3, -0.8]]},
                        "value": [0, 0, 0]}],
        "output": {"fields": ["displacement"], "surface": False},
    }
    t = time.perf_counter()
    result = run(spec, cache=GeometryCache(None))
    seconds = time.perf_counter() - t
    h = result.grid.spacing
    volume = float(np.sum(result.volume_fraction) * h**3)
    queue.put({"cells": int(np.count_nonzero(result.volume_fraction)), "volume": volume, "seconds": seconds,
               "iterations": result.solver.iterations, "warnings": list(result.solver.warnings)})


def _reporting(target, path: str, queue) -> None:
    """target(path, queue), its exception (the mesher's own message) queued as the result."""
    try:
        target(path, queue)
    except Exception as exc:  # noqa: BLE001 - what the tool said is the record
        queue.put({"error": f"{type(exc).__name__}: {exc}"})


def attempt(target, path: Path, timeout: float) -> dict:
    try:
        out = run_isolated(_reporting, target, str(path), timeout=timeout)
    except TimeoutError:
        return {"meshed": False, "why": f"no mesh within {timeout:g} s"}
    except RuntimeError as exc:  # the child died without a word (a crash in native code)
        return {"meshed": False, "why": str(exc)}
    return {"meshed": False, "why": out["error"]} if "error" in out else {"meshed": True, **out}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json")
    ap.add_argument("--timeout", type=float, default=300.0)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, (path, volume) in make_inputs(Path(tmp)).items():
            for tool, target in (("fTetWild", _ftetwild), ("gmsh", _gmsh), ("voxelastic", _voxelastic)):
                r = {"input": name, "tool": tool, "solid_volume": volume, **attempt(target, path, args.timeout)}
                rows.append(r)
                got = (f"{r['cells']} cells, volume {r['volume'] / volume - 1:+.2%}, {r['seconds']:.1f} s"
                       if r["meshed"] else r["why"].splitlines()[0][:120])
                print(f"{name:14s} {tool:10s} {got}", flush=True)
                for w in r.get("warnings", []):
                    print(f"{'':25s} warning: {w[:160]}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
