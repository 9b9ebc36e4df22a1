"""Exceptions that carry a message meant for the user (CLI: one line, service: HTTP 422)."""


class VoxelasticError(Exception):
    """Base class: the message names the offending input and the reason."""


class GeometryError(VoxelasticError):
    """The mesh cannot be read or does not describe a solid (empty, NaN, zero volume...)."""


class GridError(VoxelasticError):
    """The background grid is invalid or too large for the configured memory limit."""


class ResultFormatError(VoxelasticError):
    """A result file is not a voxelastic result or has an unsupported format version."""


class MethodUnavailableError(VoxelasticError):
    """The requested discretization is not implemented in this version."""


class BoundaryError(VoxelasticError):
    """A boundary condition or load that cannot be applied (names the boundary and why)."""


class ThinFeatureError(VoxelasticError):
    """Material thinner than a grid cell leaves displacement samples that nothing holds (a
    singular stiffness matrix); the message counts them, says where, and what to change."""


class BackendError(VoxelasticError, RuntimeError):
    """The compute backend a job asks for (``solver.arch``, ``solver.precision``) cannot run here:
    no CUDA on this machine, or a process already running its kernels on another one."""


class PrecisionRangeError(VoxelasticError):
    """An input outside what the job's solve precision holds (``solver.precision`` 'f32'): names
    the field, the range that precision holds for the job and the way out."""
