"""Surface loading, validation and repair: files or arrays -> an oriented ``Surface``.

3D: any mesh format trimesh reads (STL, OBJ, PLY, OFF, GLB/GLTF, 3MF, ...), from a path or from
bytes plus a file name whose extension names the format. Scenes are flattened with their node
transforms. The triangles are then validated and repaired (``mesh_surface``):

1. non-finite coordinates, out-of-range indices, no faces -> ``GeometryError``;
2. exactly coincident vertices are merged (first occurrence keeps its place, so the vertex order
   is the input's minus the duplicates), open-edge vertices far closer together than their edges
   are long are welded (cracks, ``engine.geometry.stitch``) and vertices no face uses are dropped;
3. faces with a repeated vertex are dropped; repeated faces are reduced to one, and a face
   paired with its reverse (a double-sided internal wall) cancels out, as it does in every
   integral over the surface;
4. winding is made consistent across each connected shell (majority of the input wins);
5. triangle and quad holes are filled (``trimesh.repair.fill_holes``), except the rims of lone
   triangles and quads, which are not holes;
6. each shell is oriented by its nesting: outer shells outward, cavities inward;
7. zero or negative enclosed volume -> ``GeometryError``;
8. shells whose solids overlap are replaced by their boolean union (``engine.geometry.shells``).

Every step that changed something leaves a warning with its numbers in ``Surface.warnings``.
A surface that is still open is returned with ``closed=False``: inside tests then use the
generalized winding number (``engine.geometry.winding``).

2D (``dimension=2``): an SVG/DXF drawing is handed to ``engine.geometry.polygon``, which turns
its closed curves into oriented segments.

Placement: ``x' = R (scale * x) + t`` -- the uniform scale first, then the rigid transform
(``transform`` = [[R, t], [0, 1]], 4x4 in 3D and 3x3 in 2D; R orthogonal).
"""

from __future__ import annotations

import codecs
import io
import os
import re
from pathlib import Path

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_tree, connected_components
from trimesh.exchange.load import mesh_formats, path_formats
from trimesh.resolvers import FilePathResolver, ZipResolver

from engine.errors import GeometryError
from engine.files import read_input
from engine.geometry._shared import FLAT_TOL, check_volume, describe_error, place
from engine.geometry.inflate import DEFAULT_MAX_INFLATED, check_zip_container, container_suffix, inflate
from engine.geometry.polygon import drawing_surface
from engine.geometry.shells import unite_overlapping_shells
from engine.geometry.surface import Surface
from engine.geometry.stitch import stitch_cracks
from engine.geometry.stl import TEXT, fix_binary_count
from engine.geometry.topology import edge_balance, edges, manifold_adjacency, shells
from engine.geometry.winding import winding_number

MeshSource = str | os.PathLike | bytes | trimesh.Trimesh | trimesh.Scene

# 'field.path: reason', as the service splits engine messages
_FIELD = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)*: ")
_COMMON_FORMATS = "stl, obj, ply, off, glb, gltf, 3mf; svg, dxf in 2D; also inside .gz, .bz2, .xz, .zip, .tar"
# text formats whose first line trimesh misreads behind a UTF-8 byte-order mark (Windows editors
# write one): an OBJ starting "\ufeffv 0 0 0" lost its first vertex and was "not a valid OBJ file"
_BOM_FORMATS = {"obj", "off", "ply"}
# line ends of text meshes, given to trimesh as "\n": its readers find lines at "\n", so a file with
# classic Mac line ends ("\r") was one long line (a PLY or OBJ "not valid" or "no mesh found", an ASCII
# STL enclosing no volume), and one saved twice through a Windows text stream ("\r\r\n") had a blank
# line after every row, which misaligns a PLY's elements; Windows' own "\r\n" was read as it is
_TEXT_FORMATS = {"obj", "off", "ply", "stl"}
_LINE_END = re.compile(rb"\r+\n?")
# formats that are ZIP archives themselves: their members are inflated by trimesh's loader
_ZIP_FORMATS = {"3mf", "3dxml"}
# a hint for formats whose files commonly fail for a reason the user can fix
_HINTS = {
    "gltf": "; a .gltf must embed its buffers as data: URIs (or upload a .glb, which holds everything in one file)",
    "obj": "; each 'v' line needs three coordinates and each 'f' line vertex numbers that exist",
    "ply": "; its header must declare the vertex properties x, y, z and a face list that the data then holds",
}


