"""A scanned model (issue 23): the Stanford bunny, its base held on a table that accelerates sideways,
solved by voxelastic from its STL and by the peer meshing that STL, against P2 on the STL's own solid.

    .venv/bin/python -m benchmarks.scan [--quick] [--json out.json] [--tarball bunny-1.0.1.tgz]

The model: the npm package ``bunny`` 1.0.1 (public domain; the Stanford 3D Scanning Repository's
bunny, decimated and closed by its author: 1,839 vertices, 3,674 triangles, watertight), fetched from
the npm registry on first use into the engine's cache root (``VOXELASTIC_CACHE_DIR``, default
~/.cache/voxelastic; or read from ``--tarball``) and checked
against its published SHA-1, scaled from its units to metres by 0.01: a 9.9 x 9.7 x 7.5 cm solid,
triangles with edges of 1.8-10 mm (mean 3.8 mm). A PLA print of it: E = 3.5e9 Pa, nu = 0.36, 1,240 kg/m^3.
Its base (the facets within 20 degrees of facing down, all below y = 5 mm: no such facet crosses that
plane, so clipping and the peer's centroid rule take the same 268 facets) is held; gravity 9.81 m/s^2
down (-y) and the table's 5 g along x load it. No closed form: the reference is P2 on gmsh's
tetrahedra inside the STL's own triangles (the solid every method reads), on two interior sizes, the
coarser one saying how far it is from converged; DG k = 2 and the peer's P2 on fTetWild's mesh of the
STL should approach it together. The error of a run: relative l2 of u at 300 probes inside the
bunny, 1 mm or more from its surface. Seconds: as in ``benchmarks.bracket`` (warm whole jobs, the
cold one first in a fresh process; the peer's meshing counted).
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import tarfile
import tempfile
import urllib.request
from pathlib import Path

import numpy as np

from .parts import Part, parser, probes, reference, run_methods, selected

TARBALL = "https://registry.npmjs.org/bunny/-/bunny-1.0.1.tgz"
SHA1 = "86383da45ab7a99571a5a572b7be0e3564815f9e"  # the registry's published shasum of that tarball
SCALE = 0.01  # the package's units -> m
PROBES, PROBE_DEPTH = 300, 0.001
# the references, coarser first: (times each STL triangle is split in 4, the same plane; interior size [m]).
# gmsh keeps the STL's triangles as the surface mesh, so an interior size above them changes nothing
# (8 and 6 mm: the same u to 5e-14); the split refines the surface without changing the solid.
REFERENCES = ((0, 0.003), (1, 0.0025))
BUNNY = Part(young=3.5e9, poisson=0.36, density=1240.0, gravity=(5 * 9.81, -9.81, 0.0),
             clamps=({"halfspace": {"point": [0.0, 0.005, 0.0], "normal": [0.0, 1.0, 0.0]}},),
             clamp_facing={"direction": [0.0, -1.0, 0.0], "max_angle_deg": 20.0})


def _tarball(path: Path | None) -> bytes:
    """The package's bytes: from ``path``, else the cache, else the registry (then cached)."""
    if path is None:
        from engine.geometry.cache import cache_root

        path = cache_root() / "bunny-1.0.1.tgz"
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            with urllib.request.urlopen(TARBALL, timeout=60) as response:
                path.write_bytes(response.read())
    data = path.read_bytes()
    if hashlib.sha1(data).hexdigest() != SHA1:
        raise SystemExit(f"{path}: not the bunny 1.0.1 package (SHA-1 {hashlib.sha1(data).hexdigest()}, "
                         f"expected {SHA1})")
    return data


def write_stl(path: Path, tarball: Path | None = None) -> None:
    """The bunny in metres as a binary STL: the file a user would send."""
    import trimesh

    with tarfile.open(fileobj=io.BytesIO(_tarball(tarball))) as tar:
        source = tar.extractfile("package/index.js").read().decode()
    arrays = {name: json.loads(re.search(rf"{name}\s*=\s*(\[.*?\]\])", source, re.S).group(1))
              for name in ("positions", "cells")}
    mesh = trimesh.Trimesh(SCALE * np.asarray(arrays["positions"], dtype=float), np.asarray(arrays["cells"]),
                           process=False)
    mesh.export(path)


def _split(stl: str, times: int, folder: str) -> str:
    """The STL with each triangle split in 4 ``times`` times (midpoints: the same solid, finer facets)."""
    import trimesh

    if times == 0:
        return stl
    mesh = trimesh.load(stl, force="mesh")
    for _ in range(times):
        mesh = mesh.subdivide()
    path = str(Path(folder) / f"split{times}.stl")
    mesh.export(path)
    return path


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--tarball", type=Path, help="the npm package bunny-1.0.1.tgz (default: cache, else registry)")
    args = ap.parse_args()
    runs = selected({
        "staggered": [("vox", {"kind": "staggered"}, h) for h in (0.004, 0.002, 0.0014, 0.001)],
        "DG k = 2": [("vox", {"kind": "dg", "degree": 2}, h) for h in (0.008, 0.005, 0.0035, 0.0025)],
        "P1 on the STL": [("peer", 1, h) for h in (0.006, 0.004, 0.003)],
        "P2 on the STL": [("peer", 2, h) for h in (0.008, 0.005, 0.0035)],
    }, args)
    out: dict = {"references": REFERENCES}
    with tempfile.TemporaryDirectory() as tmp:
        stl = str(Path(tmp) / "bunny.stl")
        write_stl(Path(stl), args.tarball)
        points = probes(stl, PROBES, PROBE_DEPTH).tolist()
        meshes = [(_split(stl, splits, tmp), h) for splits, h in REFERENCES]
        u, out["reference"] = reference(points, BUNNY, "facets", meshes,
                                        f"reference: P2 inside the STL's facets split {REFERENCES[-1][0]} time(s), "
                                        f"interior h = {REFERENCES[-1][1]:g}")
        out["rows"] = run_methods(runs, stl, points, BUNNY, {"error": u})
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
