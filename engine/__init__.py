"""voxelastic engine: elasticity of objects given by surface meshes, on voxel grids.

Data flow (each stage a module named after what it produces)::

    surface mesh  --geometry.load_surface-->     Surface
    Surface       --grid.make_grid-->            Grid
    Surface, Grid --geometry.subcell_volumes-->  SubcellVolumes (exact, sparse)
    SubcellVolumes --geometry.control_volumes--> ControlVolumes (staggered fractions)
    Surface, Grid --geometry.slice_cells-->      CutCells (DG pieces with moments)
    ...           --method, solve-->             fields
    fields        --output.write_result-->       HDF5 + XDMF

Importing this package never initialises Taichi; ``engine.runtime.init`` does, once.
"""

__version__ = "0.1.0"
