"""Hex slicing for the DG method: the solid cut by the grid planes into per-cell pieces.

``slice_cells(surface, grid)`` cuts the closed surface with manifold3d by recursive bisection
along grid planes (a region whose volume equals its box is emitted as full cells without further
cuts), splits every cell's part into connected pieces, and computes exact polynomial moments of
each piece, of each interface (connected part of a grid face shared by two pieces) and the
surface triangles bounding each piece (for Nitsche conditions and loads).

Grid-plane faces of a piece are recognised geometrically (all vertices on the cell's plane
``x_a = origin_a + h i`` to 1e-9 h, normal pointing out of the cell). Whether such a face is an
interface or surface is decided by the neighbouring cell: where the neighbour's piece has the
same region with the opposite normal (equal area moments) it is an interface; where it does not
(a surface of the mesh lying in a grid plane, e.g. a box aligned with the grid) the regions are
intersected and differenced in 2D (shapely) and the remainder becomes surface.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import manifold3d
import numpy as np
import shapely
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import GeometryError
from ..grid import Grid
from .moments import (
    area_terms,
    cell_face_moments,
    cell_moments,
    monomial_exponents,
    shift_moments,
    triangle_integrals,
)
from .surface import Surface
from .winding import winding_number

_PLANE_TOL = 1e-9  # [h] a vertex within this of a grid plane lies on it
_FULL_TOL = 1e-12  # relative: a region whose volume matches its box this well is full
_MATCH_TOL = 1e-9  # [h^2 units] area moments of the two sides of an interface must agree this well
_SLIVER = 1e-12  # [h^2] 2D remainders smaller than this are round-off, not surface


@dataclass
class CutCells:
    """The DG elements: connected pieces of (grid cell ∩ solid), sparse over touched cells.

    Moments use xi = (x - c)/h with c the centre of the piece's cell and h the grid spacing:
    ``moments[p, i] = int_piece xi^alpha_i dV / h^3`` with alpha = ``exponents[i]``
    (``monomial_exponents(3, degree)``). Full cells carry ``cell_moments(degree)``.

    Interfaces (interior DG faces) f: ``face_minus[f]`` / ``face_plus[f]`` are the pieces on the
    low / high side along ``face_axis[f]``; the face normal is +e_axis (minus -> plus).
    ``face_moments[f, i] = int_f xi^alpha_i dA / h^2`` about the centre of the *minus* piece's
    cell (so xi_axis = +1/2 on the face); re-centre for the plus side with
    ``moments.shift_moments(face_moments, degree, e_axis)``.

    Boundary: ``boundary_triangles[t]`` [3, 3] (absolute coordinates [m], outward normal by the
    right-hand rule) is a piece of the mesh surface bounding piece ``boundary_piece[t]``
    (sorted by piece). Grid-plane faces of a piece are never boundary unless the surface itself
    lies in the grid plane there.
    """

    grid: Grid
    degree: int
    exponents: np.ndarray
    piece_cell: np.ndarray
    full: np.ndarray
    volume: np.ndarray
    moments: np.ndarray
    face_minus: np.ndarray
    face_plus: np.ndarray
    face_axis: np.ndarray
    face_area: np.ndarray
    face_moments: np.ndarray
    boundary_piece: np.ndarray
    boundary_triangles: np.ndarray
    warnings: list[str] = field(default_factory=list)

    @property
    def num_pieces(self) -> int:
        return int(self.piece_cell.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.face_axis.shape[0])

    def piece_centers(self) -> np.ndarray:
        """Centres [P, 3] [m] of the pieces' cells: the origin of each piece's xi coordinates."""
        return self.grid.sample_points(self.piece_cell)

    def closure_error(self) -> float:
        """max over pieces of |sum of outward area vectors| / h^2 (interfaces + boundary): 0 for
        closed pieces; a check that no face went missing or was counted twice."""
        if self.num_pieces == 0:
            return 0.0
        total = np.zeros((self.num_pieces, 3))
        vec = np.eye(3)[self.face_axis] * self.face_area[:, None]
        np.add.at(total, self.face_minus, vec)
        np.add.at(total, self.face_plus, -vec)
        t = self.boundary_triangles
        np.add.at(total, self.boundary_piece, 0.5 * np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
        return float(np.abs(total).max() / self.grid.spacing**2)


@dataclass
class _Pieces:
    """Raw slicing output before moments and faces."""

    full_boxes: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # [lo, hi) all-solid ranges
    cells: list[tuple[int, int, int]] = field(default_factory=list)  # one per cut piece
    meshes: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (vertices [m,3], triangles [k,3])
    dropped: int = 0  # sliver pieces below min_fraction
    dropped_volume: float = 0.0  # [m^3]

    def extend(self, other: _Pieces) -> None:
        self.full_boxes += other.full_boxes
        self.cells += other.cells
        self.meshes += other.meshes
        self.dropped += other.dropped
        self.dropped_volume += other.dropped_volume


def slice_cells(surface: Surface, grid: Grid, degree: int = 4, *, min_fraction: float = 1e-12,
                workers: int | None = None, stats: dict | None = None) -> CutCells:
    """Slice the closed surface by the grid into DG pieces with exact moments up to ``degree``.

    min_fraction: pieces smaller than this fraction of h^3 are round-off slivers and dropped (with
    a warning). workers: worker processes for the bisection (each on its own CPU); None picks 1
    for small jobs and up to 4 (the CPUs available) where the estimated bisection time exceeds
    ~2 s; if workers cannot start, the bisection runs here. stats, if given, receives seconds per
    stage ("manifold", "bisect", "moments_and_faces"), the worker count ("workers") and the number
    of grid faces that needed 2D booleans because a surface lies in them ("faces_resolved_2d").
    Raises GeometryError for a 2D, open, non-manifold or inside-out surface.
    """
    if not isinstance(degree, (int, np.integer)) or degree < 0:
        raise GeometryError(f"slice_cells: degree must be an integer >= 0, got {degree!r}")
    if grid.dim != 3:
        raise GeometryError(f"slice_cells: hex slicing needs a 3D grid, got a {grid.dim}D grid")
    clock = time.perf_counter()
    solid, warnings = _make_manifold(surface, grid)
    stamp = time.perf_counter()
    # Workers boot while the parent cuts the top levels of the tree.
    procs = _start_workers(_auto_workers(surface, grid) if workers is None else workers)
    try:
        raw = _bisect(solid, grid, min_fraction, procs)
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()
    if raw.dropped:
        warnings.append(f"dropped {raw.dropped} sliver pieces below {min_fraction:g} h^3 "
                        f"(total {raw.dropped_volume:.3g} m^3)")
    stats = {} if stats is None else stats
    stats["manifold"] = stamp - clock
    stats["bisect"] = time.perf_counter() - stamp
    stats["workers"] = max(len(procs), 1)
    stamp = time.perf_counter()
    cut = _assemble(raw, grid, int(degree), warnings, stats)
    stats["moments_and_faces"] = time.perf_counter() - stamp
    return cut


def _make_manifold(surface: Surface, grid: Grid) -> tuple[manifold3d.Manifold, list[str]]:
    """The solid as a manifold3d object (f64), trimmed to the grid box; GeometryError if invalid."""
    vertices = np.array(surface.vertices, dtype=np.float64, order="C")  # writable copy: nanobind rejects read-only
    faces = np.asarray(surface.faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise GeometryError(
            f"slice_cells: needs a 3D triangle surface, got vertices {vertices.shape} and faces {faces.shape}")
    if faces.shape[0] == 0:
        raise GeometryError("slice_cells: the surface has no triangles")
    if not np.issubdtype(faces.dtype, np.integer) or faces.min() < 0 or faces.max() >= len(vertices):
        raise GeometryError(f"slice_cells: face vertex indices must be integers in [0, {len(vertices)})")
    if not np.all(np.isfinite(vertices)):
        raise GeometryError("slice_cells: the surface has non-finite vertex coordinates")
    if not surface.closed:
        raise GeometryError("slice_cells: the surface is not closed; hex slicing needs a watertight mesh")
    solid = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=vertices,
                                                  tri_verts=np.array(faces, dtype=np.uint64, order="C")))
    status = solid.status()
    if status != manifold3d.Error.NoError:
        raise GeometryError(f"slice_cells: the surface is not an oriented 2-manifold (manifold3d: {status.name})")
    volume = solid.volume()
    if not volume > 0:
        raise GeometryError(f"slice_cells: the surface encloses no volume ({volume:.3g}); is it inside out?")
    warnings: list[str] = []
    bounds = np.array(solid.bounding_box())
    lower, upper = np.asarray(grid.origin, dtype=float), grid.upper
    if np.any(bounds[:3] < lower) or np.any(bounds[3:] > upper):
        for a in range(3):
            normal = np.zeros(3)
            normal[a] = 1.0
            solid = solid.trim_by_plane(normal, float(lower[a]))
            solid = solid.trim_by_plane(-normal, -float(upper[a]))
        kept = solid.volume()
        warnings.append(f"the surface extends outside the grid; {100 * (1 - kept / volume):.3g}% of its volume "
                        "outside the grid box was dropped")
    return solid, warnings


def _auto_workers(surface: Surface, grid: Grid) -> int:
    """Processes worth starting: each costs ~0.5 s to spawn, the bisection ~0.5 ms per cut cell
    (estimated from the surface area) plus ~1 us per triangle and tree level."""
    p = np.asarray(surface.vertices, dtype=float)[np.asarray(surface.faces)]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    estimate = 5e-4 * 1.5 * area / grid.spacing**2 + 1e-6 * len(p) * np.log2(max(grid.num_cells, 2))
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return min(cpus, 4) if estimate > 2.0 else 1


def _start_workers(count: int) -> list[subprocess.Popen]:
    """Worker interpreters running ``_serve``, one per CPU this process may use (at most count).

    Plain subprocesses rather than multiprocessing: spawn would re-import the caller's __main__
    script, and fork is unsafe once manifold3d's thread pool exists.
    """
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    procs: list[subprocess.Popen] = []
    for cpu in cpus[:count] if count > 1 else []:
        try:
            procs.append(subprocess.Popen(
                [sys.executable, "-c", f"from engine.geometry.slicing import _serve; _serve({cpu})"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env))
        except OSError:
            break
    if len(procs) < 2:  # one worker would only add its start-up time
        for proc in procs:
            proc.kill()
            proc.wait()
        return []
    return procs


def _serve(cpu: int) -> None:
    """Worker main: read (grid, min_fraction, parts) from stdin, bisect, write _Pieces to stdout.

    manifold3d's thread pool is started while the process is pinned to one CPU, so it stays
    single-threaded (the workers are the parallelism; measured: a serial bisection with the pool
    burns twice the CPU time for the same wall time); then the pin is lifted so that the OS may
    move the worker away from a busy core.
    """
    if hasattr(os, "sched_setaffinity"):
        allowed = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {cpu})
        manifold3d.Manifold.cube([1.0, 1.0, 1.0]).split_by_plane([1.0, 0.0, 0.0], 0.5)[0].volume()
        os.sched_setaffinity(0, allowed)
    result = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # stray prints must not corrupt the result stream
    grid, min_fraction, parts = pickle.load(sys.stdin.buffer)
    out = _Pieces()
    for vertices, triangles, lo, hi in parts:
        part = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=vertices, tri_verts=triangles))
        _walk([(part, lo, hi)], grid, min_fraction, out)
    pickle.dump(out, result, protocol=pickle.HIGHEST_PROTOCOL)
    result.close()


def _bisect(solid: manifold3d.Manifold, grid: Grid, min_fraction: float, procs: list) -> _Pieces:
    """Recursive bisection; with worker processes the parent cuts breadth-first until there are
    4 open parts per worker and deals them out largest first (by triangle count)."""
    root = (solid, np.zeros(3, dtype=np.int64), np.asarray(grid.shape, dtype=np.int64))
    out = _Pieces()
    if not procs:
        _walk([root], grid, min_fraction, out)
        return out
    queue = deque([root])
    while queue and len(queue) < 4 * len(procs):
        queue.extend(_step(*queue.popleft(), grid, min_fraction, out))
    shares: list[list] = [[] for _ in procs]
    load = np.zeros(len(procs))
    for node in sorted(queue, key=lambda node: -node[0].num_tri()):
        k = int(np.argmin(load))
        load[k] += node[0].num_tri()
        shares[k].append(node)
    for proc, share in zip(procs, shares):
        payload = []
        for part, lo, hi in share:
            mesh = part.to_mesh64()
            payload.append((np.array(mesh.vert_properties[:, :3]), np.array(mesh.tri_verts), lo, hi))
        try:
            pickle.dump((grid, min_fraction, payload), proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            proc.stdin.close()
        except OSError:
            pass  # the worker died; its share is redone below
    for proc, share in zip(procs, shares):
        try:
            out.extend(pickle.load(proc.stdout))
        except (EOFError, OSError, pickle.UnpicklingError):  # worker failed (memory?): finish here
            _walk(list(share), grid, min_fraction, out)
    return out


def _walk(stack: list, grid: Grid, min_fraction: float, out: _Pieces) -> None:
    """Depth-first bisection of every (part, lo, hi) on the stack down to cells."""
    while stack:
        stack.extend(reversed(_step(*stack.pop(), grid, min_fraction, out)))


def _step(part: manifold3d.Manifold, lo: np.ndarray, hi: np.ndarray, grid: Grid, min_fraction: float,
          out: _Pieces) -> list:
    """One node: emit full boxes or a cell's pieces into ``out``, or return the two halves after a
    cut at the grid plane nearest the middle of the longest cell range."""
    if part.is_empty():
        return []
    origin, h = np.asarray(grid.origin, dtype=float), grid.spacing
    bounds = np.array(part.bounding_box())
    # Shrink the cell range to the part's bounds (clamped: cut vertices may sit an ulp outside).
    lo = np.maximum(lo, np.floor((bounds[:3] - origin) / h).astype(np.int64))
    hi = np.minimum(hi, np.ceil((bounds[3:] - origin) / h).astype(np.int64))
    extent = hi - lo
    if np.any(extent <= 0):
        return []
    box_volume = float(np.prod(extent)) * h**3
    if abs(part.volume() - box_volume) <= _FULL_TOL * box_volume and _only_box_faces(part, lo, hi, grid):
        out.full_boxes.append((lo, hi))
        return []
    if np.all(extent == 1):
        _split_cell(part, tuple(int(i) for i in lo), h, min_fraction, out)
        return []
    axis = int(np.argmax(extent))
    k = int(lo[axis] + extent[axis] // 2)
    normal = np.zeros(3)
    normal[axis] = 1.0
    upper_part, lower_part = part.split_by_plane(normal, float(origin[axis] + h * k))
    hi_low, lo_up = hi.copy(), lo.copy()
    hi_low[axis] = k
    lo_up[axis] = k
    return [(lower_part, lo, hi_low), (upper_part, lo_up, hi)]


def _only_box_faces(part: manifold3d.Manifold, lo: np.ndarray, hi: np.ndarray, grid: Grid) -> bool:
    """Every triangle lies in a face plane of the box [lo, hi) (cells). The volume test alone
    misses a corner clipped by less than round-off in volume but ~1e-8 h^2 in area, which the
    neighbouring cell would see as a cut."""
    mesh = part.to_mesh64()
    u = (np.asarray(mesh.vert_properties[:, :3]) - np.asarray(grid.origin)) / grid.spacing
    corners = u[np.asarray(mesh.tri_verts, dtype=np.int64)]  # [T, 3 vertices, 3 axes]
    on_plane = np.zeros(len(corners), dtype=bool)
    for a in range(3):
        for bound in (lo[a], hi[a]):
            on_plane |= np.all(np.abs(corners[:, :, a] - bound) <= _PLANE_TOL, axis=1)
    return bool(on_plane.all())


def _split_cell(part: manifold3d.Manifold, cell: tuple[int, int, int], h: float, min_fraction: float,
                out: _Pieces) -> None:
    """Connected pieces of one cell's part, largest first; inner shells (voids) join the
    smallest shell that encloses them."""
    shells, voids = [], []
    for comp in part.decompose():
        volume = comp.volume()
        mesh = comp.to_mesh64()
        entry = (volume, np.asarray(mesh.vert_properties[:, :3], dtype=np.float64),
                 np.asarray(mesh.tri_verts, dtype=np.int64))
        (shells if volume > 0 else voids).append(entry)
    shells.sort(key=lambda e: e[0])
    members: list[list] = [[s] for s in shells]
    for void in voids:
        point = void[1][void[2][0, 0]]
        hosts = [i for i, s in enumerate(shells) if abs(winding_number(s[1], s[2], point[None])[0]) > 0.5]
        if shells:  # a valid manifold always has a host; round-off fallback: the largest shell
            members[hosts[0] if hosts else len(shells) - 1].append(void)
    for group in sorted(members, key=lambda g: -sum(e[0] for e in g)):
        volume = sum(e[0] for e in group)
        if volume < min_fraction * h**3:
            out.dropped += 1
            out.dropped_volume += max(volume, 0.0)
            continue
        offsets = np.cumsum([0] + [len(e[1]) for e in group])
        out.cells.append(cell)
        out.meshes.append((np.concatenate([e[1] for e in group]),
                           np.concatenate([e[2] + off for e, off in zip(group, offsets)])))


def _assemble(raw: _Pieces, grid: Grid, degree: int, warnings: list[str], stats: dict) -> CutCells:
    """Order the pieces by cell, compute moments, interfaces and boundary triangles."""
    h = grid.spacing
    exps = monomial_exponents(3, degree)
    full_cells = [np.stack(np.meshgrid(*[np.arange(l, u) for l, u in zip(lo, hi)], indexing="ij"), -1).reshape(-1, 3)
                  for lo, hi in raw.full_boxes]
    full_cells = np.concatenate(full_cells) if full_cells else np.zeros((0, 3), dtype=np.int64)
    cut_cells = np.array(raw.cells, dtype=np.int64).reshape(-1, 3)
    cells = np.concatenate([full_cells, cut_cells])
    is_full = np.concatenate([np.ones(len(full_cells), bool), np.zeros(len(cut_cells), bool)])
    order = np.lexsort((np.arange(len(cells)), grid.linear_index(cells) if len(cells) else np.zeros(0)))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    piece_cell, full = cells[order], is_full[order]

    tri = _gather_triangles(raw.meshes, rank[len(full_cells):])
    # Each triangle is integrated once, in its piece's xi; the volume terms (cone weight) and the
    # area terms of grid-plane triangles (|N| weight) both come from the same integrals.
    xi = (tri["xyz"] - grid.sample_points(piece_cell[tri["piece"]])[:, None, :]) / h
    normal = np.cross(xi[:, 1] - xi[:, 0], xi[:, 2] - xi[:, 0])
    integrals = triangle_integrals(xi, degree)
    moments = np.tile(cell_moments(degree), (len(piece_cell), 1))
    cut = np.flatnonzero(~full)
    cone = np.einsum("td,td->t", xi[:, 0], normal)
    moments[cut] = _weighted_sum(integrals, cone, tri["piece"], len(piece_cell))[cut] / (3.0 + exps.sum(axis=1))
    volume = moments[:, 0] * h**3
    if np.any(volume <= 0):
        warnings.append(f"{int(np.sum(volume <= 0))} pieces have non-positive volume after integration")

    # Grid-plane triangles: kind = 2 * axis + (1 on the cell's high plane), -1 for surface.
    on_low = (np.abs(xi + 0.5).max(axis=1) <= _PLANE_TOL) & (normal < 0)
    on_high = (np.abs(xi - 0.5).max(axis=1) <= _PLANE_TOL) & (normal > 0)
    kind = np.full(len(xi), -1)
    for a in (2, 1, 0):  # a triangle on two planes is degenerate (zero area): any one will do
        kind[on_low[:, a]] = 2 * a
        kind[on_high[:, a]] = 2 * a + 1
    plane = np.flatnonzero(kind >= 0)
    faces, boundary = _faces(grid, degree, piece_cell, full, tri, kind, plane, integrals[plane],
                             np.linalg.norm(normal[plane], axis=1), stats)
    return CutCells(grid=grid, degree=degree, exponents=exps, piece_cell=piece_cell, full=full, volume=volume,
                    moments=moments, **faces, **boundary, warnings=warnings)


def _gather_triangles(meshes: list, cut_piece: np.ndarray) -> dict:
    """All cut pieces' triangles sorted by final piece index: xyz [T,3,3], piece [T], vid [T,3]."""
    if not meshes:
        return {"xyz": np.zeros((0, 3, 3)), "piece": np.zeros(0, np.int64), "vid": np.zeros((0, 3), np.int64)}
    sizes = np.array([len(t) for _, t in meshes])
    voffset = np.cumsum([0] + [len(v) for v, _ in meshes])[:-1]
    vertices = np.concatenate([v for v, _ in meshes])
    vid = np.concatenate([t + o for (_, t), o in zip(meshes, voffset)])
    piece = np.repeat(cut_piece, sizes)
    order = np.argsort(piece, kind="stable")
    return {"xyz": vertices[vid[order]], "piece": piece[order], "vid": vid[order]}


