"""Face apertures and cells' area vectors (engine/geometry/apertures.py): exact on boxes, and every
cell's divergence theorem to round-off on curved surfaces, in 3D and 2D."""

import itertools

import numpy as np
import trimesh

from engine.geometry.apertures import cell_area_vectors, face_apertures
from engine.geometry.surface import Surface


def _box_apertures(lo, hi, origin, h, axis, faces):
    """The solid share of axis-faces of the box [lo, hi] by hand: in the box's slab, the product of
    the in-plane overlaps."""
    plane = origin[axis] + h * faces[:, axis]
    share = ((plane >= lo[axis]) & (plane <= hi[axis])).astype(float)
    for k in range(len(lo)):
        if k != axis:
            a = origin[k] + h * faces[:, k]
            share *= np.clip(np.minimum(hi[k], a + h) - np.maximum(lo[k], a), 0, None) / h
    return share


def _block(d, n):
    return np.array(list(itertools.product(range(-1, n + 1), repeat=d)), dtype=np.int64)


def test_apertures_of_an_offset_box_are_exact():
    lo, hi = np.array([0.13, 0.27, 0.41]), np.array([1.07, 0.81, 0.66])
    box = trimesh.creation.box(bounds=[lo, hi])
    surface = Surface(np.asarray(box.vertices, float), np.asarray(box.faces, np.int64))
    origin, h, faces = np.array([0.02, -0.01, 0.0]), 0.1, _block(3, 12)
    for axis in range(3):
        got = face_apertures(surface, origin, h, axis, faces)
        expected = _box_apertures(lo, hi, origin, h, axis, faces)
        assert np.abs(got - expected).max() < 1e-13, axis
        assert 0 < np.count_nonzero((expected > 0) & (expected < 1))


def test_apertures_of_a_rectangle_are_exact_in_2d():
    lo, hi = np.array([0.13, 0.27]), np.array([1.07, 0.81])
    corners = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])  # counter-clockwise: solid on the left
    surface = Surface(corners, np.array([[0, 1], [1, 2], [2, 3], [3, 0]]))
    origin, h, faces = np.array([0.0, 0.03]), 0.1, _block(2, 12)
    for axis in range(2):
        expected = _box_apertures(lo, hi, origin, h, axis, faces)
        assert np.abs(face_apertures(surface, origin, h, axis, faces) - expected).max() < 1e-13, axis


def _divergence_defect(surface, origin, h, cells):
    """|sum_a (alpha(a, I + e_a) - alpha(a, I)) h^(d-1) e_a + int_(surface in I) n dA| per cell, over h^(d-1)."""
    d = surface.dim
    eye = np.eye(d, dtype=np.int64)
    jumps = np.stack([face_apertures(surface, origin, h, a, cells + eye[a]) - face_apertures(surface, origin, h, a, cells)
                      for a in range(d)], axis=1) * h ** (d - 1)
    area = cell_area_vectors(surface.vertices[surface.faces], origin, h, cells)
    return np.abs(jumps + area).max(axis=1) / h ** (d - 1), np.abs(area).max(axis=1) / h ** (d - 1)


def test_every_cell_of_a_curved_shell_keeps_the_divergence_theorem():
    outer = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    inner.invert()
    mesh = trimesh.util.concatenate([outer, inner])
    surface = Surface(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    origin, h = np.array([-1.1, -1.1, -1.1]) + 0.013, 0.1
    defect, area = _divergence_defect(surface, origin, h, _block(3, 22))
    assert defect.max() < 1e-12
    assert np.count_nonzero(area > 1e-3) > 500  # cut cells were tested, not only empty and full ones


def test_every_cell_of_an_annulus_keeps_the_divergence_theorem_in_2d():
    t = np.linspace(0, 2 * np.pi, 201)[:-1]
    outer = np.stack([np.cos(t), np.sin(t)], 1)
    inner = 0.5 * outer[::-1]
    ring = lambda k, n: np.stack([k + np.arange(n), k + (np.arange(n) + 1) % n], 1)  # noqa: E731
    surface = Surface(np.concatenate([outer, inner]), np.concatenate([ring(0, 200), ring(200, 200)]))
    origin, h = np.array([-1.1, -1.1]) + 0.007, 0.05
    defect, area = _divergence_defect(surface, origin, h, _block(2, 44))
    assert defect.max() < 1e-12
    assert np.count_nonzero(area > 1e-3) > 100


def test_area_vectors_of_an_open_patch_add_up_to_its_own():
    patch = np.array([[[0.05, 0.11, 0.3], [0.93, 0.2, 0.45], [0.4, 0.87, 0.1]]])
    cells = _block(3, 10)
    parts = cell_area_vectors(patch, np.zeros(3), 0.1, cells)
    whole = 0.5 * np.cross(patch[0, 1] - patch[0, 0], patch[0, 2] - patch[0, 0])
    assert np.abs(parts.sum(axis=0) - whole).max() < 1e-14
    assert np.count_nonzero(np.abs(parts).max(axis=1) > 0) > 10


def test_a_face_on_a_plane_of_cell_faces_belongs_to_the_cell_on_its_solid_side():
    """A box whose faces lie on planes of cell faces: each face's area is in the cell inside it (its
    aperture there 0: a wall), up- and down-facing alike, and every cell keeps its divergence theorem."""
    box = trimesh.creation.box(bounds=[[0.2, 0.1, 0.3], [0.7, 0.6, 0.5]])
    surface = Surface(np.asarray(box.vertices, float), np.asarray(box.faces, np.int64))
    origin, h = np.zeros(3), 0.1
    inside = np.array([[2, 1, 3], [6, 5, 4]])  # the cells at the box's low and high corners
    area = cell_area_vectors(surface.vertices[surface.faces], origin, h, inside)
    assert np.abs(area - [[-h * h] * 3, [h * h] * 3]).max() < 1e-15
    assert np.abs(face_apertures(surface, origin, h, 2, np.array([[3, 3, 5], [3, 3, 3], [3, 3, 4]])) - [0, 0, 1]).max() < 1e-14
    defect, _ = _divergence_defect(surface, origin, h, _block(3, 8))
    assert defect.max() < 1e-12
