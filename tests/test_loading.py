"""3D surface loading, validation and repair (engine.geometry.loading)."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from engine.errors import GeometryError
from engine.geometry.loading import load_surface, mesh_surface
from engine.geometry.stitch import stitch_cracks
from engine.geometry.winding import winding_number


def _sphere(radius: float = 1.0) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=2, radius=radius)  # 320 faces


def _boundary_edge_count(faces: np.ndarray) -> int:
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int(np.sum(counts == 1))


def _tet_volume(p: np.ndarray) -> float:
    return float(np.linalg.det(p[1:] - p[0]) / 6.0)


# --- repair -------------------------------------------------------------------------------------


def test_sphere_with_a_triangle_and_a_quad_hole_is_closed_again():
    sphere = _sphere()
    v0 = sphere.volume
    # A quad hole: two faces sharing an edge, on the side opposite face 0 (the triangle hole).
    far = int(np.argmin(sphere.triangles_center @ sphere.triangles_center[0]))
    pair = sphere.face_adjacency[np.any(sphere.face_adjacency == far, axis=1)][0]
    faces = np.delete(sphere.faces, [0, *pair], axis=0)
    surface = mesh_surface(sphere.vertices, faces)
    assert surface.closed
    assert surface.warnings == ["filled 2 holes with 3 triangles"]
    assert len(surface.faces) == 320
    # The triangle comes back exactly; the quad may be split along the other diagonal, which
    # changes the volume by exactly the tetrahedron of the quad's four corners.
    quad = np.unique(sphere.faces[pair])
    tet = abs(_tet_volume(sphere.vertices[quad]))
    error = abs(surface.enclosed_volume() - v0)
    assert min(error, abs(error - tet)) < 1e-13
    assert tet > 1e-4  # the bound is not vacuous


def test_big_hole_stays_open_and_says_winding_number():
    sphere = _sphere()
    cap = sphere.triangles_center[:, 2] > 0.7
    faces = sphere.faces[~cap]
    boundary = _boundary_edge_count(faces)
    assert boundary > 4  # larger than a quad: fill_holes leaves it
    surface = mesh_surface(sphere.vertices, faces)
    assert not surface.closed
    assert surface.warnings[-1].startswith(
        f"the surface is not closed: {boundary} edges without a matching opposite edge"
    )
    assert "generalized winding number" in surface.warnings[-1]
    # Unused cap vertices are dropped; the open surface is still usable for inside tests.
    unused = len(sphere.vertices) - len(np.unique(faces))
    assert surface.warnings[0].startswith(f"removed {unused} vertices that no face uses")
    w = winding_number(surface.vertices, surface.faces, np.array([[0.0, 0.0, -0.5], [0.0, 0.0, 3.0]]))
    assert w[0] > 0.9 and abs(w[1]) < 0.1


def _cracked(mesh: trimesh.Trimesh, gap: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """mesh as a facet soup whose corners each move by up to ``gap`` per coordinate."""
    soup = mesh.vertices[mesh.faces].reshape(-1, 3)
    soup = soup + np.random.default_rng(seed).uniform(-gap, gap, soup.shape)
    return soup, np.arange(len(soup)).reshape(-1, 3)


def test_a_cracked_facet_soup_is_stitched_closed():
    """An export rounded to 1e-4 m (corners that no exact weld joins): every rim vertex finds its
    copies, the sphere closes with the icosphere's own vertex and face counts, and its volume moves
    by no more than the corners did. Before, filling each lone triangle's "hole" cancelled every
    face and the mesh was refused as enclosing no volume."""
    sphere = _sphere()
    surface = load_surface(trimesh.Trimesh(*_cracked(sphere, 1e-4), process=False).export(file_type="stl"),
                           filename="cracked.stl")
    assert surface.closed
    assert (len(surface.vertices), len(surface.faces)) == (len(sphere.vertices), len(sphere.faces))
    assert len(surface.warnings) == 1 and surface.warnings[0].startswith(
        f"closed cracks: welded {3 * len(sphere.faces) - len(sphere.vertices)} open-edge vertices"), surface.warnings
    volume = trimesh.Trimesh(surface.vertices, surface.faces, process=False).volume
    assert abs(volume / sphere.volume - 1) < 4 * 1e-4 * sphere.area / sphere.volume


def test_gaps_as_wide_as_the_edges_and_closed_meshes_are_not_stitched():
    """A slit as wide as its edges are long is geometry, not a crack; two closed boxes a hair apart
    have no open edge to stitch; a lone triangle beside a sphere keeps its face (its rim is not a
    hole to fill)."""
    a = trimesh.creation.box(extents=[1, 1, 1])
    b = trimesh.creation.box(extents=[1, 1, 1])
    b.apply_translation([1 + 1e-7, 0, 0])
    both = trimesh.util.concatenate([a, b])
    pair = mesh_surface(both.vertices, both.faces)
    assert len(pair.vertices) == 16 and not any("cracks" in w for w in pair.warnings)
    # two strips of a sheet, edges 0.4-1.1 long, their facing rims `gap` apart: welded below 0.04
    for gap, welded in ((0.2, 0), (0.03, 2)):
        v = np.array([[0, 0, 0], [1, 0, 0], [1, 0.4, 0], [0, 0.4, 0],
                      [0, 0.4 + gap, 0], [1, 0.4 + gap, 0], [1, 0.8 + gap, 0], [0, 0.8 + gap, 0.0]])
        f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
        notes: list[str] = []
        kept, faces = stitch_cracks(v, f, notes)
        assert len(v) - len(kept) == welded and len(notes) == (welded > 0), notes
        if welded:
            np.testing.assert_array_equal(faces[2:], [[3, 2, 4], [3, 4, 5]])
    sphere = _sphere()
    lone = np.array([[3.0, 0, 0], [3.5, 0, 0], [3.0, 0.5, 0]])
    surface = mesh_surface(np.concatenate([sphere.vertices, lone]),
                           np.concatenate([sphere.faces, len(sphere.vertices) + np.array([[0, 1, 2]])]))
    assert len(surface.faces) == len(sphere.faces) + 1 and not surface.closed


def test_inverted_box_is_turned_outward():
    box = trimesh.creation.box(extents=(2.0, 3.0, 4.0))
    surface = mesh_surface(box.vertices, box.faces[:, ::-1])
    assert surface.warnings == ["inverted all faces: enclosed volume was negative (-24)"]
    assert surface.enclosed_volume() == pytest.approx(24.0, rel=1e-14)
    np.testing.assert_array_equal(surface.faces, box.faces)


def test_inconsistent_faces_are_reversed_by_majority():
    sphere = _sphere()
    faces = sphere.faces.copy()
    faces[::7] = faces[::7, ::-1]
    surface = mesh_surface(sphere.vertices, faces)
    assert surface.warnings == ["reversed 46 faces to make the winding consistent with their neighbours"]
    np.testing.assert_array_equal(surface.faces, sphere.faces)


def test_hollow_sphere_keeps_its_inward_cavity():
    outer, inner = _sphere(1.0), _sphere(0.5)
    vertices = np.vstack([outer.vertices, inner.vertices])
    expected = outer.volume - inner.volume
    # Inscribed shells of the same shape: the discrete 4/3 pi (R^3 - r^3), a little below it.
    assert expected == pytest.approx(outer.volume * (1 - 0.5**3), rel=1e-14)
    assert 0.96 < expected / (4 / 3 * np.pi * (1 - 0.5**3)) < 1
    surface = mesh_surface(vertices, np.vstack([outer.faces, inner.faces[:, ::-1] + len(outer.vertices)]))
    assert surface.closed and surface.warnings == []
    assert surface.enclosed_volume() == pytest.approx(expected, rel=1e-13)
    # Both shells given outward: the cavity is turned inward, by its nesting.
    surface = mesh_surface(vertices, np.vstack([outer.faces, inner.faces + len(outer.vertices)]))
    assert surface.warnings[0].startswith(
        "inverted 1 of 2 shells so that outer shells face outward and cavities inward"
    )
    assert surface.enclosed_volume() == pytest.approx(expected, rel=1e-13)


def test_disjoint_bodies_and_an_island_in_a_cavity():
    shells = [_sphere(1.0), _sphere(0.6), _sphere(0.3), _sphere(0.5)]
    offsets = [(0, 0, 0), (0, 0, 0), (0, 0, 0), (3, 0, 0)]
    vertices, faces, n = [], [], 0
    for shell, offset in zip(shells, offsets):
        vertices.append(shell.vertices + offset)
        faces.append(shell.faces[:, ::-1] + n)  # all given inward
        n += len(shell.vertices)
    surface = mesh_surface(np.vstack(vertices), np.vstack(faces))
    volumes = [s.volume for s in shells]
    # depth 0, 1, 2 around the origin and a separate ball: + - + +
    expected = volumes[0] - volumes[1] + volumes[2] + volumes[3]
    assert surface.enclosed_volume() == pytest.approx(expected, rel=1e-13)
    assert surface.warnings[0].startswith("inverted 3 of 4 shells")


def test_duplicate_and_cancelling_faces_are_removed():
    box = trimesh.creation.box()
    faces = np.vstack([box.faces, box.faces[:2], box.faces[2:3, ::-1], box.faces[2:3, ::-1]])
    surface = mesh_surface(box.vertices, faces)
    # Faces 0 and 1 twice: one copy each goes. Face 2 and two reverses: net one reversed face
    # stays, which the winding repair turns back.
    assert surface.warnings == [
        "removed 2 repeated faces",
        "removed 2 faces that cancel in pairs (coincident with opposite orientation)",
        "reversed 1 faces to make the winding consistent with their neighbours",
    ]
    assert len(surface.faces) == 12 and surface.closed
    assert surface.enclosed_volume() == pytest.approx(1.0, rel=1e-14)


def test_stl_corners_are_merged_and_vertex_order_of_obj_is_kept():
    box = trimesh.creation.box()
    surface = load_surface(box.export(file_type="stl"), filename="box.stl")
    assert len(surface.vertices) == 8
    assert surface.warnings == []  # STL never shares corners: merging them is not news (issue 18)
    assert surface.closed and surface.enclosed_volume() == pytest.approx(1.0, rel=1e-14)
    order = np.random.default_rng(1).permutation(8)
    obj = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in box.vertices[order])
    obj += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.argsort(order)[box.faces])
    surface = load_surface(obj.encode(), filename="box.obj")
    assert surface.warnings == []
    np.testing.assert_array_equal(surface.vertices, box.vertices[order])


# --- errors -------------------------------------------------------------------------------------


def test_nan_vertex_is_rejected():
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 3 1 4\n"
    message = r"^geometry\.mesh: 'a.obj': 1 of the 4 vertices has non-finite coordinates \(NaN or infinity\)$"
    with pytest.raises(GeometryError, match=message):
        load_surface(obj, filename="a.obj")
    box = trimesh.creation.box()
    vertices = box.vertices.copy()
    vertices[[1, 5], 0] = np.inf
    with pytest.raises(GeometryError, match="2 of the 8 vertices have non-finite"):
        mesh_surface(vertices, box.faces)


@pytest.mark.parametrize("filename", ["x.stl", "x.ply", "x.off", "x.glb", "x.obj"])
def test_garbage_bytes_are_rejected(filename):
    with pytest.raises(GeometryError, match=rf"^geometry\.mesh: cannot read '{filename}': "):
        load_surface(b"\x00\x01garbage\xff\xfe 12 x", filename=filename)


def test_unreadable_sources_name_the_problem(tmp_path):
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: cannot read 'x.foo': unknown file type '.foo'"):
        load_surface(b"solid", filename="x.foo")
    with pytest.raises(GeometryError, match="need a filename"):
        load_surface(b"solid")
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: cannot read 'missing.stl': No such file"):
        load_surface(tmp_path / "missing.stl")
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: cannot read 'x.stl': the file is empty$"):
        load_surface(b"", filename="x.stl")
    message = r"^geometry\.mesh: cannot read 'shape.svg': 'svg' is a 2D drawing; use dimension 2$"
    with pytest.raises(GeometryError, match=message):
        load_surface(b"<svg/>", filename="shape.svg")
    with pytest.raises(GeometryError, match="dimension 2 needs an SVG or DXF file"):
        load_surface(b"solid", filename="x.stl", dimension=2)


def test_mesh_without_faces_is_rejected():
    message = r"^geometry\.mesh: cannot read 'points.obj': no mesh found in the file \(is it a valid OBJ file\?\)$"
    with pytest.raises(GeometryError, match=message):
        load_surface(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", filename="points.obj")
    with pytest.raises(GeometryError, match=r"^'points' has no faces$"):
        mesh_surface(np.eye(3), np.zeros((0, 3), dtype=int), name="points")
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: cannot read 'empty.stl': no mesh found"):
        load_surface(b"solid empty\nendsolid empty\n", filename="empty.stl")


def test_flat_meshes_are_rejected():
    box = trimesh.creation.box()
    flat = box.vertices * [1.0, 1.0, 0.0]  # top and bottom collapse onto each other
    with pytest.raises(GeometryError, match="encloses no volume"):
        mesh_surface(flat, box.faces)
    sheet = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.0]])
    message = r"^'sheet' encloses no volume: it is flat \(zero extent along z\)$"
    with pytest.raises(GeometryError, match=message):
        mesh_surface(sheet, [[0, 1, 2], [0, 2, 3]], name="sheet")
    with pytest.raises(GeometryError, match="all 3 faces|no faces are left"):
        mesh_surface(box.vertices, [[0, 0, 1], [2, 2, 2], [3, 4, 3]])


def test_bad_placement_and_indices_are_rejected():
    box = trimesh.creation.box()
    with pytest.raises(GeometryError, match="scale must be a finite number > 0, got -1.0"):
        mesh_surface(box.vertices, box.faces, scale=-1.0)
    with pytest.raises(GeometryError, match="transform must be rigid"):
        mesh_surface(box.vertices, box.faces, transform=np.diag([2.0, 1.0, 1.0, 1.0]))
    message = r"transform must be a finite \[4, 4\] homogeneous matrix, got shape \[3, 3\]"
    with pytest.raises(GeometryError, match=message):
        mesh_surface(box.vertices, box.faces, transform=np.eye(3))
    with pytest.raises(GeometryError, match=r"face vertex indices must lie in \[0, 7\], found 0..8"):
        mesh_surface(box.vertices, np.vstack([box.faces, [[0, 1, 8]]]))


# --- sources and placement ----------------------------------------------------------------------


@pytest.mark.parametrize("file_type", ["stl", "obj", "ply", "off", "glb"])
def test_bytes_and_path_give_the_same_surface(tmp_path, file_type):
    sphere = _sphere()
    data = sphere.export(file_type=file_type)
    data = data.encode() if isinstance(data, str) else data
    path = tmp_path / f"ball.{file_type}"
    path.write_bytes(data)
    from_path, from_bytes = load_surface(path), load_surface(data, filename=f"ball.{file_type}")
    np.testing.assert_array_equal(from_path.vertices, from_bytes.vertices)
    np.testing.assert_array_equal(from_path.faces, from_bytes.faces)
    assert from_path.warnings == from_bytes.warnings
    # STL, PLY and GLB store float32, OBJ 8 decimals.
    assert from_path.enclosed_volume() == pytest.approx(sphere.volume, rel=1e-7)


def test_scale_then_rigid_transform():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    rotation = trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 0.5])
    transform = trimesh.transformations.translation_matrix([10.0, -5.0, 2.0]) @ rotation
    surface = mesh_surface(box.vertices, box.faces, scale=2.0, transform=transform)
    assert surface.enclosed_volume() == pytest.approx(6.0 * 8.0, rel=1e-13)
    corners = (box.vertices * 2.0) @ transform[:3, :3].T + transform[:3, 3]
    lower, upper = surface.bounds
    np.testing.assert_allclose(lower, corners.min(axis=0), rtol=0, atol=1e-13)
    np.testing.assert_allclose(upper, corners.max(axis=0), rtol=0, atol=1e-13)
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    surface = mesh_surface(box.vertices, box.faces, transform=mirror)
    assert surface.warnings == ["the transform mirrors the geometry: reversed all faces to keep them outward"]
    assert surface.enclosed_volume() == pytest.approx(6.0, rel=1e-14)


def test_glb_scene_nodes_are_flattened():
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    move = trimesh.transformations.translation_matrix
    turn = trimesh.transformations.rotation_matrix(np.pi / 4, [0.0, 0.0, 1.0])
    scene.add_geometry(box, node_name="a", geom_name="box", transform=move([5.0, 0.0, 0.0]))
    scene.add_geometry(box, node_name="b", geom_name="box", transform=move([0.0, 5.0, 0.0]) @ turn)
    surface = load_surface(scene.export(file_type="glb"), filename="two.glb")
    assert surface.warnings == ["combined 2 mesh instances of the scene into one surface"]
    assert surface.closed
    assert surface.enclosed_volume() == pytest.approx(2.0, rel=1e-6)  # GLB stores float32
    lower, upper = surface.bounds
    half_diagonal = np.sqrt(0.5)
    np.testing.assert_allclose(lower, [-half_diagonal, -0.5, -0.5], atol=1e-6)
    np.testing.assert_allclose(upper, [5.5, 5.0 + half_diagonal, 0.5], atol=1e-6)


def test_gltf_path_resolves_its_buffer_file(tmp_path):
    files = _sphere().export(file_type="gltf")  # {"model.gltf": ..., "gltf_buffer_0.bin": ...}
    assert len(files) > 1
    for file_name, content in files.items():
        (tmp_path / file_name).write_bytes(content)
    surface = load_surface(tmp_path / "model.gltf")
    assert surface.closed and surface.enclosed_volume() == pytest.approx(_sphere().volume, rel=1e-7)
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: cannot read 'model.gltf': "):
        load_surface(files["model.gltf"], filename="model.gltf")  # bytes alone: no buffer


def test_trimesh_objects_are_accepted():
    surface = load_surface(_sphere(2.0))
    assert surface.closed and surface.enclosed_volume() == pytest.approx(_sphere(2.0).volume, rel=1e-14)


def test_two_bodies_touching_along_a_face_load_as_one_solid_and_the_warning_says_so():
    # the shared face is triangulated differently on each side, so its triangles do not cancel in pairs
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[1, 0, 0], [2, 1, 1]])
    s = load_surface(trimesh.util.concatenate([a, b]).export(file_type="stl"), filename="pair.stl")
    assert s.closed and s.enclosed_volume() == pytest.approx(2.0, rel=1e-14)
    # their pieces' boxes meet only in the shared plane: no overlap can hide there, so nothing is unchecked
    assert s.warnings == ["bodies touch along shared faces: they are solved as one solid, bonded where they touch"]


def test_instances_of_a_scene_merge_their_shared_corners_without_a_warning():
    # two instances of one box, touching along a face: their coincident corners come from flattening
    box = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    scene = trimesh.Scene()
    scene.add_geometry(box, geom_name="box", node_name="a")
    scene.add_geometry(box, geom_name="box", node_name="b", transform=trimesh.transformations.translation_matrix([1, 0, 0]))
    surface = load_surface(scene.export(file_type="glb"), filename="pair.glb")
    assert surface.closed and surface.enclosed_volume() == pytest.approx(2.0, rel=1e-12)
    assert not any("duplicate vertices" in w for w in surface.warnings), surface.warnings


def test_every_mesh_error_names_geometry_mesh_and_placement_errors_their_own_field():
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: 'sheet.obj' encloses no volume: it is flat"):
        load_surface(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n", filename="sheet.obj")
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: polygon 'x.svg': loop 0 is not a simple closed curve"):
        load_surface(b'<svg xmlns="http://www.w3.org/2000/svg" fill="none"><path d="M0 0 L10 2 L10 0 L0 2 Z"/></svg>',
                     filename="x.svg", dimension=2)
    with pytest.raises(GeometryError, match=r"^geometry\.scale: 'c.stl': scale must be a finite number > 0, got -1"):
        load_surface(b"", filename="c.stl", scale=-1.0)
    with pytest.raises(GeometryError, match=r"^geometry\.transform: 'c.stl': transform must be rigid"):
        load_surface(b"", filename="c.stl", transform=np.diag([2.0, 1, 1, 1]))


TET_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
TET_OFF = b"OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
TET_PLY = (b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
           b"element face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
           b"3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")


@pytest.mark.parametrize("filename, text", [("t.obj", TET_OBJ), ("t.off", TET_OFF), ("t.ply", TET_PLY)])
def test_a_text_mesh_behind_a_utf8_byte_order_mark_reads_as_without(filename, text):
    # an OBJ saved by a Windows editor: the mark hid its first vertex ("not a valid OBJ file")
    plain = load_surface(text, filename=filename)
    marked = load_surface(b"\xef\xbb\xbf" + text, filename=filename)
    assert marked.faces.tolist() == plain.faces.tolist() and marked.vertices.tolist() == plain.vertices.tolist()
    assert marked.enclosed_volume() == pytest.approx(1 / 6)


TET_STL = trimesh.load_mesh(io.BytesIO(TET_OBJ), file_type="obj").export(file_type="stl_ascii").encode()


@pytest.mark.parametrize("mark", [b"", b"\xef\xbb\xbf"])
@pytest.mark.parametrize("end", [b"\r\n", b"\r", b"\r\r\n"])
@pytest.mark.parametrize("filename, text", [("t.obj", TET_OBJ), ("t.off", TET_OFF), ("t.ply", TET_PLY),
                                            ("t.stl", TET_STL)])
def test_a_text_mesh_reads_the_same_whatever_its_line_ends(filename, text, end, mark):
    # Windows' "\r\n" (also behind a byte-order mark) was read; classic Mac "\r" was one line to
    # trimesh ("not a valid PLY file", "no mesh found", an STL enclosing no volume), and "\r\r\n" (a
    # file saved twice through a Windows text stream) put a blank line after each of a PLY's rows
    plain = load_surface(text, filename=filename)
    other = load_surface(mark + text.replace(b"\n", end), filename=filename)
    assert other.faces.tolist() == plain.faces.tolist() and other.vertices.tolist() == plain.vertices.tolist()
    assert other.warnings == plain.warnings and other.enclosed_volume() == pytest.approx(1 / 6)


def test_carriage_returns_inside_a_binary_ply_are_data():
    x = float(np.frombuffer(b"\r\x00\x80\x3f", "<f4")[0])  # 1.0000015, whose float32 holds a byte 0x0d
    data = trimesh.creation.box(bounds=[[0, 0, 0], [x, 1, 1]]).export(file_type="ply", encoding="binary")
    assert b"\r" in data[data.index(b"end_header\n"):]
    assert load_surface(data, filename="box.ply").bounds[1].tolist() == [x, 1, 1]


def test_the_enclosed_volume_of_a_part_far_from_the_origin_does_not_cancel_away():
    # a 1 m bar at 1e7 m enclosed -1.9e6 m^3 about the origin (the run warned "the solid is thin for
    # this grid ... -1.9e+06 cells", and DG that the surface "intersects itself"), at 3e6 m -9.1e3 m^3
    bar = trimesh.creation.box((1, 0.2, 0.2))
    bar.apply_translation((3e6, -3e6, 3e6))
    surface = load_surface(bar.export(file_type="obj").encode(), filename="bar.obj")
    assert surface.enclosed_volume() == pytest.approx(0.04, rel=1e-6)  # the OBJ keeps 8 decimals
    assert not surface.warnings


def test_a_part_too_far_from_the_origin_for_its_size_is_refused_naming_where_it_lies():
    # a 1 m bar at 1e9 m ran, 23% off (DG 5%), with no warning
    bar = trimesh.creation.box((1, 0.2, 0.2))
    bar.apply_translation((1e9, 0, 0))
    with pytest.raises(GeometryError) as info:
        load_surface(bar.export(file_type="obj").encode(), filename="bar.obj")
    assert str(info.value) == (
        "geometry.mesh: 'bar.obj' lies 1e+09 m from the origin, 1e+09 times its size (1 m): there double precision "
        "keeps too few digits of its shape (at most 1e+07 times its size); move it towards the origin (the "
        "translation of geometry.transform, or in the file)")
    bar.apply_translation((-1e9, 0, 0))
    away = np.eye(4)
    away[0, 3] = 1e9
    with pytest.raises(GeometryError, match=r"^geometry\.transform: 'bar\.obj' lies 1e\+09 m from the origin"):
        load_surface(bar.export(file_type="obj").encode(), filename="bar.obj", transform=away)


@pytest.mark.parametrize("scale, words", [(1e-61, "geometry.scale: scaled by 1e-61, 'bar.obj' is 1e-61 m across; at least 1e-60 m is supported"),
                                          (1e61, "geometry.scale: scaled by 1e+61, 'bar.obj' reaches coordinates of 5e+60 m; at most 1e+60 m is supported")])
def test_parts_beyond_the_sizes_the_arithmetic_holds_are_refused(scale, words):
    # at 1e80 m the staggered strain fit raised a LinAlgError, at 1e-80 m every boundary lost its patch
    bar = trimesh.creation.box((1, 0.2, 0.2))
    with pytest.raises(GeometryError) as info:
        load_surface(bar.export(file_type="obj").encode(), filename="bar.obj", scale=scale)
    assert str(info.value) == words
