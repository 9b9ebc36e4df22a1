"""Hex slicing (DG pieces + exact moments) timing and accuracy, one call.

    .venv/bin/python -m benchmarks.slicing_bench [--resolution 32] [--workers N]

``bench_slicing(surface, grid)`` is what ``benchmarks/geometry.py`` calls; run alone this module
slices a ~82k-triangle bumpy icosphere and a 100k-triangle torus at 32 cells along the longest axis.
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np

from engine.geometry.slicing import CutCells, slice_cells
from engine.geometry.surface import Surface
from engine.grid import Grid, make_grid


def closure_error(cut: CutCells) -> float:
    """max over pieces of |sum of outward area vectors| / h^2 (interfaces + boundary): 0 when closed."""
    total = np.zeros((cut.num_pieces, 3))
    vec = np.eye(3)[cut.face_axis] * cut.face_area[:, None]
    np.add.at(total, cut.face_minus, vec)
    np.add.at(total, cut.face_plus, -vec)
    t = cut.boundary_triangles
    np.add.at(total, cut.boundary_piece, 0.5 * np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
    return float(np.abs(total).max() / cut.grid.spacing**2) if cut.num_pieces else 0.0


def bench_slicing(surface: Surface, grid: Grid, *, degree: int = 4, workers: int | None = None) -> dict:
    """Slice once and report seconds (wall and CPU, per stage), peak memory and counts.

    peak_rss_mb is this process's peak so far (ru_maxrss), children_peak_rss_mb the largest worker's.
    """
    stats: dict = {}
    cpu_self = time.process_time()
    cpu_children = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    cut = slice_cells(surface, grid, degree, workers=workers, stats=stats)
    wall = time.perf_counter() - wall
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    exact = surface.enclosed_volume()
    return {
        "triangles": int(len(surface.faces)),
        "grid": list(grid.shape),
        "seconds": wall,
        "stage_seconds": {k: stats[k] for k in ("manifold", "bisect", "moments_and_faces")},
        "workers": stats["workers"],
        "cpu_seconds": time.process_time() - cpu_self
        + (children.ru_utime + children.ru_stime - cpu_children.ru_utime - cpu_children.ru_stime),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "children_peak_rss_mb": children.ru_maxrss / 1024,
        "pieces": cut.num_pieces,
        "full_cells": int(np.count_nonzero(cut.full)),
        "interfaces": cut.num_faces,
        "boundary_triangles": int(len(cut.boundary_triangles)),
        "faces_resolved_2d": stats["faces_resolved_2d"],
        "relative_volume_error": abs(float(cut.volume.sum()) - exact) / exact,
        "closure_error": closure_error(cut),
        "warnings": cut.warnings,
    }


def _meshes() -> dict:
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=6, radius=1.0)
    v = sphere.vertices
    sphere.vertices = v * (1.0 + 0.12 * np.sin(3 * v[:, 0]) * np.sin(4 * v[:, 1]) * np.sin(5 * v[:, 2] + 0.3))[:, None]
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.4, major_sections=250, minor_sections=200)
    return {"bumpy_sphere": sphere, "torus": torus}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args(argv)
    for name, mesh in _meshes().items():
        surface = Surface(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
        grid = make_grid(*surface.bounds, resolution=args.resolution, padding=1)
        print(name, json.dumps(bench_slicing(surface, grid, workers=args.workers), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
