"""Compressed and archived meshes: read through a capped stream, bombs refused, messages in words.

Engine level (no service): ``engine.geometry.inflate`` and the loader's use of it, and the
loader's messages for malformed files, which must name the file and the format, never the
exception a library raised inside.
"""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import tarfile
import time
import zipfile

import pytest

from engine.errors import GeometryError
from engine.geometry.inflate import InflateLimitError, inflate
from engine.geometry.loading import load_surface
from service_helpers import MESH


def zipped(files: dict[str, bytes], method: int = zipfile.ZIP_DEFLATED) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", method) as archive:
        for name, data in files.items():
            archive.writestr(name, data)
    return out.getvalue()


def tarred(files: dict[str, bytes], mode: str = "w:gz") -> bytes:
    out = io.BytesIO()
    with tarfile.open(fileobj=out, mode=mode) as archive:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    return out.getvalue()


def zeros_bz2(size: int) -> bytes:
    """bzip2 of ``size`` zero bytes, compressed piecewise (never ``size`` bytes in memory)."""
    comp, chunk = bz2.BZ2Compressor(9), b"\0" * (16 << 20)
    parts = [comp.compress(chunk) for _ in range(size // len(chunk))]
    return b"".join(parts) + comp.flush()


@pytest.mark.parametrize(
    "name, data",
    [
        ("part.stl.gz", gzip.compress(MESH)),
        ("part.stl.bz2", bz2.compress(MESH)),
        ("part.stl.xz", lzma.compress(MESH)),
        ("part.zip", zipped({"inner/part.stl": MESH, "README.txt": b"a cantilever"})),
        ("part.tar.gz", tarred({"part.stl": MESH})),
        ("part.tar.xz", tarred({"part.stl": MESH}, "w:xz")),
    ],
)
def test_compressed_and_archived_meshes_read_like_the_plain_file(name, data):
    plain = load_surface(MESH, filename="part.stl")
    surface = load_surface(data, filename=name)
    assert surface.faces.tolist() == plain.faces.tolist()
    assert surface.vertices.tolist() == plain.vertices.tolist()


def test_an_archive_of_two_meshes_is_one_surface():
    surface = load_surface(zipped({"a.stl": MESH, "b.stl": MESH}), filename="two.zip")
    assert "combined 2 mesh files of the archive into one surface" in surface.warnings
    assert len(surface.faces) == 12  # the two copies coincide: repeated faces are removed


def test_a_bz2_bomb_stops_at_the_cap_without_inflating_it():
    bomb = zeros_bz2(2**28)
    assert len(bomb) < 300  # 256 MiB of zeros
    t = time.perf_counter()
    with pytest.raises(InflateLimitError, match=r"^geometry\.mesh: 'b.stl.bz2' inflates to more than 8388608 bytes, the limit"):
        load_surface(bomb, filename="b.stl.bz2", max_inflated_bytes=8 << 20)
    assert time.perf_counter() - t < 2.0  # 8 MiB inflated, not 1 GiB


def test_zip_and_tar_bombs_are_refused_by_what_they_produce_not_what_they_declare():
    member = b"\0" * (4 << 20)
    bomb = zipped({f"{i}.stl": member for i in range(4)})  # 16 MiB inside, ~16 KiB outside
    with pytest.raises(InflateLimitError):
        inflate("z.zip", bomb, 10 << 20)
    assert sum(map(len, inflate("z.zip", bomb, 16 << 20).values())) == 16 << 20
    # a tar whose header declares a huge member: refused before inflating it
    with pytest.raises(InflateLimitError):
        inflate("t.tar.gz", tarred({"big.stl": member}), 1 << 20)
    # a 3MF is a ZIP too; its members are checked before trimesh inflates them
    with pytest.raises(InflateLimitError):
        load_surface(zipped({"3D/3dmodel.model": member}), filename="m.3mf", max_inflated_bytes=1 << 20)


@pytest.mark.parametrize(
    "name, data, expected",
    [
        ("x.3mf", b"PK\x05\x06" + b"\0" * 18, "geometry.mesh: cannot read 'x.3mf': it is not a valid 3MF file, or it is damaged"),
        ("x.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n",
         "geometry.mesh: cannot read 'x.ply': it is not a valid PLY file, or it is damaged or incomplete; its header must"),
        ("x.gltf", b'{"asset": {"version": "2.0"}, "meshes": [{}]}',
         "geometry.mesh: cannot read 'x.gltf': it is not a valid GLTF file, or it is damaged or incomplete; a .gltf must embed"),
        ("x.stl.bz2", b"BZh9 not bzip2 at all", "geometry.mesh: cannot read 'x.stl.bz2': it is not a valid bzip2 file"),
        ("x.zip", zipped({"notes.txt": b"no mesh"}), "geometry.mesh: cannot read 'x.zip': no mesh file inside (found: notes.txt)"),
    ],
)
def test_malformed_files_are_named_in_words_not_exceptions(name, data, expected):
    with pytest.raises(GeometryError) as info:
        load_surface(data, filename=name)
    message = str(info.value)
    assert message.startswith(expected), message
    for internal in ("StopIteration", "KeyError", "NoneType", "Traceback", "Error:"):
        assert internal not in message


def test_a_scale_that_overflows_names_geometry_scale():
    with pytest.raises(GeometryError, match=r"^geometry\.scale: scaled by 1e\+308, 'c.stl' reaches coordinates of 1e\+308 m"):
        load_surface(MESH, filename="c.stl", scale=1e308)
