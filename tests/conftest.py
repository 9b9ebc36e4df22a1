
import numpy as np
import pytest
import trimesh

from engine.geometry.surface import Surface


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


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    """Taichi on the CPU in double precision before the first test, whichever file runs first.

    The process holds one runtime and ``init`` refuses a switch, so every in-process test sees
    the same one: the DG tests compare f64 results, and jobs whose spec says arch "auto" run on
    the CPU here as they would beside them. A fixture, not a call at import: collecting the tests
    (``pytest --collect-only``, a worker that only imports) starts no runtime.
    """
    from engine.runtime import init

    return init("cpu", "f64")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
