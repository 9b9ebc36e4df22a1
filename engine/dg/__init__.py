"""The hex-sliced discontinuous Galerkin method (Kaufmann et al. 2009): elements are the connected
pieces of grid cells inside the solid; see ``elasticity.DGElasticity``."""