def _faces(grid: Grid, degree: int, piece_cell: np.ndarray, full: np.ndarray, tri: dict, kind: np.ndarray,
           plane: np.ndarray, integrals: np.ndarray, jacobian: np.ndarray, stats: dict) -> tuple[dict, dict]:
    """Pair the two sides of every grid face into interfaces; collect the surface triangles.

    plane: indices of the grid-plane triangles; integrals [len(plane), n] their reference-triangle
    integrals in their piece's xi, jacobian [len(plane)] = 2 x their area in xi units.
    Each side of a grid face contributes "rows": one per edge-connected component of a cut piece's
    triangles in that face, one per face of a full cell. Rows are grouped by face; the low side
    (L, normal +e_axis) and high side (H) of a group are paired by their area moments.
    """
    n_mon = monomial_exponents(3, degree).shape[0]
    ref_face = cell_face_moments(degree)
    xyz, tri_piece = tri["xyz"], tri["piece"]
    comp = _edge_components(tri["vid"][plane], tri_piece[plane] * 6 + kind[plane])
    n_comp = int(comp.max()) + 1 if len(comp) else 0
    first = np.zeros(n_comp, dtype=np.int64)
    first[comp[::-1]] = plane[::-1]
    comp_axis, comp_side = kind[first] // 2, 1 - kind[first] % 2  # side 0: the piece is below the face
    # Face moments about the low cell's centre: xi_low = xi_piece + e_axis for pieces above.
    to_low = -np.eye(3)[comp_axis] * comp_side[:, None]
    comp_moments = shift_moments(_weighted_sum(integrals, jacobian, comp, n_comp), degree, to_low)

    fp = np.flatnonzero(full)
    f_axis = np.tile(np.arange(3), 2 * len(fp))
    piece = np.concatenate([tri_piece[first], np.repeat(fp, 6)])
    axis = np.concatenate([comp_axis, f_axis])
    side = np.concatenate([comp_side, np.tile(np.repeat([0, 1], 3), len(fp))])
    rcomp = np.concatenate([np.arange(n_comp), np.full(6 * len(fp), -1)])
    low = piece_cell[piece].copy()
    low[np.arange(len(low)), axis] -= side
    high = low.copy()
    high[np.arange(len(high)), axis] += 1
    inside = np.all(low >= 0, axis=1) & np.all(high < np.asarray(grid.shape), axis=1)
    key = axis * grid.num_cells + np.ravel_multi_index(tuple(np.clip(low, 0, np.asarray(grid.shape) - 1).T), grid.shape)
    key = np.where(inside, key, -1 - np.arange(len(key)))  # the grid's outer faces are never paired

    def moments_of(r: np.ndarray) -> np.ndarray:
        m = np.empty((len(r), n_mon))
        m[rcomp[r] >= 0] = comp_moments[rcomp[r][rcomp[r] >= 0]]
        m[rcomp[r] < 0] = ref_face[axis[r][rcomp[r] < 0]]
        return m

    order = np.lexsort((side, key))
    starts = np.flatnonzero(np.r_[True, key[order][1:] != key[order][:-1]]) if len(key) else np.zeros(0, int)
    counts = np.diff(np.r_[starts, len(key)])
    n_low = np.add.reduceat((side[order] == 0).astype(np.int64), starts) if len(starts) else np.zeros(0, int)
    found: list[tuple] = []  # interfaces (minus [k], plus [k], axis [k], moments [k, n])
    surface: list[tuple] = []  # boundary (piece [k], triangles [k, 3, 3])
    # The bulk: one row per side with equal moments (full-full faces and generic cuts).
    pair = np.flatnonzero((counts == 2) & (n_low == 1))
    r0, r1 = order[starts[pair]], order[starts[pair] + 1]
    m0, m1 = moments_of(r0), moments_of(r1)
    ok = np.max(np.abs(m0 - m1), axis=1) <= _MATCH_TOL
    r0, r1, m0, m1 = r0[ok], r1[ok], m0[ok], m1[ok]
    exact = ((rcomp[r0] < 0) | (rcomp[r1] < 0))[:, None]
    found.append((piece[r0], piece[r1], axis[r0], np.where(exact, ref_face[axis[r0]], 0.5 * (m0 + m1))))
    # One-sided groups (a surface lying in a grid plane, the grid's outer faces): all surface.
    lonely = (n_low == 0) | (n_low == counts)
    alone = order[np.repeat(lonely, counts)]
    surface.append((tri_piece[kind < 0], xyz[kind < 0]))
    in_alone = np.isin(comp, rcomp[alone][rcomp[alone] >= 0])
    surface.append((tri_piece[plane[in_alone]], xyz[plane[in_alone]]))
    whole = alone[rcomp[alone] < 0]
    surface.append((np.repeat(piece[whole], 2), _squares(grid, low[whole], axis[whole], side[whole])))
    # The rest: several pieces meet at a face, or its two sides differ (surface in the plane).
    settled = lonely.copy()
    settled[pair[ok]] = True
    stats["faces_resolved_2d"] = 0

    def region(r: int, centre: np.ndarray) -> np.ndarray | None:
        return None if rcomp[r] < 0 else (xyz[plane[comp == rcomp[r]]] - centre) / grid.spacing

    for g in np.flatnonzero(~settled):
        rows = order[starts[g]:starts[g] + counts[g]]
        rl, rh = rows[side[rows] == 0], rows[side[rows] == 1]
        matched = _match(moments_of(rl), moments_of(rh))
        if matched is not None:
            found += [(piece[rl[[i]]], piece[rh[[j]]], axis[rl[[i]]],
                       0.5 * (moments_of(rl[[i]]) + moments_of(rh[[j]]))) for i, j in matched]
            continue
        stats["faces_resolved_2d"] += 1
        _resolve_face(grid, degree, int(axis[rows[0]]), low[rows[0]], piece[rl], piece[rh], region, rl, rh,
                      found, surface)

    minus, plus, f_axis, f_mom = (np.concatenate(parts) for parts in zip(*found))
    forder = np.lexsort((plus, minus))
    f_mom = f_mom.reshape(-1, n_mon)[forder]
    faces = {"face_minus": minus[forder].astype(np.int64), "face_plus": plus[forder].astype(np.int64),
             "face_axis": f_axis[forder].astype(np.int64), "face_area": f_mom[:, 0] * grid.spacing**2,
             "face_moments": f_mom}
    b_piece, b_tri = (np.concatenate(parts) for parts in zip(*surface))
    border = np.argsort(b_piece, kind="stable")
    return faces, {"boundary_piece": b_piece[border].astype(np.int64),
                   "boundary_triangles": b_tri.reshape(-1, 3, 3)[border]}


