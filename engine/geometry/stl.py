"""Binary STL files whose triangle count disagrees with their size, made readable.

A binary STL is an 80-byte header, a uint32 triangle count and 50 bytes per triangle. trimesh
reads one only when the count matches the size exactly; otherwise it tries ASCII and finds
nothing. Exporters get this wrong in harmless ways -- a count of 0, or a newline or padding
after the last record -- and common tools (slicers, MeshLab) then take the count from the size.
``fix_binary_count`` does the same, so trimesh reads the file, and says what it did:

- a header count larger than the whole records present: a file cut short (an interrupted download
  or copy), an error naming both counts, whether it ends at a record boundary or inside a record:
  the missing triangles matter, and the records present make an open surface that repair and the
  winding number would quietly turn into some other solid;
- otherwise the size is 84 + 50 n, maybe with fewer than 50 bytes more: n triangles, the header's
  smaller count (0 is common) and the bytes after the last record ignored.

Bytes that merely have the right length are not a mesh: the records must hold finite coordinates
of float32 magnitude -- enough to call a file cut short, whose records may be too few to meet --
and, to be read, share corners (every facet of a solid shares its corners with its neighbours, so at
most half the corners are distinct; 12-byte corners of random bytes never repeat). A file without
one whole record tells nothing. Anything else is left to trimesh, which reports it as not a valid
STL file.
"""

from __future__ import annotations

import numpy as np

from engine.errors import GeometryError

_HEADER, _RECORD = 84, 50
# float32 garbage spans 1e-45..3e38; coordinates of a real part are far inside this
_MAX_COORDINATE = 1e30
# the bytes of a text file (UTF-8 included): a file of only these is no binary STL, nor binary at all
TEXT = bytes(range(32, 256)) + b"\t\n\r\f\v"


def fix_binary_count(name: str, data: bytes) -> tuple[bytes, list[str]]:
    """(the file's bytes with the count and length trimesh needs, notes saying what changed).

    Unchanged (no notes) for ASCII files, binary files whose count fits their size, and bytes
    that are no binary STL. Raises ``GeometryError`` for a binary STL that was cut short.
    """
    if len(data) < _HEADER + _RECORD or not data.translate(None, TEXT):
        return data, []  # too short to hold a triangle, or text (ASCII STL or no STL): trimesh's own reading
    count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
    n, rest = divmod(len(data) - _HEADER, _RECORD)
    if count * _RECORD == len(data) - _HEADER:
        return data, []
    corners = _corners(data, n)
    numbers = _coordinates(corners)
    if count > n and numbers:
        raise GeometryError(
            f"cannot read '{name}': the binary STL is cut short: its header gives {count} triangles"
            f" ({_HEADER + count * _RECORD} bytes), the file has {len(data)} bytes ({n} whole triangle{'s' * (n != 1)})"
        )
    if not (numbers and _shared(corners)):
        return data, []
    if rest:
        given = "as its header gives" if count == n else f"its header gives {count}"
        note = (f"the binary STL '{name}' ends in {rest} bytes that are no whole triangle record: ignored them"
                f" and read {n} triangles ({given})")
    else:
        note = (f"the binary STL '{name}' gives {count} triangles in its header but its size holds {n}:"
                f" read {n} triangles")
    fixed = data[:80] + np.uint32(n).astype("<u4").tobytes() + data[_HEADER:_HEADER + n * _RECORD]
    return fixed, [note]


def _corners(data: bytes, n: int) -> np.ndarray:
    """The corners [3 n, 3] (float32) of the n records after the header."""
    records = np.frombuffer(data, dtype=np.uint8, count=n * _RECORD, offset=_HEADER).reshape(n, _RECORD)
    return np.ascontiguousarray(records[:, 12:48]).view("<f4").reshape(-1, 3)


def _coordinates(corners: np.ndarray) -> bool:
    """Whether the corners are finite numbers of the magnitude a part's coordinates have."""
    with np.errstate(invalid="ignore", over="ignore"):
        return bool(np.isfinite(corners).all() and np.abs(corners).max() < _MAX_COORDINATE)


def _shared(corners: np.ndarray) -> bool:
    """Whether the corners are shared as a mesh's facets share them (module docstring)."""
    return 2 * len(np.unique(corners.view(np.dtype((np.void, 12))))) <= len(corners)