def load_surface(
    source: MeshSource,
    *,
    filename: str | None = None,
    dimension: int = 3,
    scale: float = 1.0,
    transform: np.ndarray | None = None,
    max_inflated_bytes: int = DEFAULT_MAX_INFLATED,
) -> Surface:
    """Read, validate and repair a surface; raises ``GeometryError`` naming the problem.

    source: a path, the file's bytes (then ``filename`` supplies the format by its extension),
    or an in-memory ``trimesh.Trimesh`` / ``trimesh.Scene``. dimension: 3 for a triangle
    mesh, 2 for a planar drawing (SVG, DXF). scale: uniform factor (> 0) applied first;
    transform: rigid [d+1, d+1] homogeneous matrix applied after scaling. Units: whatever the
    file uses times ``scale`` [m]. max_inflated_bytes: cap on what a compressed or archived file
    (.gz, .bz2, .xz, .zip, .tar.*, and the ZIP inside a .3mf) may inflate to
    (``engine.geometry.inflate.InflateLimitError`` beyond it). Every error message starts with the
    spec field it concerns: ``geometry.mesh:`` unless it names another (``geometry.scale:``).
    """
    try:
        return _load_surface(source, filename, dimension, scale, transform, max_inflated_bytes)
    except GeometryError as exc:
        # the CLI prints the message and the service files it under the field it starts with
        message = str(exc)
        if not _FIELD.match(message):
            exc.args = (f"geometry.mesh: {message}",)
        raise


def _load_surface(source, filename, dimension, scale, transform, max_inflated_bytes) -> Surface:
    if dimension not in (2, 3):
        raise GeometryError(f"dimension: must be 2 or 3, got {dimension!r}")
    name = filename or (Path(source).name if isinstance(source, (str, os.PathLike)) else "mesh")
    for field, placement in (("geometry.scale", (scale, None)), ("geometry.transform", (1.0, transform))):
        try:  # before reading: a bad placement is no fault of the mesh
            place(np.zeros((1, dimension)), *placement, name)
        except GeometryError as exc:
            raise GeometryError(f"{field}: {exc}") from None
    if isinstance(source, (trimesh.Trimesh, trimesh.Scene)):
        if dimension != 3:
            raise GeometryError("dimension: a trimesh mesh or scene needs dimension 3")
        name = filename or "mesh"
        scene = trimesh.Scene(source) if isinstance(source, trimesh.Trimesh) else source
        with np.errstate(invalid="ignore", over="ignore"):  # non-finite input is refused by _checked_arrays
            vertices, faces, notes, meshes = _flatten_scene(scene)
    else:
        name, data, file_type, resolver = _resolve_source(source, filename)
        files = [(name, data, file_type)]
        if container_suffix(name):  # also meshio's .vol.gz & co: its own gunzip has no cap
            files, resolver = _unpack(name, data, dimension, max_inflated_bytes)
        elif file_type in _ZIP_FORMATS:
            check_zip_container(name, data, max_inflated_bytes)
        if dimension == 2:
            return drawing_surface(*files[0], scale=scale, transform=transform)
        if file_type in path_formats():
            raise GeometryError(f"cannot read '{name}': '{file_type}' is a 2D drawing; use dimension 2")
        notes, read = [], []
        for n, d, t in files:
            if t == "stl":
                d, fixes = fix_binary_count(n, d)
                notes += fixes
            elif t in _BOM_FORMATS and d.startswith(codecs.BOM_UTF8):
                d = d[len(codecs.BOM_UTF8):]
            if t in _TEXT_FORMATS and b"\r" in d and not d.translate(None, TEXT):  # binary bytes stay as they are
                d = _LINE_END.sub(b"\n", d)
            read.append((n, d, t))
        # trimesh computes normals of whatever it reads: non-finite input is refused by _checked_arrays
        with np.errstate(invalid="ignore", over="ignore"):
            vertices, faces, found, meshes = _flatten_scenes([_read_scene(n, d, t, resolver) for n, d, t in read])
        notes += found
        if len(vertices) == 0:
            raise GeometryError(
                f"cannot read '{name}': no mesh found in the file (is it a valid {files[0][2].upper()} file?)"
            )
    # STL stores every facet with its own three corners: merging them is the format's normal case,
    # not news for the user (issue 18). Nor are merges where several meshes (instances of a scene,
    # files of an archive) were combined: their corners coincide where the parts meet, and the
    # combined numbering is this loader's, not the input's. A single mesh of another format shares
    # its vertices, so merges there are reported.
    stl = not isinstance(source, (trimesh.Trimesh, trimesh.Scene)) and all(
        t in ("stl", "stl_ascii") for _, _, t in files)
    surface = mesh_surface(vertices, faces, scale=scale, transform=transform, name=name,
                           report_merges=not stl and meshes == 1)
    surface.warnings[:0] = notes
    return surface


