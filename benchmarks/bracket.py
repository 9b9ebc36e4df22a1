"""A realistic part with no closed form (issue 23): an L-bracket with two bolt holes, a hole in its
web and a fillet, bolted down and pushed on its web, solved by voxelastic from its STL and by the
peer meshing that STL (fTetWild, scikit-fem P1 / P2), against references on the STL's own solid and
on the CAD solid.

    .venv/bin/python -m benchmarks.bracket [--quick] [--json out.json]

The part (metres): base [0, 0.1] x [0, 0.06] x [0, 0.01]; web [0, 0.01] x [0, 0.06] x [0, 0.06];
a fillet of radius 6 mm where they meet inside; bolt holes of radius 5 mm through the base at
(0.065, 0.015) and (0.065, 0.045); a hole of radius 8 mm through the web at y = 0.03, z = 0.04.
Built with gmsh's OpenCASCADE kernel; the STL every method reads is gmsh's surface mesh of it at
2 mm (13,568 triangles: fTetWild took 380 s on gmsh's 1 mm surface, 53k triangles). Steel-like E =
2e11 Pa, nu = 0.3. Boundaries, one meaning for all (the surface patch inside each region): u = 0 on
the walls of the two bolt holes (pinned by the bolts); traction (1e6, 0, 0) Pa on the outer face x = 0.

Two references, both P2 solved by PARDISO. The STL's (``error_stl``): straight P2 on gmsh's tetrahedra
inside the STL's own facets at 2 mm, the solid every voxelastic method reads (fTetWild's mesh only
approximates it). The CAD solid's (``error``): isoparametric P2 on gmsh's second-order mesh, on two
meshes (the finer one is the reference, the coarser says how far it is from converged); the STL's
chords are up to 0.1 mm inside the CAD holes, and the two references differ by about 2e-3, the
floor of every method's ``error``. Iterative solves (voxelastic, the STL peer's pyamg CG with the
rigid modes) stop at a relative residual of 1e-8. The error of a run: relative l2 of u at 300
probes inside the part, 1 mm or more from its surface. Seconds are whole-job wall times in a warm
process (voxelastic: `engine.simulate`, geometry cache off, the same job run first in a fresh process
as the cold time; the peer: meshing + assembly + solve + probes, imports excluded, which is also its
cold time: nothing is compiled).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from .parts import Part, error, parser, probes, reference, run_methods, selected

E, NU = 2.0e11, 0.3
TRACTION = (1.0e6, 0.0, 0.0)
BOLTS = ((0.065, 0.015), (0.065, 0.045))
BOLT_RADIUS = 0.005
STL_SIZE = 0.002
PROBES, PROBE_DEPTH = 300, 0.001
STL_REFERENCE_SIZE = 0.002  # [m] interior tetrahedra; at the surface the STL's own 2 mm facets
RTOL = 1e-8  # every iterative solve, voxelastic's and the peer's: far below the errors compared


def _build() -> None:
    """The bracket in the current gmsh model (OpenCASCADE), synchronised."""
    import gmsh

    occ = gmsh.model.occ
    base = occ.addBox(0, 0, 0, 0.1, 0.06, 0.01)
    web = occ.addBox(0, 0, 0, 0.01, 0.06, 0.06)
    solid = occ.fuse([(3, base)], [(3, web)])[0][0][1]
    occ.synchronize()
    # the inner edge where base and web meet: along y at x = z = 0.01
    inner = [tag for _, tag in gmsh.model.getEntitiesInBoundingBox(0.0099, -1, 0.0099, 0.0101, 1, 0.0101, 1)]
    solid = occ.fillet([solid], inner, [0.006])[0][1]
    cutters = [(3, occ.addCylinder(x, y, -0.01, 0, 0, 0.03, BOLT_RADIUS)) for x, y in BOLTS]
    cutters.append((3, occ.addCylinder(-0.01, 0.03, 0.04, 0.03, 0, 0, 0.008)))
    occ.cut([(3, solid)], cutters)
    occ.synchronize()


def _sizes(h: float) -> None:
    import gmsh

    for name, value in (("MeshSizeMin", h), ("MeshSizeMax", h), ("MeshSizeFromCurvature", 0),
                        ("MeshSizeExtendFromBoundary", 0), ("MeshSizeFromPoints", 0)):
        gmsh.option.setNumber(f"Mesh.{name}", value)


def write_stl(path: Path) -> None:
    """gmsh's triangles of the bracket's surface at STL_SIZE: the file a user would export."""
    import gmsh

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        _build()
        _sizes(STL_SIZE)
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.Binary", 1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


# the pushed face's facets only: the load box also cuts 0.1 mm strips off the faces along its edges (and
# the web hole's wall), which clipping would load too, 0.85% more force than the peer's centroid rule
FACING = {"direction": [-1.0, 0.0, 0.0], "max_angle_deg": 30.0}


def _regions() -> tuple[list, list]:
    """(clamp regions, load regions) in the job spec's form. Each bolt hole's wall is held: the
    sphere about the hole's centre through the wall's rims takes the wall and nothing else, so the
    patch ends on the part's own edges, where every method's facets end too (a washer square would
    end inside facets, where clipping and the peer's centroid rule part by O(h))."""
    reach = float(np.hypot(BOLT_RADIUS, 0.005)) * (1 + 1e-9)
    clamps = [{"sphere": {"center": [x, y, 0.005], "radius": reach}} for x, y in BOLTS]
    return clamps, [{"box": [[-1.0, -1.0, -1.0], [1e-4, 1.0, 1.0]]}]


def _cad(h: float) -> None:
    """The CAD solid meshed at size h [m] (the "curved" reference)."""
    _build()
    _sizes(h)


def part() -> Part:
    clamps, loads = _regions()
    return Part(young=E, poisson=NU, clamps=tuple(clamps), load=loads[0], traction=TRACTION, load_facing=FACING,
                cad=_cad, rtol=RTOL)


def main() -> None:
    args = parser(__doc__).parse_args()
    reference_sizes = (0.004, 0.0025) if args.quick else (0.003, 0.002)
    runs = {
        "staggered": [("vox", {"kind": "staggered"}, h) for h in (0.004, 0.002, 0.001, 0.0005)],
        "DG k = 2": [("vox", {"kind": "dg", "degree": 2}, h) for h in (0.01, 0.005, 0.0025)],
        "P1 on the STL": [("peer", 1, h) for h in (0.006, 0.004, 0.0025)],
        "P2 on the STL": [("peer", 2, h) for h in (0.008, 0.005, 0.0035)],
    }
    runs = selected(runs, args)
    out: dict = {"reference_sizes": reference_sizes, "stl_reference_size": STL_REFERENCE_SIZE, "rows": []}
    with tempfile.TemporaryDirectory() as tmp:
        stl = Path(tmp) / "bracket.stl"
        write_stl(stl)
        points = probes(str(stl), PROBES, PROBE_DEPTH).tolist()
        bracket = part()
        cad, out["reference"] = reference(points, bracket, "curved", [(str(stl), h) for h in reference_sizes],
                                          f"reference: isoparametric P2 at h = {reference_sizes[-1]:g}")
        solid, out["stl_reference"] = reference(points, bracket, "facets", [(str(stl), STL_REFERENCE_SIZE)],
                                                f"STL reference: P2 inside its facets at h = {STL_REFERENCE_SIZE:g}")
        out["stl_reference"]["vs_cad"] = error(solid, cad)
        print(f"the STL reference differs from the CAD reference by {out['stl_reference']['vs_cad']:.2e}", flush=True)
        out["rows"] = run_methods(runs, str(stl), points, bracket, {"error": cad, "error_stl": solid})
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
