"""voxelastic engine: elasticity of objects given by surface meshes, on voxel grids.

Data flow (each stage a module named after what it produces)::

    job spec       --schemas.parse_job-->             JobSpec (validated; errors name the field)
    surface mesh   --geometry.load_surface-->         Surface
    Surface        --grid.make_grid-->                Grid
    JobSpec        --method.method_entry-->           MethodEntry (the registry: geometry, memory, builder)
    Surface, Grid  --geometry.volume_fractions-->     VolumeFractions     (staggered: exact, block-sparse)
    Surface, Grid  --geometry.slice_cells-->          CutCells            (DG: cell pieces with moments)
    geometry       --boundary.make_boundaries-->      Prescribed, SurfaceLoad (surface patches, both methods)
    geometry, bcs  --staggered / dg problem-->        Method: operator or system, loads, solver
    Method         --analysis.run_analysis-->         FieldData (static / quasi-static / dynamic steps)
    fields         --output.write_result-->           HDF5 + viewer files

``pipeline.run`` (``engine.simulate``) chains them. A tiny job, end to end: a 1 m x 0.25 m plate
in 2D (plane strain), its left end held along x, its bottom along y, pulled by 1 kPa at its right
end; E = 1 MPa, nu = 0.3 give u_x = sigma L (1 - nu^2) / E and u_y = -nu / (1 - nu) eps_xx y at
the far top corner, which the staggered grid reproduces to round-off:

>>> import engine
>>> result = engine.simulate({
...     "dimension": 2,
...     "geometry": {"polygon": [[[0, 0], [1, 0], [1, 0.25], [0, 0.25]]]},
...     "grid": {"cell_size": 0.0625},
...     "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3},
...     "boundaries": [
...         {"kind": "displacement", "name": "end", "region": {"box": [[-1, -1], [0, 1]]}, "value": [0, None]},
...         {"kind": "displacement", "name": "floor", "region": {"box": [[-1, -1], [2, 0]]}, "value": [None, 0]},
...         {"kind": "traction", "name": "pull", "region": {"box": [[1, -1], [2, 1]]}, "value": [1000, 0]},
...     ],
...     "output": {"probes": [[1, 0.25]]},
... })
>>> [round(float(v), 12) for v in result.fields.probes["displacement"][0]]
[0.00091, -9.75e-05]

Importing this package never initialises Taichi; ``engine.runtime.init`` does, once.
"""

import os as _os

__version__ = "0.2.0"

# Set before any module imports Taichi (the gstaichi build): no banner on stdout, which carries the
# CLI's output.
_os.environ.setdefault("ENABLE_GSTAICHI_HEADER_PRINT", "False")


def simulate(spec, mesh=None, **options):
    """Run a job (spec as JobSpec/dict/JSON, mesh as bytes or path) and return its ``Result``.

    See ``engine.pipeline.run`` for the options. Imported lazily so ``import engine`` stays light.
    """
    from .pipeline import run

    return run(spec, mesh, **options)