def mesh_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    scale: float = 1.0,
    transform: np.ndarray | None = None,
    name: str = "mesh",
    report_merges: bool = True,
) -> Surface:
    """Validate, place and repair a triangle mesh: vertices [m, 3] [m], faces [k, 3] int.

    Steps and warnings as in the module docstring; ``name`` labels error messages;
    ``report_merges=False`` merges coincident vertices without a warning (STL input).
    """
    vertices, faces = _checked_arrays(vertices, faces, name)
    vertices, mirrored = place(vertices, scale, transform, name)
    warnings: list[str] = []
    if mirrored:
        faces = faces[:, ::-1]
        warnings.append("the transform mirrors the geometry: reversed all faces to keep them outward")
    vertices, faces = _merge_vertices(vertices, faces, warnings if report_merges else [])
    vertices, faces = stitch_cracks(vertices, faces, warnings)
    faces = _require_faces(_drop_bad_faces(faces, warnings), name)
    vertices, faces = _drop_unused_vertices(vertices, faces, warnings)
    faces = _orient_consistently(faces, len(vertices), warnings)
    faces = _fill_holes(vertices, faces, warnings)
    # A fill may repeat or cancel an existing face (a hole bounded by a face's own edges).
    faces = _require_faces(_drop_bad_faces(faces, warnings), name)
    faces = _orient_consistently(faces, len(vertices), warnings)
    faces, shell = _orient_by_nesting(vertices, faces, warnings)
    surface = Surface(vertices=vertices, faces=faces, closed=True, warnings=warnings)
    check_volume(surface, name)
    boundary, conflicts = _open_edges(faces, len(vertices))
    if boundary or conflicts:
        surface.closed = False
        problems = []
        if boundary:
            problems.append(
                f"{boundary} edges without a matching opposite edge (holes larger than quads remain)"
            )
        if conflicts:
            problems.append(f"{conflicts} edges where the winding cannot be made consistent")
        warnings.append(
            f"the surface is not closed: {'; '.join(problems)};"
            " inside tests use the generalized winding number"
        )
    else:
        surface = unite_overlapping_shells(surface, shell)
    return surface


# --- reading ---------------------------------------------------------------------------------


def _resolve_source(source, filename: str | None):
    """(display name, file bytes, trimesh file type, resolver of sibling files or None)."""
    resolver = None
    if isinstance(source, (bytes, bytearray, memoryview)):
        if not filename:
            raise GeometryError(
                "mesh bytes need a filename whose extension names the format (e.g. 'part.stl')"
            )
        name, data = filename, bytes(source)
    elif isinstance(source, (str, os.PathLike)):
        path = Path(source)
        name = filename or path.name
        try:
            data = read_input(path)
        except OSError as exc:
            raise GeometryError(f"cannot read '{name}': {exc.strerror or exc}") from None
        resolver = FilePathResolver(str(path))  # GLTF buffers, OBJ materials beside the file
    else:
        raise GeometryError(f"a mesh source must be a path or bytes, got {type(source).__name__}")
    known = mesh_formats() | path_formats()
    matches = [ft for ft in known if Path(name).name.lower().endswith("." + ft)]
    container = container_suffix(name)
    if container and not matches:
        matches = [container.lstrip(".")]  # the format inside is known once it is unpacked
    if not matches:
        suffix = Path(name).suffix
        reason = f"unknown file type '{suffix}'" if suffix else "the file name has no extension"
        raise GeometryError(f"cannot read '{name}': {reason} (formats: {_COMMON_FORMATS}, ...)")
    if len(data) == 0:
        raise GeometryError(f"cannot read '{name}': the file is empty")
    return name, data, max(matches, key=len), resolver


