"""Overlapping shells: find them, and unite them into one clean solid.

Meshes from the wild often hold several closed shells whose solids overlap (CAD assemblies, a
handle pushed into a body). Every later stage assumes the shells bound the solid once: the scan
conversion would count the overlap twice, and manifold3d's slicing of such a mesh is undefined.
``unite_overlapping_shells`` runs on the closed, nesting-oriented surface from ``loading``:

1. Candidate pairs: shells whose bounding boxes intersect, by sort and sweep along the axis
   where the fewest intervals overlap (``box_pairs``); a single shell or well-separated shells
   cost no more than this.
2. Exact test per candidate pair with manifold3d: the region R_i enclosed by each shell (built
   outward from its own triangles, ``Mesh64``) and I = vol(R_i ∩ R_j) decide

       I <= tol                          disjoint (or touching)
       I >= vol(R_i) - tol, i smaller    R_i inside R_j: nested, the surfaces do not cross
       otherwise                         the surfaces cross: an overlap

   with tol = ``OVERLAP_TOL`` * the smaller shell volume. Two shells enclosing the same region
   (a duplicated body) count as crossing. Pairs with more than ``_APART_MIN_FACES`` triangles
   first try a cheaper test (``_Shells.apart``): if no triangle bounding box of one meets one of
   the other's, the surfaces cannot cross, so the pair is disjoint or nested -- decided, only if
   it matters, by the winding number of one shell at a vertex of the other. This keeps a hollow
   part (two nested 82k-triangle spheres) at ~40 ms. If no pair crosses, the surface comes back
   unchanged (the same object).
3. Otherwise, shells linked by crossing or nesting are rebuilt together; all other shells keep
   their triangles. Nesting is decided by exact containment, not by the orientation loading
   gave: shell j contains shell i when R_i ⊂ R_j and their surfaces do not cross, and the parent
   of i is its innermost container (most containers of its own). A shell at even depth of that
   forest is a solid, at odd depth a cavity -- the rule loading applies, made exact. Bottom-up
   by depth, each shell's part is ``R_i - ⋃ part(children)`` (a cavity minus the islands in it,
   a solid minus its cavities), and the solid is the union of the roots' parts: a union of
   bodies, so crossing solids merge, crossing cavities of one solid merge into one void, islands
   inside cavities stay, and a second body reaching into a cavity keeps its material there.

Why not keep loading's orientation as the solid/cavity flag: loading nests shells by the winding
number at one point of each shell, which is exact for shells that do not cross but a coin flip
for one that does (a box pushed into a sphere, wholly inside the sphere's bounding box and with
that point inside the sphere, comes out inward). Shells whose role this step changes are
counted in a warning.

Limitations, stated rather than faked:
- A cavity that pokes out through its solid's surface is not contained by it, so it is a root:
  it is united as a solid. Loading has normalised the input orientation by then (usually to
  outward for such a shell, and it warns), so the intent "notch" cannot be recovered here.
- A single shell that intersects itself is not detected: manifold3d builds such a mesh without
  complaint, and its only checks that would tell (booleans of the shell with itself) cost
  seconds on 100k triangles (measured 4.6 s for a union, 1.0 s for an intersection), more than
  loading itself. Downstream, the volume fractions warn when sub-cell volumes leave [0, 1].
- Open surfaces (``closed`` False) are returned unchanged: their inside test is the winding
  number, for which a double cover already reads as inside.
- A shell manifold3d rejects (``status`` not ``NoError``) cannot be tested; if its bounding box
  shares a volume with another shell's, it is left as it is, with a warning that says so (boxes
  that meet only in a face, as those of bodies touching along a plane, cannot hide an overlap).
"""

from __future__ import annotations

import itertools

import manifold3d
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from engine.errors import GeometryError
from engine.geometry.surface import Surface
from engine.geometry.topology import edge_balance
from engine.geometry.winding import winding_number

# Intersection volumes below this fraction of the smaller shell's volume are round-off or a
# touch; the same slack decides containment. manifold3d's volumes are exact to ~1e-16 relative.
OVERLAP_TOL = 1e-9
# Candidate pairs generated at once by the sweep (bounds its scratch memory, ~100 MB).
_PAIR_CHUNK = 1 << 22

