"""Hex slicing (DG pieces + exact moments): timing and accuracy of one call.

``bench_slicing(surface, grid)`` is what ``python -m benchmarks.geometry`` runs for the slicing floor.
"""

from __future__ import annotations

import resource
import time

import numpy as np

from engine.geometry.slicing import slice_cells
from engine.geometry.surface import Surface
from engine.grid import Grid


def bench_slicing(surface: Surface, grid: Grid, *, degree: int = 4, workers: int | None = None) -> dict:
    """Slice once and report seconds (wall and CPU, per stage), peak memory and counts.

    stage_seconds: "manifold" (starting the workers, building the solid), "bisect" (cutting and
    integrating the pieces, in the workers), "moments_and_faces" (ordering, interface pairing).
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
        "parts_moved": stats["parts_moved"],
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
        "closure_error": cut.closure_error(),
        "warnings": cut.warnings,
    }