def _unpack(name: str, data: bytes, dimension: int, limit: int):
    """The mesh (or drawing) files inside a compressed or archived file: ([(name, bytes, type)],
    a resolver over all its members for files that refer to others, such as .gltf buffers)."""
    members = inflate(name, data, limit)
    wanted = path_formats() if dimension == 2 else mesh_formats()
    files = []
    for member, content in members.items():
        types = [ft for ft in wanted if member.lower().endswith("." + ft)]
        if types and content:
            files.append((member, content, max(types, key=len)))
    if not files:
        inside = ", ".join(sorted(members)[:5]) or "nothing"
        kind = "drawing (svg, dxf)" if dimension == 2 else "mesh file"
        raise GeometryError(f"cannot read '{name}': no {kind} inside (found: {inside}); a compressed file "
                            "must keep the mesh's own suffix, e.g. part.stl.gz")
    if dimension == 2 and len(files) > 1:
        raise GeometryError(f"cannot read '{name}': {len(files)} drawings inside; upload one")
    return files, ZipResolver({k: io.BytesIO(v) for k, v in members.items()})


def _read_scene(name: str, data: bytes, file_type: str, resolver) -> trimesh.Scene:
    # process=False: no merging or reordering by trimesh; repair is done here, with warnings.
    extra = {"maintain_order": True} if file_type == "obj" else {}
    try:
        return trimesh.load_scene(
            io.BytesIO(data), file_type=file_type, resolver=resolver, process=False, **extra
        )
    except MemoryError:
        raise  # not the file's fault as such: the caller's memory limit reports it
    except Exception as exc:  # noqa: BLE001 - any loader failure is a bad file to the user
        # trimesh's own exceptions name its internals (StopIteration, KeyError: 'y'), not the problem
        what = f"{file_type.upper()} file"
        raise GeometryError(f"cannot read '{name}': {describe_error(exc, what)}"
                            f"{_HINTS.get(file_type, '')}") from None


def _flatten_scenes(scenes: list[trimesh.Scene]) -> tuple[np.ndarray, np.ndarray, list[str], int]:
    """The mesh instances of several scenes (the files of an archive) as one surface."""
    if len(scenes) == 1:
        return _flatten_scene(scenes[0])
    parts = [_flatten_scene(s) for s in scenes]
    notes = sorted({n for _, _, ns, _ in parts for n in ns if not n.startswith("combined")})
    found = [(v, f) for v, f, _, _ in parts if len(v)]
    meshes = sum(m for _, _, _, m in parts)
    if not found:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), notes, meshes
    offsets = np.cumsum([0] + [len(v) for v, _ in found[:-1]])
    notes.append(f"combined {len(found)} mesh files of the archive into one surface")
    faces = np.concatenate([f + o for (_, f), o in zip(found, offsets)])
    return np.concatenate([v for v, _ in found]), faces, notes, meshes