# Cells along the longest side of the box two shells share, for the test that their triangles'
# bounding boxes stay apart (``_Shells.apart``): 2.1 M cells at most.
_APART_CELLS = 128
# Below this many triangles in a pair, manifold3d's exact test (~0.1 ms) beats that test.
_APART_MIN_FACES = 2000

# Why manifold3d rejects a piece that is open on its own: it is part of bodies sharing faces or edges.
_TOUCHING = "open on its own: bodies touching along shared faces"

# Relation of shell i to shell j; _APART: disjoint or nested, not yet known which.
_DISJOINT, _INSIDE, _CONTAINS, _CROSSING, _APART = 0, 1, 2, 3, 4


def unite_overlapping_shells(surface: Surface, shell: np.ndarray) -> Surface:
    """The surface with overlapping shells replaced by the boundary of their boolean solid.

    surface: closed and oriented (outer shells outward, cavities inward), as ``loading`` makes it.
    shell: [k] int, shell label per face (edge-connected components, labels 0..n-1).
    Returns ``surface`` itself when no two shells cross; otherwise a new closed Surface whose
    untouched shells keep their triangles, with a warning giving the overlap volume [m^3].
    Raises ``GeometryError`` if manifold3d fails on the boolean.
    """
    shell = np.asarray(shell, dtype=np.int64)
    n = int(shell.max()) + 1 if len(shell) else 0
    if not surface.closed or n < 2:
        return surface
    solids = _Shells(surface, shell, n)
    first, second = box_pairs(solids.lower, solids.upper)
    if len(first) == 0:
        return surface
    relation, overlap = _relations(solids, first, second)
    crossing = relation == _CROSSING
    rebuilt = np.zeros(n, dtype=bool)
    if crossing.any():
        _settle_apart(solids, first, second, relation)
        linked = relation != _DISJOINT
        graph = coo_matrix((np.ones(int(linked.sum())), (first[linked], second[linked])), shape=(n, n))
        component = connected_components(graph, directed=False)[1]
        rebuilt = np.isin(component, component[first[crossing]])
        # A shell manifold3d rejects cannot take part in booleans: its component stays as it is.
        rejected = [s for s in np.nonzero(rebuilt)[0] if solids[s] is None]
        rebuilt &= ~np.isin(component, component[rejected])
    unchecked = _unchecked(solids, first, second)
    if unchecked:
        reasons = ", ".join(sorted({solids.rejected[s] for s in unchecked}))
        surface.warnings.append(
            f"could not check {len(unchecked)} surface pieces for overlaps with their neighbours"
            f" ({reasons}): where they overlap others, the overlap counts twice; make each body a closed"
            " surface of its own, or unite them in the modelling program"
        )
    elif _TOUCHING in solids.rejected.values():
        # nothing unchecked, but the user may have meant parts in contact, not one part
        surface.warnings.append("bodies touch along shared faces: they are solved as one solid, bonded where they touch")
    if not rebuilt.any():
        return surface
    depth, parent = _nesting(solids, rebuilt, first, second, relation)
    shells = np.nonzero(rebuilt)[0].tolist()
    solid = _evaluate(solids, shells, depth, parent)
    united = _replace_shells(surface, shell, rebuilt, solid)
    before = sum(solids.signed_volume(s) for s in shells)
    doubled = overlap[crossing & rebuilt[first]].sum()
    united.warnings.append(
        f"united {len(shells)} overlapping shells (overlap volume {doubled:.6g} m^3;"
        f" enclosed volume {before:.6g} -> {solid.volume():.6g} m^3); vertex numbering differs from"
        " the input"
    )
    solid_now = [s for s in shells if depth[s] % 2 == 0 and solids.signed_volume(s) < 0]
    cavity_now = [s for s in shells if depth[s] % 2 == 1 and solids.signed_volume(s) > 0]
    if solid_now or cavity_now:
        united.warnings.append(
            f"took {len(solid_now)} shells that loading oriented as cavities as solids and"
            f" {len(cavity_now)} solids as cavities: their surfaces cross others, so their nesting"
            " was decided by exact containment"
        )
    return united