def _weighted_sum(values: np.ndarray, weight: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """``out[k] = sum_{labels[t] = k} weight[t] values[t]`` -> [n, ...], as one sparse product."""
    indicator = csr_matrix((weight, (labels, np.arange(len(labels)))), shape=(n, len(labels)))
    return np.asarray(indicator @ values)


def _edge_components(vid: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Component label per triangle [T]: triangles of one group sharing an edge are connected."""
    t = len(vid)
    if t == 0:
        return np.zeros(0, dtype=np.int64)
    e0 = np.concatenate([vid[:, 0], vid[:, 1], vid[:, 2]])
    e1 = np.concatenate([vid[:, 1], vid[:, 2], vid[:, 0]])
    owner = np.tile(np.arange(t), 3)
    lo, hi, grp = np.minimum(e0, e1), np.maximum(e0, e1), np.tile(group, 3)
    order = np.lexsort((hi, lo, grp))
    same = (lo[order][1:] == lo[order][:-1]) & (hi[order][1:] == hi[order][:-1]) & (grp[order][1:] == grp[order][:-1])
    a, b = owner[order][:-1][same], owner[order][1:][same]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(t, t))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def _match(low: np.ndarray, high: np.ndarray) -> list[tuple[int, int]] | None:
    """Bijection between the rows of two moment tables that agree to _MATCH_TOL, or None."""
    if len(low) != len(high):
        return None
    close = np.max(np.abs(low[:, None, :] - high[None, :, :]), axis=2) <= _MATCH_TOL
    if not (np.all(close.sum(axis=1) == 1) and np.all(close.sum(axis=0) == 1)):
        return None
    return [(i, int(np.flatnonzero(close[i])[0])) for i in range(len(low))]


def _squares(grid: Grid, low_cell: np.ndarray, axis: np.ndarray, side: np.ndarray) -> np.ndarray:
    """Whole grid faces above ``low_cell`` [k, 3] as triangles [2k, 3, 3], normal +e_axis for side
    0 and -e_axis for side 1."""
    b, c = (axis + 1) % 3, (axis + 2) % 3
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    corner = np.zeros((len(axis), 4, 3))
    rows = np.arange(len(axis))[:, None]
    corner[rows, :, axis[:, None]] = 1.0
    corner[rows, :, b[:, None]] = uv[:, 0]
    corner[rows, :, c[:, None]] = uv[:, 1]
    pts = np.asarray(grid.origin) + grid.spacing * (low_cell[:, None, :] + corner)
    idx = np.where(side[:, None, None] == 0, np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0, 2, 1], [0, 3, 2]]))
    return pts[rows[:, :, None], idx].reshape(-1, 3, 3)


def _resolve_face(grid: Grid, degree: int, axis: int, low_cell: np.ndarray, low_piece: np.ndarray,
                  high_piece: np.ndarray, region, low_rows, high_rows, found: list, surface: list) -> None:
    """2D booleans for one grid face whose sides differ: interfaces = L ∩ H per piece pair (each
    connected part its own interface), surface = L - H and H - L. ``region(row, centre)`` gives a
    row's triangles in xi about ``centre`` (None for a whole face of a full cell)."""
    h = grid.spacing
    b, c = (axis + 1) % 3, (axis + 2) % 3
    centre = grid.sample_points(low_cell[None, :])[0]

    def polygon(r: int):
        t = region(r, centre)
        if t is None:
            return shapely.box(-0.5, -0.5, 0.5, 0.5)
        tris = shapely.polygons(t[:, :, [b, c]])
        return shapely.union_all(tris[shapely.area(tris) > 0])

    lows, highs = [polygon(r) for r in low_rows], [polygon(r) for r in high_rows]
    for pl, p_low in zip(lows, low_piece):
        for ph, p_high in zip(highs, high_piece):
            for part in _polygons(pl.intersection(ph)):
                xi = (_lift(part, axis, centre, h, +1) - centre) / h
                found.append((np.array([p_low]), np.array([p_high]), np.array([axis]),
                              area_terms(xi, degree).sum(axis=0)[None, :]))
    for mine, pieces, other, sign in ((lows, low_piece, highs, +1), (highs, high_piece, lows, -1)):
        rest_of = shapely.union_all(other)
        for p, owner in zip(mine, pieces):
            for part in _polygons(p.difference(rest_of)):
                tris = _lift(part, axis, centre, h, sign)
                surface.append((np.full(len(tris), owner), tris))


def _polygons(geometry) -> list:
    """The polygons of a shapely result with area above the round-off threshold."""
    parts = shapely.get_parts(geometry)
    return [p for p in parts if isinstance(p, shapely.Polygon) and p.area > _SLIVER]


def _lift(polygon, axis: int, centre: np.ndarray, h: float, sign: int) -> np.ndarray:
    """Triangulate a polygon in the face plane (xi_axis = +1/2) into [k, 3, 3] absolute triangles
    with normal ``sign * e_axis``."""
    b, c = (axis + 1) % 3, (axis + 2) % 3  # e_b x e_c = e_axis
    tri2 = shapely.get_coordinates(shapely.constrained_delaunay_triangles(polygon)).reshape(-1, 4, 2)[:, :3]
    xi = np.zeros(tri2.shape[:2] + (3,))
    xi[:, :, axis] = 0.5
    xi[:, :, b], xi[:, :, c] = tri2[:, :, 0], tri2[:, :, 1]
    ccw = (tri2[:, 1, 0] - tri2[:, 0, 0]) * (tri2[:, 2, 1] - tri2[:, 0, 1]) \
        - (tri2[:, 1, 1] - tri2[:, 0, 1]) * (tri2[:, 2, 0] - tri2[:, 0, 0])
    flip = (ccw > 0) != (sign > 0)
    xi[flip] = xi[flip][:, ::-1]
    return centre + h * xi