def _flatten_scene(scene: trimesh.Scene) -> tuple[np.ndarray, np.ndarray, list[str], int]:
    """Mesh instances of a scene in world coordinates: (vertices [m, 3], faces [k, 3], notes,
    number of instances)."""
    vertices, faces, skipped, count = [], [], set(), 0
    for node in scene.graph.nodes_geometry:
        matrix, geometry_name = scene.graph[node]
        geometry = scene.geometry[geometry_name]
        if not isinstance(geometry, trimesh.Trimesh):
            skipped.add(type(geometry).__name__)
            continue
        v = np.asarray(geometry.vertices, dtype=np.float64)
        f = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
        matrix = np.asarray(matrix, dtype=np.float64)
        if not np.array_equal(matrix, np.eye(4)):
            v = v @ matrix[:3, :3].T + matrix[:3, 3]
            if np.linalg.det(matrix[:3, :3]) < 0:
                f = f[:, ::-1]  # a mirroring node transform turns outward faces inward
        faces.append(f + count)
        vertices.append(v)
        count += len(v)
    notes = []
    if skipped:
        notes.append(f"ignored scene objects that are not triangle meshes ({', '.join(sorted(skipped))})")
    if len(vertices) > 1:
        notes.append(f"combined {len(vertices)} mesh instances of the scene into one surface")
    if not vertices:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), notes, 0
    return np.concatenate(vertices), np.concatenate(faces), notes, len(vertices)


# --- validation ---------------------------------------------------------------------------------