def box_pairs(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All pairs of intersecting axis-aligned boxes (closed: touching boxes count).

    lower, upper: [n, 3] corners. Returns (i [p], j [p]) int64 with i < j, sorted by i then j.
    Sort and sweep: along one axis, each box meets the boxes that start before it ends; the
    axis with the fewest such interval overlaps is swept, the other two filter.
    """
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    n = len(lower)
    best = None
    for axis in range(lower.shape[1] if n > 1 else 0):
        order = np.argsort(lower[:, axis], kind="stable")
        end = np.searchsorted(lower[order, axis], upper[order, axis], side="right")
        count = np.maximum(end - np.arange(1, n + 1), 0)  # later starts within this box's span
        if best is None or count.sum() < best[2].sum():
            best = (axis, order, count)
    if best is None or best[2].sum() == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    _, order, count = best
    total = np.cumsum(count)
    found_i, found_j, start = [], [], 0
    while start < n:
        done = total[start - 1] if start else 0
        stop = max(int(np.searchsorted(total, done + _PAIR_CHUNK, side="right")), start + 1)
        c = count[start:stop]
        a = np.repeat(np.arange(start, stop), c)
        b = a + 1 + np.arange(len(a)) - np.repeat(np.cumsum(c) - c, c)
        a, b = order[a], order[b]
        hit = np.all((lower[a] <= upper[b]) & (lower[b] <= upper[a]), axis=1)
        found_i.append(np.minimum(a[hit], b[hit]))
        found_j.append(np.maximum(a[hit], b[hit]))
        start = stop
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    key = np.lexsort((j, i))
    return i[key], j[key]


class _Shells:
    """The shells of a surface: bounds, and (built on first use) signed volumes [m^3] and the
    regions they enclose as outward manifold3d solids (None where manifold3d rejects a shell;
    ``rejected`` says why)."""

    def __init__(self, surface: Surface, shell: np.ndarray, n: int) -> None:
        self.surface, self.shell = surface, shell
        order = np.argsort(shell, kind="stable")
        self.members = np.split(order, np.cumsum(np.bincount(shell, minlength=n))[:-1])  # faces per shell
        a, b, c = (surface.vertices[surface.faces[:, q]] for q in range(3))  # corners [k, 3]
        self.tri_lower = np.minimum(np.minimum(a, b), c)  # triangle bounding boxes [k, 3]
        self.tri_upper = np.maximum(np.maximum(a, b), c)
        starts = np.cumsum([0] + [len(m) for m in self.members[:-1]])
        self.lower = np.minimum.reduceat(self.tri_lower[order], starts)  # [n, 3]
        self.upper = np.maximum.reduceat(self.tri_upper[order], starts)
        self.rejected: dict[int, str] = {}
        self._solid: dict[int, manifold3d.Manifold] = {}
        self._volume: np.ndarray | None = None

    def signed_volume(self, s: int) -> float:
        if self._volume is None:
            # About each shell's lower corner: origin-free for closed shells, less round-off.
            reference = self.lower[self.shell]
            a, b, c = (self.surface.vertices[self.surface.faces[:, q]] - reference for q in range(3))
            tet = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
            self._volume = np.bincount(self.shell, weights=tet, minlength=len(self.members))
        return float(self._volume[s])

    def volume(self, s: int) -> float:
        return abs(self.signed_volume(s))

    def __getitem__(self, s: int) -> manifold3d.Manifold | None:
        if s not in self._solid:
            faces = self.surface.faces[self.members[s]]
            used, local = np.unique(faces, return_inverse=True)
            local = local.reshape(faces.shape)
            if self.signed_volume(s) < 0:
                local = local[:, ::-1]  # a cavity: the region it bounds, outward
            solid = manifold3d.Manifold(manifold3d.Mesh64(
                vert_properties=np.ascontiguousarray(self.surface.vertices[used]),
                tri_verts=np.ascontiguousarray(local, dtype=np.uint64),
            ))
            if solid.status() != manifold3d.Error.NoError:
                # a piece open on its own is part of bodies that share faces or edges (two boxes
                # touching along a face, triangulated differently on each side)
                alone = edge_balance(local, len(used))[2].any()
                self.rejected[s] = _TOUCHING if alone else solid.status().name
            self._solid[s] = solid
        return None if s in self.rejected else self._solid[s]

    def apart(self, i: int, j: int) -> bool:
        """True if no triangle of shell i has a bounding box meeting one of shell j's, so the
        surfaces cannot cross; False proves nothing (the boxes are snapped outward to a grid).

        Over the box both shells share, a difference array of i's triangle boxes summed along
        the three axes counts the boxes covering each cell; a summed-area table of the covered
        cells then answers for each of j's triangle boxes in O(1).
        """
        lower = np.maximum(self.lower[i], self.lower[j])
        upper = np.minimum(self.upper[i], self.upper[j])
        if np.any(lower > upper):
            return True
        boxes = []
        for s in (i, j):
            lo, hi = self.tri_lower[self.members[s]], self.tri_upper[self.members[s]]
            near = np.all((lo <= upper) & (hi >= lower), axis=1)
            if not near.any():
                return True
            boxes.append((lo[near], hi[near]))
        # Cells about the size of the triangles: n triangles on a surface are ~extent / sqrt(n)
        # across, so the cell count follows the triangle count.
        cells = min(_APART_CELLS, 2 * int(np.sqrt(len(boxes[0][0]) + len(boxes[1][0]))) + 1)
        h = float((upper - lower).max()) / cells
        if not h > 0:
            return False
        shape = np.minimum(np.floor((upper - lower) / h).astype(np.int64) + 1, cells)
        ranges = []
        for lo, hi in boxes:
            first = np.clip(np.floor((lo - lower) / h).astype(np.int64), 0, shape - 1)
            last = np.clip(np.floor((hi - lower) / h).astype(np.int64), 0, shape - 1)
            ranges.append((first, last + 1))  # half-open cell ranges
        corners = list(itertools.product((0, 1), repeat=3))
        stride = np.array([(shape[1] + 1) * (shape[2] + 1), shape[2] + 1, 1])
        (a0, a1), (b0, b1) = ranges
        delta = np.zeros(int(np.prod(shape + 1)))
        for c in corners:
            index = np.where(c, a1, a0) @ stride
            delta += np.bincount(index, minlength=len(delta)) * (-1.0) ** sum(c)
        cover = delta.reshape(shape + 1).cumsum(0).cumsum(1).cumsum(2)[:-1, :-1, :-1] > 0.5
        table = np.zeros(shape + 1)
        table[1:, 1:, 1:] = cover.cumsum(0).cumsum(1).cumsum(2)
        hits = sum((-1.0) ** (3 - sum(c)) * table.reshape(-1)[np.where(c, b1, b0) @ stride] for c in corners)
        return not np.any(hits > 0.5)


def _relations(shells: _Shells, first: np.ndarray, second: np.ndarray):
    """Relation of each candidate pair (``_DISJOINT`` ... ``_APART``) and vol(R_i ∩ R_j) [m^3]
    where manifold3d computed it (pairs whose triangles come close)."""
    relation = np.zeros(len(first), dtype=np.int64)
    overlap = np.zeros(len(first))
    for p, (i, j) in enumerate(zip(first.tolist(), second.tolist())):
        if len(shells.members[i]) + len(shells.members[j]) > _APART_MIN_FACES and shells.apart(i, j):
            relation[p] = _APART
            continue
        a, b = shells[i], shells[j]
        if a is None or b is None:
            continue
        common = (a ^ b).volume()
        vi, vj = shells.volume(i), shells.volume(j)
        tol = OVERLAP_TOL * min(vi, vj)
        overlap[p] = common
        if common <= tol:
            continue
        inside, contains = common >= vi - tol, common >= vj - tol
        relation[p] = _CROSSING if inside == contains else (_INSIDE if inside else _CONTAINS)
    return relation, overlap


def _unchecked(solids: _Shells, first: np.ndarray, second: np.ndarray) -> list[int]:
    """The pieces manifold3d rejected whose bounding box shares a volume with a neighbour's.

    Pieces whose boxes meet only in a plane, a line or a point (two bodies touching along a
    face, each side split into open pieces) cannot overlap in volume: nothing is left unchecked.
    """
    if not solids.rejected:
        return []
    extent = (solids.upper - solids.lower).max()
    common = np.minimum(solids.upper[first], solids.upper[second]) - np.maximum(solids.lower[first], solids.lower[second])
    thick = np.all(common > OVERLAP_TOL * extent, axis=1)
    near = set(first[thick].tolist()) | set(second[thick].tolist())
    return sorted(s for s in solids.rejected if s in near)


def _settle_apart(shells: _Shells, first: np.ndarray, second: np.ndarray, relation: np.ndarray) -> None:
    """Decide the ``_APART`` pairs in place: with the surfaces apart, one shell is inside the
    other exactly when one of its vertices is (winding number of the other shell there)."""
    vertices, faces = shells.surface.vertices, shells.surface.faces
    lower, upper = shells.lower, shells.upper
    for p in np.nonzero(relation == _APART)[0]:
        i, j = int(first[p]), int(second[p])
        relation[p] = _DISJOINT
        for inner, outer, code in ((i, j, _INSIDE), (j, i, _CONTAINS)):
            boxed = np.all(lower[inner] >= lower[outer]) and np.all(upper[inner] <= upper[outer])
            if boxed:
                point = vertices[faces[shells.members[inner][0], :1]]
                if abs(winding_number(vertices, faces[shells.members[outer]], point)[0]) > 0.5:
                    relation[p] = code
                    break


def _nesting(solids: _Shells, rebuilt: np.ndarray, first, second, relation):
    """(depth [n], parent [n], -1 for roots) of the containment forest of the rebuilt shells."""
    n = len(rebuilt)
    inner = np.concatenate([first[relation == _INSIDE], second[relation == _CONTAINS]])
    outer = np.concatenate([second[relation == _INSIDE], first[relation == _CONTAINS]])
    containers = np.bincount(inner, minlength=n)
    parent, depth = np.full(n, -1), np.zeros(n, dtype=np.int64)
    # A container j of i has fewer containers than i (j's containers contain i, and so does j):
    # in order of that count, every parent is settled before its children.
    for i in sorted(np.nonzero(rebuilt & (containers > 0))[0], key=lambda s: containers[s]):
        candidates = outer[inner == i]
        # Innermost: most containers of its own, then the smallest.
        best = max(candidates.tolist(), key=lambda s: (containers[s], -solids.volume(s)))
        parent[i], depth[i] = best, depth[best] + 1
    return depth, parent


def _evaluate(solids: _Shells, shells: list[int], depth: np.ndarray, parent: np.ndarray):
    """The boolean solid of the rebuilt shells (module docstring, step 3), deepest first."""
    roots: list[manifold3d.Manifold] = []
    children: dict[int, list[manifold3d.Manifold]] = {}
    for s in sorted(shells, key=lambda s: -depth[s]):
        part = solids[s]
        if s in children:
            part = part - manifold3d.Manifold.batch_boolean(children[s], manifold3d.OpType.Add)
        (children.setdefault(int(parent[s]), []) if parent[s] >= 0 else roots).append(part)
    result = manifold3d.Manifold.batch_boolean(roots, manifold3d.OpType.Add)
    if result.status() != manifold3d.Error.NoError:
        raise GeometryError(f"could not unite the overlapping shells (manifold3d: {result.status().name})")
    return result


def _replace_shells(surface: Surface, shell: np.ndarray, rebuilt: np.ndarray, solid) -> Surface:
    """The kept shells (their vertices first, in input order) plus the boundary of ``solid``."""
    kept = surface.faces[~rebuilt[shell]]
    used = np.zeros(len(surface.vertices), dtype=bool)
    used[kept] = True
    mesh = solid.to_mesh64()
    new_vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    new_faces = np.asarray(mesh.tri_verts, dtype=np.int64) + int(used.sum())
    return Surface(
        vertices=np.concatenate([surface.vertices[used], new_vertices]),
        faces=np.concatenate([(np.cumsum(used) - 1)[kept], new_faces]),
        closed=True,
        warnings=list(surface.warnings),
    )
