"""Whether a result may replace what is at its path: the check ``write_result`` and the CLI share."""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from pathlib import Path

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def replace_problem(path: str | os.PathLike, inputs: Sequence[str | os.PathLike] = ()) -> str | None:
    """Why a result must not replace what is at ``path`` or its ``sidecar_paths`` (None if it may).

    A result replaces files by renaming over them, which would turn a device (``-o /dev/null``) or
    a pipe into a regular file and wipe an input given by mistake (``-o part.stl``): refused are an
    existing target that is not a regular file or a link, one that is one of ``inputs`` (the job's
    spec and mesh), and an existing ``path`` that is not an HDF5 file (an earlier result is replaced).
    """
    path = Path(path)
    named = [Path(p) for p in inputs]
    for target in [path, *_sidecars(path)]:
        try:
            mode = os.lstat(target).st_mode
        except OSError:
            continue  # nothing there yet
        if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
            return f"'{target}' exists and is not a regular file"
        for given in named:
            same = os.path.abspath(target) == os.path.abspath(given)
            if same or (stat.S_ISREG(mode) and given.exists() and os.path.samefile(target, given)):
                return f"'{target}' is the job's own input '{given}': choose another output name"
    if path.is_file():
        with open(path, "rb") as fh:
            if fh.read(len(_HDF5_SIGNATURE)) != _HDF5_SIGNATURE:
                return f"'{path}' exists and is not an HDF5 file: remove it or choose another output name"
    return None


def _sidecars(path: Path) -> list[Path]:
    from .output import sidecar_paths  # the names the writer uses

    return list(sidecar_paths(path).values())

