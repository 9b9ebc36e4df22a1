"""voxelastic engine: elasticity of objects given by surface meshes, on voxel grids.

Data flow (each stage a module named after what it produces)::

    surface mesh   --geometry.load_surface-->         Surface
    Surface        --grid.make_grid-->                Grid
    Surface, Grid  --geometry.volume_fractions-->     VolumeFractions (exact, block-sparse)
    Surface, Grid  --geometry.slice_cells-->          CutCells (DG pieces with moments)
    fractions      --staggered.StaggeredElasticity--> operator, loads, multigrid-PCG solves
    method         --analysis.run_analysis-->         FieldData (static / steps)
    fields         --output.write_result-->           HDF5 + XDMF

Importing this package never initialises Taichi; ``engine.runtime.init`` does, once.
"""

import os as _os

__version__ = "0.2.0"

# Set before any module imports taichi: no version check calling out to the internet, and no
# banner on stdout (stdout carries the CLI's output).
_os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
_os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")


def simulate(spec, mesh=None, **options):
    """Run a job (spec as JobSpec/dict/JSON, mesh as bytes or path) and return its ``Result``.

    See ``engine.pipeline.run`` for the options. Imported lazily so ``import engine`` stays light.
    """
    from .pipeline import run

    return run(spec, mesh, **options)