def _checked_arrays(vertices, faces, name: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        vertices = np.array(vertices, dtype=np.float64)
        faces = np.array(faces, dtype=np.int64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"'{name}': vertices and faces must be numeric arrays ({exc})") from None
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise GeometryError(f"'{name}': vertices must have shape [m, 3], got {list(vertices.shape)}")
    faces = faces.reshape(-1, 3) if faces.size == 0 else faces
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise GeometryError(f"'{name}': faces must have shape [k, 3], got {list(faces.shape)}")
    if len(faces) == 0:
        raise GeometryError(f"'{name}' has no faces")
    bad = int((~np.isfinite(vertices).all(axis=1)).sum())
    if bad:
        raise GeometryError(
            f"'{name}': {bad} of the {len(vertices)} vertices {'has' if bad == 1 else 'have'}"
            " non-finite coordinates (NaN or infinity)"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise GeometryError(
            f"'{name}': face vertex indices must lie in [0, {len(vertices) - 1}],"
            f" found {faces.min()}..{faces.max()}"
        )
    return vertices, faces


def _require_faces(faces: np.ndarray, name: str) -> np.ndarray:
    if len(faces) == 0:
        raise GeometryError(
            f"'{name}' encloses no volume: no faces are left after removing degenerate"
            " and cancelling faces"
        )
    return faces


# --- 3D repair ----------------------------------------------------------------------------------


def _merge_vertices(vertices: np.ndarray, faces: np.ndarray, warnings: list[str]):
    """Merge exactly equal vertices, keeping first occurrences in their input order."""
    # + 0.0 turns -0.0 into 0.0 so both compare equal as rows.
    _, first, inverse = np.unique(vertices + 0.0, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(vertices):
        return vertices, faces
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    warnings.append(
        f"merged {len(vertices) - len(first)} duplicate vertices ({len(vertices)} -> {len(first)});"
        " vertex numbering differs from the input"
    )
    return vertices[first[order]], rank[inverse.reshape(-1)][faces]


def _drop_bad_faces(faces: np.ndarray, warnings: list[str]) -> np.ndarray:
    """Drop faces with a repeated vertex; reduce each set of faces on the same three vertices to
    their net orientation: one face, or none where opposite faces cancel."""
    degenerate = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    if degenerate.any():
        warnings.append(f"removed {int(degenerate.sum())} degenerate faces (a vertex repeated)")
        faces = faces[~degenerate]
    if len(faces) == 0:
        return faces
    key = np.sort(faces, axis=1)
    n = int(key.max()) + 1
    if n <= 2**21:  # one int64 per sorted triple: a 1D unique is much faster than rows
        key = (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
    axis = 0 if key.ndim == 2 else None
    _, group, counts = np.unique(key, axis=axis, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    if counts.max() == 1:
        return faces
    # Orientation of a face relative to its sorted vertex triple: rotate the smallest index to
    # the front; (min, a, b) with a < b is the sorted cyclic order (+1), else reversed (-1).
    rows, roll = np.arange(len(faces)), np.argmin(faces, axis=1)
    sign = np.where(faces[rows, (roll + 1) % 3] < faces[rows, (roll + 2) % 3], 1, -1)
    net = np.bincount(group, weights=sign, minlength=len(counts)).astype(np.int64)
    candidate = (sign == np.sign(net[group])) & (net[group] != 0)
    keep = np.zeros(len(faces), dtype=bool)
    keep[np.nonzero(candidate)[0][np.unique(group[candidate], return_index=True)[1]]] = True
    shared = net[counts > 1]
    repeated = int(np.sum(np.abs(shared) - (shared != 0)))
    cancelled = int(counts[counts > 1].sum() - np.abs(shared).sum())
    if repeated:
        warnings.append(f"removed {repeated} repeated faces")
    if cancelled:
        warnings.append(
            f"removed {cancelled} faces that cancel in pairs (coincident with opposite orientation)"
        )
    return faces[keep]


def _drop_unused_vertices(vertices: np.ndarray, faces: np.ndarray, warnings: list[str]):
    used = np.zeros(len(vertices), dtype=bool)
    used[faces] = True
    if used.all():
        return vertices, faces
    warnings.append(
        f"removed {int((~used).sum())} vertices that no face uses;"
        " vertex numbering differs from the input"
    )
    return vertices[used], (np.cumsum(used) - 1)[faces]


def _orient_consistently(faces: np.ndarray, n_vertices: int, warnings: list[str]) -> np.ndarray:
    """Reverse faces so that neighbours across manifold edges agree, per connected shell; in
    each shell the orientation held by the majority of its faces is kept."""
    k = len(faces)
    n_shells, label, (fa, fb, same) = shells(faces, n_vertices)
    if not same.any():
        return faces
    # A spanning tree from a virtual root (node k) linked to one face of every shell; edge
    # weight = 1 + (child must be reversed relative to parent), so no weight is zero.
    roots = np.unique(label, return_index=True)[1]
    rows, cols = np.concatenate([fa, np.full(n_shells, k)]), np.concatenate([fb, roots])
    weight = np.concatenate([1 + same, np.ones(n_shells)])
    graph = coo_matrix((weight, (rows, cols)), shape=(k + 1, k + 1)).tocsr()
    tree = breadth_first_tree(graph, k, directed=False).tocoo()
    parent, flip = np.arange(k + 1), np.zeros(k + 1, dtype=np.int64)
    parent[tree.col], flip[tree.col] = tree.row, np.rint(tree.data).astype(np.int64) - 1
    # XOR of the relative flips along the path to the root, by pointer jumping (log depth steps).
    while not np.array_equal(parent[parent], parent):
        flip ^= flip[parent]
        parent = parent[parent]
    flip = flip[:k].astype(bool)
    majority = np.bincount(label, weights=flip, minlength=n_shells) > np.bincount(label) / 2
    flip ^= majority[label]
    if flip.any():
        faces = faces.copy()
        faces[flip] = faces[flip, ::-1]
        warnings.append(
            f"reversed {int(flip.sum())} faces to make the winding consistent with their neighbours"
        )
    return faces


def _open_edges(faces: np.ndarray, n_vertices: int) -> tuple[int, int]:
    """(edges without a partner, edges shared by several faces but not in opposite pairs).

    The surface is closed -- the boundary of a solid, so the divergence theorem and the signed
    prism sums are exact -- when every edge a->b is matched by as many edges b->a. This also
    accepts non-manifold edges shared by two touching shells.
    """
    _, counts, net = edge_balance(faces, n_vertices)
    unbalanced = net != 0
    return int(np.sum(unbalanced & (counts == 1))), int(np.sum(unbalanced & (counts > 1)))


# A shell of at most this many faces is not a surface with a hole: filling "the hole" of a lone
# triangle (or quad) adds its own back face, which then cancels it, so a facet soup whose corners
# do not weld exactly (an export rounded to 1e-4 m) lost every face and was refused as enclosing no
# volume. Such shells stay open and the winding number takes them as they are.
LONE_SHELL = 2


def _fill_holes(vertices: np.ndarray, faces: np.ndarray, warnings: list[str]) -> np.ndarray:
    if _open_edges(faces, len(vertices))[0] == 0:
        return faces
    n_shells, label, _ = shells(faces, len(vertices))
    lone = (np.bincount(label, minlength=n_shells) <= LONE_SHELL)[label]
    if lone.all():
        return faces
    kept, faces = faces[lone], faces[~lone]
    before = _boundary_loops(faces, len(vertices))
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
    try:
        trimesh.repair.fill_holes(mesh)  # triangle and quad holes only, oriented to the rim
    except Exception:  # noqa: BLE001 - a failed fill leaves the mesh open, which is reported
        return np.concatenate([faces, kept])
    if len(mesh.faces) == len(faces):
        return np.concatenate([faces, kept])
    filled = np.asarray(mesh.faces, dtype=np.int64)
    holes = before - _boundary_loops(filled, len(vertices))
    added = len(filled) - len(faces)
    warnings.append(
        f"filled {holes} {'hole' if holes == 1 else 'holes'} with {added}"
        f" {'triangle' if added == 1 else 'triangles'}"
    )
    return np.concatenate([filled, kept])


def _boundary_loops(faces: np.ndarray, n_vertices: int) -> int:
    """Number of connected curves formed by edges used by a single face."""
    edge, counts, ends = edges(faces, n_vertices)
    single = counts[edge] == 1
    if not single.any():
        return 0
    a, b = ends[single, 0], ends[single, 1]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n_vertices, n_vertices))
    label = connected_components(graph, directed=False)[1]
    return len(np.unique(label[a]))


def _orient_by_nesting(vertices: np.ndarray, faces: np.ndarray, warnings: list[str]):
    """Orient every shell by how deeply it is nested.

    A shell inside an odd number of other shells bounds a cavity and must face inward (negative
    volume); all others face outward. Orienting each shell to positive volume on its own --
    what ``trimesh.repair.fix_normals`` does -- would turn the cavity of a hollow sphere into a
    second solid ball, and an overall volume check would miss an inverted shell among others.
    """
    n_shells, label, _ = shells(faces, len(vertices))
    order = np.argsort(label, kind="stable")
    members = np.split(order, np.cumsum(np.bincount(label, minlength=n_shells))[:-1])
    volume = np.zeros(n_shells)
    lower, upper, probe = np.zeros((n_shells, 3)), np.zeros((n_shells, 3)), np.zeros((n_shells, 3))
    for s, shell in enumerate(members):
        p = vertices[faces[shell]]
        # Volume about the shell's own centroid: independent of the origin for closed shells,
        # and a stable orientation measure for almost-closed ones.
        q = p - p.reshape(-1, 3).mean(axis=0)
        volume[s] = np.einsum("ij,ij->i", q[:, 0], np.cross(q[:, 1], q[:, 2])).sum() / 6.0
        lower[s], upper[s] = p.reshape(-1, 3).min(axis=0), p.reshape(-1, 3).max(axis=0)
        area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        probe[s] = p[np.argmax(area)].mean(axis=0)  # a point on the shell, off its edges
    depth = np.zeros(n_shells, dtype=np.int64)
    for s in range(n_shells if n_shells > 1 else 0):
        # Only shells whose bounding box lies within this one's can be inside it.
        inner = np.nonzero((lower >= lower[s]).all(axis=1) & (upper <= upper[s]).all(axis=1))[0]
        inner = inner[inner != s]
        if len(inner):
            depth[inner] += np.abs(winding_number(vertices, faces[members[s]], probe[inner])) > 0.5
    flat = np.abs(volume) <= FLAT_TOL * (upper - lower).max(axis=1) ** 3
    wrong = ~flat & ((volume > 0) != (depth % 2 == 0))
    if not wrong.any():
        return faces, label
    flip = wrong[label]
    faces = faces.copy()
    faces[flip] = faces[flip, ::-1]
    if wrong.all():
        warnings.append(f"inverted all faces: enclosed volume was negative ({volume.sum():.6g})")
    else:
        after = np.abs(volume).dot(np.where(depth % 2 == 0, 1.0, -1.0))
        warnings.append(
            f"inverted {int(wrong.sum())} of {n_shells} shells so that outer shells face outward"
            f" and cavities inward (enclosed volume {volume.sum():.6g} -> {after:.6g})"
        )
    return faces, label
