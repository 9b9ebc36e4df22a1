"""Content-addressed cache of geometry preprocessing (a repeated job skips the cut-cell stage).

Keys hash everything the result depends on: the mesh bytes, the geometry and grid parts of the
job spec, the kind of preprocessing and a version that is bumped whenever the algorithms change.
Entries are pickles written by this process only (the cache directory is ours, not user input),
to a temporary name and renamed, so a crash never leaves a truncated entry behind.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import tempfile
from pathlib import Path
from typing import Any, Callable, TypeVar

T = TypeVar("T")

# Bump when the output of any cached computation changes.
GEOMETRY_VERSION = "5"


def cache_key(kind: str, mesh_bytes: bytes, params: dict[str, Any]) -> str:
    """SHA-256 over the preprocessing kind, the mesh content and the JSON of its parameters."""
    h = hashlib.sha256()
    for part in (GEOMETRY_VERSION, kind, json.dumps(params, sort_keys=True, default=repr)):
        h.update(part.encode())
        h.update(b"\0")
    h.update(hashlib.sha256(mesh_bytes).digest())
    return h.hexdigest()


def cache_root() -> Path:
    """Where the engine keeps its caches: VOXELASTIC_CACHE_DIR, else $XDG_CACHE_HOME/voxelastic
    (~/.cache/voxelastic)."""
    base = os.environ.get("VOXELASTIC_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "voxelastic"
    )
    return Path(base)


def default_directory() -> Path:
    """The geometry cache's directory under :func:`cache_root`."""
    return cache_root() / "geometry"


class GeometryCache:
    """Pickled results keyed by :func:`cache_key`; ``directory=None`` disables caching."""

    def __init__(self, directory: str | Path | None):
        self.directory = Path(directory) if directory is not None else None

    def _path(self, key: str) -> Path:
        assert self.directory is not None
        return self.directory / key[:2] / f"{key}.pkl"

    def get_or_compute(self, key: str, compute: Callable[[], T]) -> tuple[T, bool]:
        """The cached value for ``key`` (and True), or ``compute()`` stored under it (and False)."""
        if self.directory is None:
            return compute(), False
        path = self._path(key)
        try:
            with open(path, "rb") as f:
                return pickle.load(f), True
        except FileNotFoundError:
            pass
        except Exception:
            # an unreadable entry (older Python, truncated disk) is recomputed, never trusted
            path.unlink(missing_ok=True)
        value = compute()
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump(value, f, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return value, False
