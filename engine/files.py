"""Reading the input files a user names (the job spec, the mesh): what is no file is refused in words.

``Path.read_bytes`` reads whatever the name opens: ``/dev/zero`` or ``/dev/urandom`` until memory
runs out, a terminal or a pipe that nothing writes to until someone does; a path holding a NUL
character raises ``ValueError``, which no caller expects of a file name. ``read_input`` refuses
those with an ``OSError`` whose ``strerror`` says why, the way every caller already reports an
unreadable file. A job spec may come through a pipe (``voxelastic validate /dev/stdin``,
``<(zcat job.json.gz)``); a mesh is a file (its format is its name's suffix, and compressed
meshes are read as they are).
"""

from __future__ import annotations

import errno
import os
import stat

_NOT_FILES = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device", stat.S_IFSOCK: "a socket",
              stat.S_IFIFO: "a pipe"}


def read_input(path: str | os.PathLike, *, pipe: bool = False) -> bytes:
    """The bytes of the file at ``path`` (or of the pipe, with ``pipe``); ``OSError`` (``strerror``
    in words) for a device, a socket, a pipe otherwise, or a path that no file can have."""
    try:
        mode = os.stat(path).st_mode
    except ValueError:  # "embedded null byte": not a name the file system can hold
        raise OSError(errno.EINVAL, "the path holds a NUL character, which no file name can") from None
    kind = _NOT_FILES.get(stat.S_IFMT(mode))
    if kind is not None and not (pipe and stat.S_ISFIFO(mode)):
        raise OSError(errno.EINVAL, f"it is {kind}, not a file")
    with open(path, "rb") as fh:
        return fh.read()
