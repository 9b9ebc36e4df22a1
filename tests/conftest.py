import os

import numpy as np
import pytest
import trimesh

from engine.geometry.surface import Surface

# Keep Taichi's offline cache inside the test session's reach and quiet.
os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")


def surface_of(mesh: trimesh.Trimesh) -> Surface:
    return Surface(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64))


def polygon_surface_2d(*loops: np.ndarray) -> Surface:
    """Oriented segments of closed loops given in the orientation wanted (solid on the left)."""
    verts, faces, base = [], [], 0
    for loop in loops:
        loop = np.asarray(loop, dtype=float)
        n = len(loop)
        verts.append(loop)
        faces.append(np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1) + base)
        base += n
    return Surface(np.concatenate(verts), np.concatenate(faces).astype(np.int64))


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
