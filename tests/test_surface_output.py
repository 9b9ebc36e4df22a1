"""The staggered method's surface output on surfaces the grid does not resolve everywhere."""

import numpy as np
import trimesh

from engine import simulate
from engine.geometry.cache import GeometryCache


def test_surface_vertices_outside_the_resolved_material_still_move():
    """A box whose tip vertex is pushed across to the other side (a mildly self-intersecting shell):
    two surface vertices had no active sample in their stencils and came out NaN, and the viewers'
    refined surface then NaN over most of its values; they now take the nearest samples' values."""
    box = trimesh.creation.box(extents=(1, 0.2, 0.2), transform=trimesh.transformations.translation_matrix((0.5, 0, 0)))
    v = box.vertices.copy()
    v[np.nonzero((v[:, 0] > 0.9) & (v[:, 1] > 0) & (v[:, 2] > 0))[0][0]] = [1.0, -0.15, 0.1]
    mesh = trimesh.Trimesh(v, box.faces, process=False).export(file_type="stl")
    spec = {"dimension": 3, "geometry": {"mesh": "m.stl"}, "grid": {"resolution": 16, "padding": 1},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000}, "loads": {"gravity": [0, 0, -9.81]},
            "boundaries": [{"kind": "displacement", "name": "clamp", "region": {"box": [[-0.1, -0.5, -0.5], [0.05, 0.5, 0.5]]},
                            "value": [0, 0, 0]}],
            "output": {"fields": ["displacement"], "surface": True}}
    result = simulate(spec, mesh, filename="m.stl", cache=GeometryCache(None))
    u = result.fields.surface["displacement"]
    assert np.isfinite(u).all()
    tip = np.abs(result.surface_vertices[:, 0] - 1) < 1e-6
    assert np.all(u[tip, 2] < 0)  # the free end sags
