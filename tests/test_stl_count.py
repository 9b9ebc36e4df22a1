"""Binary STLs whose triangle count disagrees with their size (engine.geometry.stl via load_surface)."""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest
import trimesh

from engine.errors import GeometryError
from engine.geometry.loading import load_surface

BAR = bytes(trimesh.creation.box(bounds=[[0, 0, 0], [2, 1, 1]]).export(file_type="stl"))  # 12 triangles


def _with_count(data: bytes, count: int) -> bytes:
    return data[:80] + struct.pack("<I", count) + data[84:]


@pytest.mark.parametrize(
    "data, note",
    [
        (BAR + b"\0" * 37, "the binary STL 'bar.stl' ends in 37 bytes that are no whole triangle record: ignored them"
                           " and read 12 triangles (as its header gives)"),
        (BAR + b"\n\n", "the binary STL 'bar.stl' ends in 2 bytes that are no whole triangle record: ignored them"
                        " and read 12 triangles (as its header gives)"),
        (_with_count(BAR, 0), "the binary STL 'bar.stl' gives 0 triangles in its header but its size holds 12:"
                              " read 12 triangles"),
        (_with_count(BAR, 5), "the binary STL 'bar.stl' gives 5 triangles in its header but its size holds 12:"
                              " read 12 triangles"),
    ],
)
def test_a_binary_stl_whose_count_disagrees_with_its_size_is_read_by_its_size(data, note):
    surface = load_surface(data, filename="bar.stl")
    assert surface.warnings == [note]
    assert len(surface.faces) == 12 and surface.closed and surface.enclosed_volume() == pytest.approx(2.0, rel=1e-12)


@pytest.mark.parametrize("data, counts", [
    (BAR[:342], "12 triangles (684 bytes), the file has 342 bytes (5 whole triangles)"),  # inside a record
    # at a record boundary: the 5 facets were read as an open surface, 11 as a box with a filled
    # hole (a solid not in the file), 1 or 2 (whose corners do not meet) as "no mesh found"
    (BAR[:334], "12 triangles (684 bytes), the file has 334 bytes (5 whole triangles)"),
    (BAR[:634], "12 triangles (684 bytes), the file has 634 bytes (11 whole triangles)"),
    (BAR[:134], "12 triangles (684 bytes), the file has 134 bytes (1 whole triangle)"),
    (BAR[:144], "12 triangles (684 bytes), the file has 144 bytes (1 whole triangle)"),
    (_with_count(BAR, 1000), "1000 triangles (50084 bytes), the file has 684 bytes (12 whole triangles)"),
])
def test_a_binary_stl_cut_short_is_refused_with_its_counts(data, counts):
    message = f"geometry.mesh: cannot read 'bar.stl': the binary STL is cut short: its header gives {counts}"
    with pytest.raises(GeometryError) as info:
        load_surface(data, filename="bar.stl")
    assert str(info.value) == message


@pytest.mark.parametrize("data", [
    bytes(np.random.default_rng(0).integers(0, 256, 84 + 50 * 40, dtype=np.uint8)),  # random bytes of an STL's length
    b"{" + b" " * 200 + b'"a": 1}' + b" " * 290,  # text: ASCII STL or nothing
])
def test_bytes_that_are_no_stl_are_still_refused(data):
    with pytest.raises(GeometryError, match=r"^geometry\.mesh: cannot read 'x.stl': "):
        load_surface(data, filename="x.stl")


def test_a_vertex_at_infinity_is_refused_without_numpy_warnings():
    box = trimesh.creation.box()
    vertices = box.vertices.copy()
    vertices[0] = np.inf
    with np.errstate(invalid="ignore"):  # the exporter's own normals
        data = trimesh.Trimesh(vertices, box.faces, process=False).export(file_type="stl")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning from numpy would raise here
        with pytest.raises(GeometryError, match=r"^geometry\.mesh: 'inf.stl': 4 of the 36 vertices have non-finite"):
            load_surface(data, filename="inf.stl")
